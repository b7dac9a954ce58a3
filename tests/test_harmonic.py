"""Harmonic-balance backbones against independent references.

References: closed-form backbones (Duffing, Coulomb, Masing loop written out
here), a long DOP853 integration of the free Duffing orbit, an optimiser on the
energy-based microslip damping, and per-model loops for the batched path.
"""

import numpy as np
import pytest
from oscillators import duffing
from scipy import integrate, optimize

from identification.analytical.harmonic import backbone
from identification.model import JointModel

W0 = 2 * np.pi * 100.0  # rad/s


# ----------------------------------------------------------------- Duffing


def test_single_harmonic_duffing_is_the_classical_backbone():
    a = np.geomspace(1e-6, 3e-3, 25)
    k3 = 2e11
    result = backbone(duffing(k3, damping_ratio=None), a)
    expected = np.sqrt(W0**2 + 0.75 * k3 * a**2) / (2 * np.pi)
    np.testing.assert_allclose(result.frequency_hz, expected, rtol=1e-10)
    assert result.converged.all()
    np.testing.assert_array_equal(result.damping_ratio, 0.0)


def free_duffing_orbit(k3: float, x0: float, n_periods: int = 60) -> tuple[float, float]:
    """Period (s) and fundamental amplitude (m) of the free orbit from x(0) = x0, ẋ(0) = 0."""

    def rhs(t, s):
        return [s[1], -(W0**2) * s[0] - k3 * s[0] ** 3]

    def upward_zero(t, s):
        return s[0]

    upward_zero.direction = 1.0
    t_end = n_periods * 2 * np.pi / W0  # the orbit is faster than W0: > n_periods periods
    sol = integrate.solve_ivp(
        rhs, (0, t_end), [x0, 0.0], method="DOP853", rtol=1e-11, atol=1e-11 * x0,
        events=upward_zero, dense_output=True,
    )  # fmt: skip
    crossings = sol.t_events[0]
    period = (crossings[-1] - crossings[0]) / (crossings.size - 1)
    # Fourier projection over one period starting at the maximum (t = 0); periodic
    # trapezoid is spectrally accurate.
    t = np.arange(512) * period / 512
    fundamental = 2 * np.mean(sol.sol(t)[0] * np.cos(2 * np.pi * t / period))
    return period, fundamental


def test_multi_harmonic_matches_time_integration_of_the_free_duffing_orbit():
    a_target = 1e-3
    k3 = 0.3 * W0**2 / (0.75 * a_target**2)  # ¾ k3 a² / ω0² = 0.3
    period, a1 = free_duffing_orbit(k3, x0=a_target)
    assert 0.29 < 0.75 * k3 * a1**2 / W0**2 < 0.31
    reference_hz = 1.0 / period
    multi = backbone(duffing(k3, damping_ratio=None), [a1], method="multi", harmonics=5)
    single = backbone(duffing(k3, damping_ratio=None), [a1])
    error_multi = abs(multi.frequency_hz[0] / reference_hz - 1)
    error_single = abs(single.frequency_hz[0] / reference_hz - 1)
    print(f"\nfree Duffing orbit: {reference_hz:.8f} Hz; H=5 error {error_multi:.2e}, "
          f"H=1 error {error_single:.2e}")  # fmt: skip
    assert multi.converged[0]
    assert error_multi < 5e-4  # the 0.05 % asked for; H = 5 actually reaches ~1e-10
    assert error_multi < 1e-8
    assert error_single > 5e-4 and error_single > 100 * error_multi
    # The free undamped orbit needs no excitation.
    assert abs(multi.damping_ratio[0]) < 1e-12


