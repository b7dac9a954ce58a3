"""Tests of the PLL phase-resonance simulator and the open-loop integrator.

Independent expectations: closed-form single-harmonic Duffing backbone,
multi-harmonic balance (:mod:`identification.analytical.harmonic`), the analytical
steady state of a linear oscillator, scipy's DOP853, the Masing rule.
"""

import concurrent.futures
import math

import numpy as np
import pytest
from oscillators import duffing
from scipy import integrate

from identification.analytical.harmonic import backbone
from identification.analytical.pll import (
    PLLConfig,
    PLLGains,
    design_gains,
    pll_backbones,
    simulate_base_excitation,
    simulate_pll,
    stable_substeps,
    target_phase_deg,
)
from identification.model import JointModel

OMEGA0 = 2 * np.pi * 100.0
ZETA = 0.003


#: k3 of the 100 Hz Duffing panel of these tests (1/(m²·s²)): frequency up about 3 % at 1 mm.
CUBIC = 3.2e10


def duffing_microslip():
    """Softening by microslip (slip from 0.05 mm), then Duffing hardening: 100 Hz at rest."""
    k = OMEGA0**2
    k_t = 0.1 * k
    return JointModel(
        {
            "linear_stiffness": 0.9 * k,
            "viscous_damping": 2 * ZETA * OMEGA0,
            "cubic_stiffness": 3.2e10,
            "microslip": {"coefficient": 1.0, "k_t": k_t, "F_s": k_t * 5e-5},
        },
        name="duffing_microslip",
    )


# Base-acceleration levels giving about 0.03–1 mm.
LEVELS = {
    "pandey2025": np.geomspace(0.25, 5.0, 5),
    "duffing_microslip": np.geomspace(0.08, 4.0, 5),
}


def model_named(name):
    return duffing_microslip() if name == "duffing_microslip" else JointModel.preset(name)


# --------------------------------------------------------------------------
# PLL against independent backbones.


def test_pll_matches_closed_form_duffing_backbone():
    model = duffing(CUBIC, ZETA)
    result = simulate_pll(model, np.geomspace(0.05, 3.0, 4))
    assert result.locked.all()
    a = result.amplitude_m
    assert a.min() < 5e-5 and a.max() > 5e-4
    omega = np.sqrt(OMEGA0**2 + 0.75 * 3.2e10 * a**2)  # single-harmonic Duffing backbone
    np.testing.assert_allclose(result.frequency_hz, omega / (2 * np.pi), rtol=3e-3)
    np.testing.assert_allclose(result.damping_ratio, 2 * ZETA * OMEGA0 / (2 * omega), rtol=0.05)
    assert np.all(np.abs(result.phase_error_deg) < PLLConfig().lock_tolerance_deg)


@pytest.mark.parametrize("name", ["pandey2025", "duffing_microslip"])
def test_pll_matches_multi_harmonic_backbone(name):
    model = model_named(name)
    result = simulate_pll(model, LEVELS[name])
    assert result.locked.all()
    reference = backbone(model, result.amplitude_m, method="multi", harmonics=5)
    assert reference.converged.all()
    np.testing.assert_allclose(result.frequency_hz, reference.frequency_hz, rtol=3e-3)
    np.testing.assert_allclose(result.damping_ratio, reference.damping_ratio, rtol=0.05)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["pandey2025", "duffing_microslip"])
def test_pll_matches_multi_harmonic_backbone_41_levels(name):
    model = model_named(name)
    low, high = LEVELS[name][[0, -1]]
    result = simulate_pll(model, np.geomspace(low, high, 41), PLLConfig(n_periods=70))
    assert result.locked.all()
    reference = backbone(model, result.amplitude_m, method="multi", harmonics=7)
    np.testing.assert_allclose(result.frequency_hz, reference.frequency_hz, rtol=3e-3)
    np.testing.assert_allclose(result.damping_ratio, reference.damping_ratio, rtol=0.05)


@pytest.mark.parametrize("sensing", ["velocity", "acceleration"])
def test_sensing_choice_locks_on_the_same_backbone(sensing):
    model = duffing(CUBIC, ZETA)
    levels = [0.1, 1.0]
    by_displacement = simulate_pll(model, levels)
    result = simulate_pll(model, levels, PLLConfig(sensing=sensing, reference="base_velocity"))
    assert result.locked.all()
    np.testing.assert_allclose(result.frequency_hz, by_displacement.frequency_hz, rtol=1e-4)
    np.testing.assert_allclose(result.damping_ratio, by_displacement.damping_ratio, rtol=0.01)


def test_target_phases():
    assert [target_phase_deg(s) for s in ("displacement", "velocity", "acceleration")] == [
        -90.0,
        0.0,
        90.0,
    ]
    # The TRC rig's reference, the base velocity, leads the force by 90°.
    assert target_phase_deg("velocity", "base_velocity") == -90.0
    assert target_phase_deg("displacement", "base_velocity") == -180.0


def test_design_gains_places_the_loop_poles():
    """Roots of s(s + ω_f)(s + σ) + ω_f (K_p s + K_i), the linearised loop, all at −p."""
    frequency_hz, zeta = 106.0, 0.006
    gains = design_gains(frequency_hz, zeta, bandwidth_ratio=4.0)
    sigma = zeta * 2 * np.pi * frequency_hz
    w_f = gains.detector_bandwidth
    poly = np.polymul(np.polymul([1, 0], [1, w_f]), [1, sigma])
    poly = np.polyadd(poly, [w_f * gains.kp, w_f * gains.ki])
    roots = np.roots(poly)
    np.testing.assert_allclose(roots.real, -4.0 * sigma, rtol=1e-3)
    np.testing.assert_allclose(roots.imag, 0.0, atol=1e-3 * sigma)


# --------------------------------------------------------------------------
# Time series.


def test_recorded_time_series_is_consistent():
    model = JointModel.preset("pandey2025")
    levels = [0.5, 2.0, 1.0]
    config = PLLConfig(reference="base_velocity")
    result = simulate_pll(model, levels, config, record=True)
    plain = simulate_pll(model, levels, config)
    np.testing.assert_array_equal(result.frequency_hz, plain.frequency_hz)
    np.testing.assert_array_equal(result.damping_ratio, plain.damping_ratio)
    ts = result.time_series
    dt = 1 / ts.fs
    np.testing.assert_allclose(np.diff(ts.t), dt)
    np.testing.assert_allclose(ts.base_acceleration, ts.level * np.sin(ts.phase), atol=1e-12)
    # θ integrates the recorded frequency (θ_{n+1} = θ_n + ω_n dt).
    np.testing.assert_allclose(np.diff(ts.phase), 2 * np.pi * ts.frequency_hz[:-1] * dt, atol=1e-11)
    # Each channel is the derivative of the one before (central differences, O(dt²));
    # the base velocity −A cos θ / ω is quasi-static, exact where the level holds.
    holds = np.zeros(ts.t.size, dtype=bool)
    for start, stop in ts.holds:
        holds[start + 1 : stop - 1] = True
    pairs = [(ts.x, ts.v, slice(1, -1)), (ts.v, ts.a, slice(1, -1))]
    pairs.append((ts.base_velocity, ts.base_acceleration, holds))
    for signal, derivative, where in pairs:
        np.testing.assert_allclose(
            np.gradient(signal, dt)[where], derivative[where], atol=2e-3 * np.abs(derivative).max()
        )
    for j, level in enumerate(levels):
        start, stop = ts.holds[j]
        assert np.all(ts.level[start:stop] == level) and np.all(ts.level_index[start:stop] == j)
        m_start, m_stop = ts.measurements[j]
        assert start < m_start < m_stop == stop
        # Least-squares fundamental of the recorded displacement over the measured periods.
        window = slice(m_start, m_stop)
        theta = ts.phase[window]
        basis = np.column_stack([np.ones_like(theta), np.sin(theta), np.cos(theta)])
        coefficients = np.linalg.lstsq(basis, ts.x[window], rcond=None)[0]
        np.testing.assert_allclose(np.hypot(*coefficients[1:]), result.amplitude_m[j], rtol=2e-3)
        # Locked: the detector's displacement phase against the base velocity is on target.
        expected = target_phase_deg("displacement", "base_velocity")
        phase = ts.response_phase_deg[m_stop - 1]
        assert abs((phase - expected + 180) % 360 - 180) < config.lock_tolerance_deg
        assert (m_stop - m_start) / ts.fs == pytest.approx(
            config.n_periods / result.frequency_hz[j], abs=1.5 * dt
        )