def test_even_quadratic_stiffness_acts_through_mean_and_second_harmonic():
    # Lindstedt–Poincaré for ẍ + ω0² x + α x² = 0 (Nayfeh & Mook §4.1), ε = α a / ω0²:
    # ω = ω0 (1 − 5ε²/12), x = a cos τ + (α a² / 2ω0²)(−1 + cos 2τ / 3) + O(ε²a).
    alpha, a = 4e7, np.array([5e-5, 1e-4, 2e-4])
    eps = alpha * a / W0**2
    model = JointModel({"linear_stiffness": W0**2, "quadratic_stiffness": alpha})
    single = backbone(model, a)
    np.testing.assert_array_equal(2 * np.pi * single.frequency_hz, W0)  # no signature
    multi = backbone(model, a, method="multi")
    shift = 1 - 2 * np.pi * multi.frequency_hz / W0
    np.testing.assert_allclose(shift, 5 * eps**2 / 12, rtol=1e-3)
    np.testing.assert_allclose(multi.harmonics_cos_m[:, 0], -alpha * a**2 / (2 * W0**2), rtol=1e-3)
    np.testing.assert_allclose(multi.harmonics_cos_m[:, 2], alpha * a**2 / (6 * W0**2), rtol=1e-3)


# ----------------------------------------------------------------- Coulomb


def test_aft_damping_of_coulomb_friction_matches_the_closed_form():
    c, friction, a = 2.0, 5.0, np.array([2e-4, 5e-4, 1e-3])
    model = JointModel(
        {
            "linear_stiffness": W0**2,
            "viscous_damping": c,
            "coulomb_friction": {"coefficient": friction, "v_reg": 1e-7},
        }
    )
    n_time = 4096
    result = backbone(model, a, method="multi", harmonics=1, n_time=n_time)
    assert result.converged.all()
    omega = 2 * np.pi * result.frequency_hz
    np.testing.assert_allclose(omega, W0, rtol=1e-12)  # friction in quadrature: no shift
    closed_form = (c + 4 * friction / (np.pi * a * omega)) / (2 * omega)
    # The AFT sum replaces ∫|sin θ| by the trapezoid sum (2/N) Σ |sin θ_n|, i.e. 4/π by
    # (4/N) cot(π/N): relative error π²/(3N²) ≈ 2e-7 at N = 4096, below 1e-6.
    np.testing.assert_allclose(result.damping_ratio, closed_form, rtol=1e-6)
    trapezoid = (np.pi / n_time) / np.tan(np.pi / n_time)
    discrete = (c + 4 * friction * trapezoid / (np.pi * a * omega)) / (2 * omega)
    np.testing.assert_allclose(result.damping_ratio, discrete, rtol=1e-12)


# ----------------------------------------------------------------- microslip

K_T = 0.5 * W0**2
A_SLIP = 1e-4  # F_s / k_t
VISCOUS = 0.5


def microslip_model() -> JointModel:
    return JointModel(
        {
            "linear_stiffness": W0**2,
            "viscous_damping": VISCOUS,
            "microslip": {"coefficient": 1.0, "k_t": K_T, "F_s": K_T * A_SLIP},
        }
    )


def masing(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Equivalent stiffness and dissipated energy per cycle of the bilinear loop (Caughey)."""
    a = np.asarray(a, float)
    phi = np.arccos(np.clip(1 - 2 * A_SLIP / a, -1, 1))
    k_eq = np.where(a > A_SLIP, K_T * (phi - 0.5 * np.sin(2 * phi)) / np.pi, K_T)
    energy = np.where(a > A_SLIP, 4 * K_T * A_SLIP * (a - A_SLIP), 0.0)
    return k_eq, energy


def test_microslip_softens_from_stuck_to_free_stiffness():
    a = np.geomspace(1e-3 * A_SLIP, 1e4 * A_SLIP, 60)
    for method in ("single", "multi"):
        result = backbone(microslip_model(), a, method=method)
        assert result.converged.all()
        omega2 = (2 * np.pi * result.frequency_hz) ** 2
        assert omega2[0] == pytest.approx(W0**2 + K_T, rel=1e-12)
        assert omega2[-1] == pytest.approx(W0**2, rel=2e-5)
        assert np.all(np.diff(omega2) <= 1e-9 * omega2[0])


def test_aft_microslip_damping_matches_the_masing_loop():
    a = np.geomspace(1.2 * A_SLIP, 50 * A_SLIP, 9)
    result = backbone(microslip_model(), a, method="multi", harmonics=1, n_time=8192)
    assert result.converged.all()
    k_eq, energy = masing(a)
    omega = np.sqrt(W0**2 + k_eq)
    zeta = (VISCOUS + energy / (np.pi * a**2 * omega)) / (2 * omega)
    np.testing.assert_allclose(2 * np.pi * result.frequency_hz, omega, rtol=1e-8)
    np.testing.assert_allclose(result.damping_ratio, zeta, rtol=1e-6)


def test_microslip_damping_peaks_where_the_energy_balance_says():
    def zeta(a):
        k_eq, energy = masing(a)
        omega = np.sqrt(W0**2 + k_eq)
        return (VISCOUS + energy / (np.pi * a**2 * omega)) / (2 * omega)

    best = optimize.minimize_scalar(
        lambda a: -zeta(a), bounds=(A_SLIP, 20 * A_SLIP), method="bounded",
        options={"xatol": 1e-12},
    )  # fmt: skip
    grid = np.geomspace(1.01 * A_SLIP, 20 * A_SLIP, 801)
    spacing = np.log(grid[1] / grid[0])
    for method, kwargs in [("single", {}), ("multi", {"harmonics": 1, "n_time": 1024})]:
        result = backbone(microslip_model(), grid, method=method, **kwargs)
        peak = grid[np.argmax(result.damping_ratio)]
        assert abs(np.log(peak / best.x)) <= spacing, method


# ----------------------------------------------------------------- pandey2025


def test_pandey2025_linear_limit():
    model = JointModel.preset("pandey2025")
    for method in ("single", "multi"):
        result = backbone(model, [1e-9], method=method)
        assert result.frequency_hz[0] == pytest.approx(np.sqrt(4.49e5) / (2 * np.pi), rel=1e-6)
        assert round(result.frequency_hz[0], 1) == 106.6


def test_pandey2025_backbone_is_sane_over_the_test_range():
    model = JointModel.preset("pandey2025")
    a = np.array([0.1e-3, 0.5e-3, 0.9e-3])
    single = backbone(model, a)
    multi = backbone(model, a, method="multi")
    print("\npandey2025   a (mm)   f single (Hz)   f H=5 (Hz)   ζ single (%)   ζ H=5 (%)")
    for i in range(a.size):
        print(
            f"{'':13}{a[i] * 1e3:.1f}      {single.frequency_hz[i]:.4f}      "
            f"{multi.frequency_hz[i]:.4f}      {100 * single.damping_ratio[i]:.4f}"
            f"       {100 * multi.damping_ratio[i]:.4f}"
        )
    for r in (single, multi):
        assert r.converged.all()
        assert np.all(np.diff(r.frequency_hz) < 0)  # softening (x·|x|, x³ negative)
        assert np.all((r.frequency_hz > 95) & (r.frequency_hz < 107))
        assert np.all((r.damping_ratio > 1e-3) & (r.damping_ratio < 2e-2))  # paper: < ~1 %
    np.testing.assert_allclose(multi.frequency_hz, single.frequency_hz, rtol=5e-3)
    np.testing.assert_allclose(multi.damping_ratio, single.damping_ratio, rtol=5e-2)
    # Even terms (x², x·ẋ, ẋ²) show up in the multi-harmonic mean and 2nd harmonic only.
    assert np.all(np.abs(multi.harmonics_cos_m[:, 0]) > 0)
    assert np.all(np.abs(multi.harmonics_cos_m[:, 2]) > 1e-3 * a)


# ----------------------------------------------------------------- batches


@pytest.mark.parametrize("method", ["single", "multi"])
@pytest.mark.parametrize(
    "model",
    [
        JointModel.preset("pandey2025"),
        microslip_model().with_effect("tanh_saturation", -20.0, x_s=3e-4),
    ],
    ids=["pandey2025", "microslip+tanh"],
)
def test_batch_of_parameter_sets_equals_a_loop_over_models(model, method):
    names = model.parameter_names
    nominal = np.array([model.parameters[n] for n in names])
    sets = nominal * np.random.default_rng(1).uniform(0.9, 1.1, (4, len(names)))
    a = np.array([5e-5, 3e-4, 1e-3])
    batch = backbone(model, a, parameters=sets, names=names, method=method)
    assert batch.frequency_hz.shape == (4, 3)
    for i, row in enumerate(sets):
        single = backbone(
            model.with_parameters(dict(zip(names, row, strict=True))), a, method=method
        )
        for field in ("frequency_hz", "damping_ratio", "base_acceleration"):
            np.testing.assert_allclose(getattr(batch, field)[i], getattr(single, field), rtol=1e-12)
        np.testing.assert_array_equal(batch.converged[i], single.converged)
    assert batch.converged.all()


def test_base_acceleration_is_the_power_balance_of_the_damping():
    model = JointModel.preset("pandey2025")
    a = np.array([2e-4, 8e-4])
    for method in ("single", "multi"):
        r = backbone(model, a, method=method)
        omega = 2 * np.pi * r.frequency_hz
        np.testing.assert_allclose(r.damping_ratio, r.base_acceleration / (2 * omega**2 * a))
    # Linear oscillator: A = c a ω, D = c / (2ω).
    linear = backbone(
        JointModel({"linear_stiffness": W0**2, "viscous_damping": 3.0}), a, method="multi"
    )
    np.testing.assert_allclose(linear.base_acceleration, 3.0 * a * W0, rtol=1e-10)


# ----------------------------------------------------------------- no answer


def test_no_positive_stiffness_gives_nan_not_an_exception():
    softening = duffing(-1e11, damping_ratio=None)  # ω² = ω0² − ¾·1e11·a² < 0 above ≈ 2.3 mm
    a = np.array([1e-4, 1e-3, 5e-3])
    for method in ("single", "multi"):
        r = backbone(softening, a, method=method)
        np.testing.assert_array_equal(r.converged, [True, True, False])
        assert np.isfinite(r.frequency_hz[:2]).all() and np.isnan(r.frequency_hz[2])
        assert np.isnan(r.damping_ratio[2]) and np.isnan(r.base_acceleration[2])
    r = backbone(JointModel({"linear_stiffness": -1.0}), a, method="multi")
    assert not r.converged.any() and np.isnan(r.frequency_hz).all()


def test_non_converged_newton_is_flagged_and_nan():
    r = backbone(duffing(2e11, damping_ratio=None), [1e-3], method="multi", max_iter=0)
    assert not r.converged[0]
    assert np.isnan(r.frequency_hz[0]) and np.isnan(r.harmonics_cos_m[0]).all()


# ----------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"amplitudes_m": [1e-3, np.nan]}, r"amplitudes_m\[1\]"),
        ({"amplitudes_m": [1e-3, -1e-4]}, r"amplitudes_m\[1\]"),
        ({"amplitudes_m": [[1e-3]]}, "1-D"),
        ({"parameters": [[1.0]], "names": ["no_such_effect"]}, "no_such_effect"),
        ({"parameters": [[1.0]], "names": ["quadratic_stiffness"]}, "quadratic_stiffness"),
        ({"parameters": [1.0, 2.0], "names": ["linear_stiffness"]}, r"shape \(n_sets, 1\)"),
        ({"parameters": [[1.0, 2.0]], "names": ["linear_stiffness"]}, r"shape \(n_sets, 1\)"),
        ({"parameters": [[np.inf]], "names": ["linear_stiffness"]}, "linear_stiffness"),
        ({"parameters": [[1.0]]}, "without names"),
        ({"names": ["linear_stiffness"]}, "without parameters"),
        ({"method": "triple"}, "triple"),
        ({"method": "multi", "harmonics": 0}, "harmonics"),
        ({"method": "multi", "harmonics": 3, "n_time": 12}, "n_time"),
        ({"method": "multi", "tol": -1.0}, "tol"),
        ({"method": "multi", "max_iter": 2.5}, "max_iter"),
    ],
)
def test_bad_input_names_the_item(kwargs, message):
    kwargs = {"amplitudes_m": [1e-3], **kwargs}
    with pytest.raises(ValueError, match=message):
        backbone(duffing(1e11, damping_ratio=None), **kwargs)


def test_bad_shape_parameter_is_named():
    model = microslip_model()
    with pytest.raises(ValueError, match=r"microslip\.k_t"):
        backbone(model, [1e-4], parameters=[[-1.0]], names=["microslip.k_t"])


# ------------------------------------------------ a measured excitation as the forcing


def fourier_phasors(samples: np.ndarray) -> np.ndarray:
    """``Z_k`` of ``Σ_k Re(Z_k e^{ikθ})`` from samples at ``θ = 2πn/N`` (numpy's FFT)."""
    return 2 * np.fft.rfft(samples) / samples.size


def own_frame(phasors: np.ndarray) -> np.ndarray:
    """Orders 2.. as fractions of the fundamental, in the frame where it is a real cosine."""
    k = np.arange(phasors.size)
    return (phasors * np.exp(-1j * k * np.angle(phasors[1])))[2:] / abs(phasors[1])


THETA = 2 * np.pi * np.arange(256) / 256
#: A shaker's base acceleration per unit fundamental, phase-resonance frame (sin θ): 5 % of
#: 2nd and 4 % of 3rd harmonic.
SHAKER = np.sin(THETA) + 0.05 * np.sin(2 * THETA + 0.5) + 0.04 * np.sin(3 * THETA - 1.0)


@pytest.mark.parametrize("kind", ["base_acceleration", "force"])
def test_linear_response_harmonics_are_the_frf_times_the_excitation_harmonics(kind):
    """ẍ + cẋ + kx = p: each response harmonic is H(kω)·P_k with H(Ω) = 1/(k − Ω² + icΩ),
    whatever the fundamental. The excitation is written in time (p = −a_base for a base
    acceleration, the force per unit mass for a force), its ratios measured from it by
    numpy's FFT in its own frame, as a test would."""
    zeta, a = 0.01, 1e-3
    model = JointModel({"linear_stiffness": W0**2, "viscous_damping": 2 * zeta * W0})
    shape = SHAKER if kind == "base_acceleration" else -SHAKER  # p₁ = −A sin θ either way
    ratios = own_frame(fourier_phasors(shape))
    result = backbone(model, [a], method="multi", excitation_harmonics=ratios,
                      excitation_kind=kind)  # fmt: skip
    omega, amplitude = 2 * np.pi * result.frequency_hz[0], result.base_acceleration[0]
    assert omega == pytest.approx(W0, rel=1e-12)  # the fundamental is the linear one's
    assert amplitude == pytest.approx(2 * zeta * W0 * omega * a, rel=1e-10)
    forcing = fourier_phasors(amplitude * (-shape if kind == "base_acceleration" else shape))
    k = np.arange(2, 6)
    expected = forcing[k] / (W0**2 - (k * omega) ** 2 + 2j * zeta * W0 * k * omega)
    computed = result.harmonics_cos_m[0, k] - 1j * result.harmonics_sin_m[0, k]
    np.testing.assert_allclose(computed / a, expected / a, atol=1e-12)
    assert abs(computed[0]) / a > 1e-4  # the forcing's 2nd harmonic shows
    # a pure excitation is the pure-sine path, number for number
    pure = backbone(model, [a], method="multi")
    zero = backbone(model, [a], method="multi", excitation_harmonics=[0.0, 0.0],
                    excitation_kind=kind)  # fmt: skip
    np.testing.assert_array_equal(zero.harmonics_cos_m, pure.harmonics_cos_m)
    np.testing.assert_array_equal(zero.frequency_hz, pure.frequency_hz)


def test_duffing_driven_by_a_distorted_base_matches_the_independent_simulator():
    """A Duffing oscillator (2 % hardening at 1 mm, ζ = 2 %) driven by the phase-resonant
    base acceleration the balance gives, distortion included, integrated by the independent
    simulator (DOP853): the steady state has the fundamental a cos θ (phase resonance at
    that amplitude) and the harmonics the balance predicts. Driven by a pure sine instead,
    a symmetric Duffing oscillator has no 2nd harmonic at all."""
    from independent_sim import forced_steady_state

    zeta, k3, a = 0.02, 2e10, 1e-3
    model = duffing(k3, damping_ratio=zeta)
    ratios = own_frame(fourier_phasors(SHAKER))
    result = backbone(model, [a], method="multi", harmonics=7, excitation_harmonics=ratios)
    omega, amplitude = 2 * np.pi * result.frequency_hz[0], result.base_acceleration[0]
    assert omega / W0 - 1 > 0.015

    def shaker(t: float) -> float:
        theta = omega * t
        return np.sin(theta) + 0.05 * np.sin(2 * theta + 0.5) + 0.04 * np.sin(3 * theta - 1.0)

    steady = forced_steady_state(
        lambda x, v: W0**2 * x + 2 * zeta * W0 * v + k3 * x**3,
        lambda t: -amplitude * shaker(t),
        2 * np.pi / omega,
        fs_hz=320 * omega / (2 * np.pi),  # 320 samples per period
        settle_periods=300,
        record_periods=10,
    )
    theta = omega * (steady["time_s"] + 300 * 2 * np.pi / omega)
    k = np.arange(6)
    basis = np.column_stack([np.cos(np.outer(theta, k)), np.sin(np.outer(theta, k[1:]))])
    coef = np.linalg.lstsq(basis, steady["displacement_m"], rcond=None)[0]
    simulated = coef[:6] - 1j * np.concatenate([[0.0], coef[6:]])
    assert simulated[1] == pytest.approx(a, rel=1e-6, abs=1e-6 * a)  # a cos θ: phase resonance
    predicted = result.harmonics_cos_m[0, :6] - 1j * result.harmonics_sin_m[0, :6]
    np.testing.assert_allclose(simulated / a, predicted / a, atol=2e-7)
    assert abs(simulated[2]) / a > 3e-4
    pure = backbone(model, [a], method="multi", harmonics=7)
    assert abs(pure.harmonics_cos_m[0, 2]) + abs(pure.harmonics_sin_m[0, 2]) < 1e-12 * a


@pytest.mark.parametrize("kind, sign", [("base_acceleration", -1.0), ("force", 1.0)])
def test_a_mean_in_the_excitation_is_a_static_offset_of_the_linear_response(kind, sign):
    """A mean m·A in the excitation (a force-driven test's static preload; p = −a_base for
    a base acceleration) displaces a linear oscillator by its static deflection p̄/k, leaves
    the fundamental's resonance alone and adds no harmonics."""
    zeta, a, mean = 0.01, 1e-3, 0.2
    model = JointModel({"linear_stiffness": W0**2, "viscous_damping": 2 * zeta * W0})
    result = backbone(model, [a], method="multi", excitation_mean=mean, excitation_kind=kind)
    amplitude = result.base_acceleration[0]
    assert amplitude == pytest.approx(2 * zeta * W0**2 * a, rel=1e-10)
    assert result.harmonics_cos_m[0, 0] == pytest.approx(sign * mean * amplitude / W0**2, rel=1e-9)
    np.testing.assert_allclose(
        result.harmonics_cos_m[0, 2:], 0, atol=1e-11 * a
    )  # the solver tolerance
    np.testing.assert_allclose(
        result.harmonics_sin_m[0, 2:], 0, atol=1e-11 * a
    )  # the solver tolerance