# --------------------------------------------------------------------------
# Open-loop integrator.


def test_linear_oscillator_reaches_analytical_steady_state():
    w0, zeta, w, amplitude = 2 * np.pi * 50.0, 0.05, 2 * np.pi * 45.0, 3.0
    model = JointModel({"linear_stiffness": w0**2, "viscous_damping": 2 * zeta * w0})
    t = np.arange(0, 1.5, 1e-4)
    x, v, a = simulate_base_excitation(model, t, amplitude * np.sin(w * t))
    # x = Im(X e^{iωt}) with X = −A / (ω0² − ω² + 2iζω0ω).
    expected = -amplitude / (w0**2 - w**2 + 2j * zeta * w0 * w)
    last = t > 1.4
    basis = np.column_stack([np.sin(w * t[last]), np.cos(w * t[last])])
    (re, im) = np.linalg.lstsq(basis, x[last], rcond=None)[0]
    np.testing.assert_allclose(re + 1j * im, expected, rtol=1e-4)
    np.testing.assert_allclose(a, -(w0**2) * x - 2 * zeta * w0 * v - amplitude * np.sin(w * t))


def _error_at_step(dt, model, forcing, t_end=0.2):
    t = np.arange(0, t_end + dt / 2, dt)
    x, _, _ = simulate_base_excitation(model, t, forcing(t), x0=2e-4)

    def rhs(time, y):
        return model.rhs(time, y, forcing(time))

    reference = integrate.solve_ivp(
        rhs, (0, t[-1]), [2e-4, 0.0], method="DOP853", rtol=1e-13, atol=1e-16, t_eval=t
    )
    return np.abs(x - reference.y[0]).max()


def test_rk4_order_is_four():
    model = duffing(CUBIC, damping_ratio=0.02)
    forcing = lambda t: 20.0 * np.sin(2 * np.pi * 80.0 * t)  # noqa: E731
    coarse = _error_at_step(1 / 2000, model, forcing)
    fine = _error_at_step(1 / 4000, model, forcing)
    assert 12 < coarse / fine < 20


def test_jenkins_loop_dissipates_masing_energy():
    """Slow harmonic loading: ∮ F dx of the element equals 4 F_s (a − a_s)."""
    k, k_t, f_s = (2 * np.pi * 100) ** 2, 4e4, 2.0
    c = 2 * 0.05 * 2 * np.pi * 100
    model = JointModel(
        {
            "linear_stiffness": k,
            "viscous_damping": c,
            "microslip": {"coefficient": 1.0, "k_t": k_t, "F_s": f_s},
        }
    )
    f = 5.0  # far below resonance: quasi-static
    t = np.arange(0, 3 / f, 1e-4)
    base = 150.0 * np.sin(2 * np.pi * f * t)
    x, v, a = simulate_base_excitation(model, t, base)
    element = -a - base - k * x - c * v  # the Jenkins force, from the equation of motion
    cycle = t >= 2 / f
    amplitude = 0.5 * (x[cycle].max() - x[cycle].min())
    assert amplitude > 3 * f_s / k_t  # well into slip
    energy = -np.trapezoid(element[cycle], x[cycle])  # clockwise loop in (x, F)
    energy = abs(energy)
    assert energy == pytest.approx(4 * f_s * (amplitude - f_s / k_t), rel=5e-3)


def test_stiff_friction_is_substepped_not_divergent():
    model = JointModel(
        {
            "linear_stiffness": OMEGA0**2,
            "viscous_damping": 1.0,
            "coulomb_friction": 20.0,
        }
    )
    assert stable_substeps(model, 10_000.0) > 1
    t = np.arange(0, 0.2, 1e-4)
    forcing = 60.0 * np.sin(2 * np.pi * 95.0 * t)
    x, _, _ = simulate_base_excitation(model, t, forcing)
    assert np.isfinite(x).all()
    t_fine = np.arange(0, 0.2, 2.5e-5)
    x_fine, _, _ = simulate_base_excitation(model, t_fine, 60.0 * np.sin(2 * np.pi * 95.0 * t_fine))
    np.testing.assert_allclose(x, x_fine[::4], atol=1e-3 * np.abs(x_fine).max())


def test_too_stiff_friction_raises():
    model = JointModel({"linear_stiffness": OMEGA0**2, "coulomb_friction": 1e6})
    with pytest.raises(ValueError, match="sub-steps"):
        simulate_base_excitation(model, np.arange(0, 0.01, 1e-4), np.zeros(100))


# --------------------------------------------------------------------------
# Batches and executors.

NAMES = ["cubic_stiffness", "viscous_damping"]
SETS = np.array([[-3.32e9, 7.51], [-2.9e9, 7.0], [-3.6e9, 8.2]])
BATCH_LEVELS = [0.5, 2.0]


def _loop_of_singles(model):
    rows = [
        simulate_pll(model.with_parameters(dict(zip(NAMES, s, strict=True))), BATCH_LEVELS)
        for s in SETS
    ]
    return np.array([r.frequency_hz for r in rows]), np.array([r.damping_ratio for r in rows])


def test_batch_equals_loop_of_singles():
    model = JointModel.preset("pandey2025")
    batch = pll_backbones(model, BATCH_LEVELS, SETS, NAMES, chunk_size=2, progress=False)
    frequency, damping = _loop_of_singles(model)
    assert batch.frequency_hz.shape == (3, 2) and batch.locked.all()
    np.testing.assert_array_equal(batch.frequency_hz, frequency)
    np.testing.assert_array_equal(batch.damping_ratio, damping)
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        pooled = pll_backbones(model, BATCH_LEVELS, SETS, NAMES, executor=pool, chunk_size=1)
    np.testing.assert_array_equal(pooled.frequency_hz, frequency)


def test_batch_through_dask_cluster():
    distributed = pytest.importorskip("dask.distributed")
    model = JointModel.preset("pandey2025")
    local = pll_backbones(model, BATCH_LEVELS, SETS, NAMES, progress=False)
    with (
        distributed.LocalCluster(
            n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        remote = pll_backbones(model, BATCH_LEVELS, SETS, NAMES, executor=client, chunk_size=2)
    np.testing.assert_array_equal(remote.frequency_hz, local.frequency_hz)
    np.testing.assert_array_equal(remote.damping_ratio, local.damping_ratio)
    np.testing.assert_array_equal(remote.locked, local.locked)


# --------------------------------------------------------------------------
# Robustness and bad input.


def _assert_all_unlocked(result):
    assert not result.locked.any()
    for values in (result.amplitude_m, result.frequency_hz, result.damping_ratio):
        assert np.isnan(values).all()


def test_negative_stiffness_diverges_into_unlocked_levels():
    model = JointModel({"linear_stiffness": -(OMEGA0**2), "viscous_damping": 1.0})
    _assert_all_unlocked(simulate_pll(model, [0.1, 1.0], PLLConfig(initial_frequency_hz=100.0)))
    _assert_all_unlocked(simulate_pll(model, [0.1, 1.0]))  # no resonance to start from


def test_negative_damping_diverges_into_unlocked_levels():
    model = JointModel({"linear_stiffness": OMEGA0**2, "viscous_damping": -200.0})
    result = simulate_pll(model, [0.1, 1.0], PLLConfig(max_hold_s=2.0), record=True)
    _assert_all_unlocked(result)
    assert np.isnan(result.phase_error_deg).all()
    assert np.isfinite(result.time_series.x).all()


def test_batch_marks_only_the_bad_set():
    model = duffing(CUBIC, ZETA)
    sets = np.array([[OMEGA0**2, 2 * ZETA * OMEGA0], [OMEGA0**2, -300.0]])
    batch = pll_backbones(model, [0.3], sets, ["linear_stiffness", "viscous_damping"])
    assert batch.locked.tolist() == [[True], [False]]
    assert np.isnan(batch.frequency_hz[1]).all() and np.isfinite(batch.frequency_hz[0]).all()


def test_unreachable_lock_gives_unlocked_levels():
    config = PLLConfig(lock_tolerance_deg=1e-9, max_hold_s=0.5)
    result = simulate_pll(duffing(CUBIC, ZETA), [0.3], config)
    _assert_all_unlocked(result)
    assert np.isfinite(result.phase_error_deg).all()


@pytest.mark.parametrize("levels", [[], [0.1, -1.0], [0.1, np.nan], [0.0], [[0.1, 0.2]]], ids=str)
def test_bad_levels_raise(levels):
    with pytest.raises(ValueError, match="levels"):
        simulate_pll(duffing(CUBIC, ZETA), levels)


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"fs": -1.0}, "fs"),
        ({"sensing": "strain"}, "sensing"),
        ({"reference": "voltage"}, "reference"),
        ({"n_periods": 0}, "n_periods"),
        ({"lock_periods": 2.5}, "lock_periods"),
        ({"lock_tolerance_deg": math.inf}, "lock_tolerance_deg"),
        ({"settling_tolerance": 0.0}, "settling_tolerance"),
        ({"ramp_s": -0.1}, "ramp_s"),
        ({"frequency_limits": (1.2, 2.0)}, "frequency_limits"),
        ({"frequency_limits": "wide"}, "frequency_limits"),
        ({"initial_frequency_hz": 0.0}, "initial_frequency_hz"),
        ({"gains": (1.0, 2.0, 3.0)}, "gains"),
    ],
)
def test_bad_config_raises(kwargs, name):
    with pytest.raises(ValueError, match=name):
        PLLConfig(**kwargs)


def test_bad_gains_and_holds_raise():
    with pytest.raises(ValueError, match="ki"):
        PLLGains(kp=1.0, ki=-1.0, detector_bandwidth=10.0)
    with pytest.raises(ValueError, match="max_hold_s"):
        simulate_pll(duffing(CUBIC, ZETA), [0.1], PLLConfig(max_hold_s=0.1))
    with pytest.raises(ValueError, match="fs"):
        simulate_pll(duffing(CUBIC, ZETA), [0.1], PLLConfig(fs=1000.0))


def test_bad_batch_input_raises():
    model = duffing(CUBIC, ZETA)
    with pytest.raises(ValueError, match="unknown parameter"):
        pll_backbones(model, [0.1], [[1.0]], ["no_such_effect"])
    with pytest.raises(ValueError, match="cubic_stiffness"):
        pll_backbones(model, [0.1], [[np.nan]], ["cubic_stiffness"])
    with pytest.raises(ValueError, match="chunk_size"):
        pll_backbones(model, [0.1], [[1e10]], ["cubic_stiffness"], chunk_size=0)


@pytest.mark.parametrize(
    ("t", "base", "name"),
    [
        ([0.0, 1e-4, 1e-4], [0.0, 0.0, 0.0], "increasing"),
        ([0.0, 1e-4, np.nan], [0.0, 0.0, 0.0], "t"),
        ([0.0, 1e-4, 2e-4], [0.0, np.inf, 0.0], "base_acceleration"),
        ([0.0, 1e-4, 2e-4], [0.0, 0.0], "base_acceleration"),
    ],
)
def test_bad_open_loop_input_raises(t, base, name):
    with pytest.raises(ValueError, match=name):
        simulate_base_excitation(duffing(CUBIC, ZETA), t, base)
