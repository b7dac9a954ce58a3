"""The lab rig against independent expectations.

Every check compares the lab engine with something it does not compute itself:
the closed-form FRF of a linear oscillator, the exact periodic orbits of
piecewise-linear oscillators (built here from their analytic pieces), Segalman's
closed-form Iwan dissipation, the power-law damper's energy per cycle by
quadrature, a first-order low pass of the detector's 2ω product term, the
shaker distortion that was asked for, the drift that was put in, and the roots
of a two-mode FRF.
"""

import json
import math
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from scipy import integrate, optimize, special, stats

from identification.measurements.extraction import extract_backbone
from identification.measurements.records import Campaign
from identification.model import JointModel
from identification.rig import (
    LAB_HIDDEN_SCENARIOS,
    LAB_NULL_SCENARIOS,
    LAB_OUT_OF_CATALOGUE_SCENARIOS,
    RIG_PRESETS,
    Rig,
    read_ground_truth,
    rig_for_preset,
)
from identification.rig.conditions import Controller, Drift, Sensors, Shaker
from identification.rig.joints import (
    Clearance,
    IwanJoint,
    PowerLawDamping,
    PreloadedContact,
    SecondMode,
    joint_from_dict,
)
from identification.rig.lab import LabRig

F0 = 100.0
K0 = (2 * math.pi * F0) ** 2
ZETA = 0.005
#: Noise-free and held long enough (12 amplitude time constants 1/ζω) to be settled.
QUIET = {"noise_m_s": 0.0, "hold_s": 4.0}


def _linear(zeta: float = ZETA, stiffness: float = K0) -> JointModel:
    return JointModel({"linear_stiffness": stiffness, "viscous_damping": 2 * zeta * math.sqrt(K0)})


def _hold_window(rig: LabRig, level: int, periods: int = 70) -> slice:
    """The last ``periods`` nominal periods of hold ``level`` (samples)."""
    ramp, hold = rig._samples()
    end = (level + 1) * (ramp + hold)
    return slice(end - round(periods * rig.fs / F0), end)


def _harmonics(theta: np.ndarray, signal: np.ndarray, orders=(1, 2, 3)) -> np.ndarray:
    """Complex amplitudes ``C_k`` of ``signal ≈ c₀ + Σ Re(C_k e^{ikθ})`` (least squares)."""
    k = np.asarray(orders)
    basis = np.column_stack(
        [np.ones_like(theta), np.cos(np.outer(theta, k)), np.sin(np.outer(theta, k))]
    )
    coef = np.linalg.lstsq(basis, signal, rcond=None)[0]
    return coef[1 : 1 + k.size] - 1j * coef[1 + k.size :]


# --------------------------------------------------------------------------
# Linear oscillator: the closed-form FRF


def test_linear_steady_state_is_the_closed_form_frf_on_and_off_resonance():
    """Locked at phase resonance and 30° away from it, the rig's true signals follow
    H(ω) = −1/(ω_n² − ω² + 2iζω_nω) from the base acceleration to the displacement, and the
    loop sits where that FRF puts the phase."""
    omega_n = 2 * math.pi * F0
    for offset_deg in (0.0, 30.0):
        rig = LabRig.for_amplitudes(
            _linear(), [2e-4, 1e-3], controller=Controller(phase_offset_deg=offset_deg), **QUIET
        )
        series = rig.run(rig.nominal)
        window = _hold_window(rig, 1)
        theta = series.theta[window]
        omega = 2 * math.pi * series.frequency_hz[window].mean()
        displacement = _harmonics(theta, series.x[window], (1,))[0]
        base = _harmonics(theta, series.base_acceleration[window], (1,))[0]
        frf = -1.0 / (omega_n**2 - omega**2 + 2j * ZETA * omega_n * omega)
        assert displacement / base == pytest.approx(frf, rel=2e-4)
        # where the loop locks: arg(V/V_b) = −90° + offset, V/V_b = ω² H(ω)·(−1)
        expected = optimize.brentq(
            lambda w, offset=offset_deg: (
                math.degrees(math.atan2(2 * ZETA * omega_n * w, omega_n**2 - w**2))
                - (90.0 - offset)
            ),
            0.9 * omega_n,
            1.1 * omega_n,
        )
        assert omega == pytest.approx(expected, abs=2 * math.pi * 5e-4)
    assert expected < omega_n - 2 * math.pi * 0.1  # 30° off resonance is 0.12 Hz below it


def test_linear_backbone_from_the_records_is_the_natural_frequency_and_damping():
    rig = LabRig.for_amplitudes(_linear(), [1e-4, 1e-3, 2e-3], noise_m_s=1e-4, hold_s=4.0)
    record, truth = rig.campaign(assemblies=1)[0]
    curve = extract_backbone(record)
    # 1e-4 m/s on the base channels makes the lock wander by a few mHz at 0.1 mm
    np.testing.assert_allclose(curve.frequency_hz, F0, rtol=1e-4)
    np.testing.assert_allclose(curve.damping_ratio, ZETA, rtol=5e-3)
    np.testing.assert_allclose(curve.amplitude_m, [1e-4, 1e-3, 2e-3], rtol=0.01)
    assert np.abs(curve.phase_error_deg).max() < 0.3
    assert truth["lab"]["small_amplitude_frequency_hz"] == pytest.approx(F0)


# --------------------------------------------------------------------------
# Piecewise-linear joints: exact periodic orbits


def _clearance_orbit(k0, k_c, gap, peak):
    """Period and fundamental amplitude of ẍ + k0 x + k_c·deadzone(x, gap) = 0, max ``peak``."""
    w0, w1 = math.sqrt(k0), math.sqrt(k0 + k_c)
    if peak <= gap:
        return 2 * math.pi / w0, peak
    centre = k_c * gap / w1**2  # the contact branch oscillates about this
    t_contact = math.acos((gap - centre) / (peak - centre)) / w1
    speed = w1 * math.sqrt((peak - centre) ** 2 - (gap - centre) ** 2)
    radius = math.hypot(gap, speed / w0)
    start = math.acos(gap / radius)
    t_free = (0.5 * math.pi - start) / w0
    period = 4 * (t_contact + t_free)
    w = 2 * math.pi / period
    contact = integrate.quad(
        lambda t: (centre + (peak - centre) * math.cos(w1 * t)) * math.cos(w * t), 0, t_contact
    )[0]
    free = integrate.quad(
        lambda t: radius * math.cos(start + w0 * (t - t_contact)) * math.cos(w * t),
        t_contact,
        t_contact + t_free,
    )[0]
    return period, 8 / period * (contact + free)  # quarter-wave symmetry


def _contact_orbit(k0, k_c, preload, peak):
    """Period and fundamental amplitude of ẍ + k0 x + max(k_c x, −P) = 0, max ``peak``."""
    lift_off = preload / k_c
    w0, w1 = math.sqrt(k0), math.sqrt(k0 + k_c)
    if peak <= lift_off:
        return 2 * math.pi / w1, peak
    energy = 0.5 * w1**2 * peak**2
    open_potential = lambda x: 0.5 * k0 * x * x - k_c * lift_off * (x + 0.5 * lift_off)  # noqa: E731
    low = optimize.brentq(lambda x: open_potential(x) - energy, -20 * peak, -lift_off)
    t_closed = math.acos(-lift_off / peak) / w1  # from the maximum to lift-off
    centre = preload / k0  # the open branch oscillates about this
    radius = centre - low
    t_open = math.acos((lift_off + centre) / radius) / w0  # from lift-off to the minimum
    period = 2 * (t_closed + t_open)
    w = 2 * math.pi / period

    def x(t):
        t = abs(t)
        if t <= t_closed:
            return peak * math.cos(w1 * t)
        return centre - radius * math.cos(w0 * (0.5 * period - t))

    a1 = integrate.quad(
        lambda t: x(t) * math.cos(w * t),
        -0.5 * period,
        0.5 * period,
        points=[-t_closed, t_closed],
        limit=200,
    )[0]
    return period, 2 / period * a1


@pytest.mark.parametrize(
    ("joint", "orbit"),
    [
        (Clearance(3e-4, 0.3 * K0), lambda p: _clearance_orbit(K0, 0.3 * K0, 3e-4, p)),
        (PreloadedContact(0.3 * K0, 0.0), lambda p: _contact_orbit(K0, 0.3 * K0, 0.0, p)),
        (
            PreloadedContact(0.3 * K0, 0.3 * K0 * 3e-4),
            lambda p: _contact_orbit(K0, 0.3 * K0, 0.3 * K0 * 3e-4, p),
        ),
    ],
    ids=["clearance", "bilinear", "preloaded-contact"],
)
def test_piecewise_linear_backbone_is_the_exact_periodic_orbit(joint, orbit):
    rig = LabRig.for_amplitudes(_linear(), [1e-4, 5e-4, 2e-3], joints=(joint,), **QUIET)
    curve = extract_backbone(rig.campaign(assemblies=1)[0][0])
    exact = []
    for amplitude in curve.amplitude_m:
        peak = optimize.brentq(lambda p, a=amplitude: orbit(p)[1] - a, 1e-6, 5 * amplitude)
        exact.append(1 / orbit(peak)[0])
    np.testing.assert_allclose(curve.frequency_hz, exact, rtol=1e-5)
    if joint == PreloadedContact(0.3 * K0, 0.0):  # the bilinear oscillator's own formula
        w0, w1 = math.sqrt(K0), math.sqrt(1.3 * K0)
        np.testing.assert_allclose(curve.frequency_hz, w0 * w1 / (w0 + w1) / math.pi, rtol=1e-5)
    else:  # the backbone moves by several per cent over the range
        assert abs(curve.frequency_hz[-1] / curve.frequency_hz[0] - 1) > 0.05


def test_joint_describing_functions_against_quadrature():
    """The joints' describing functions (they place the levels) are their force's fundamental."""
    theta = np.linspace(0, 2 * np.pi, 20_001)[:-1]
    omega = 2 * np.pi * F0
    for joint in (
        Clearance(3e-4, 1e5),
        PreloadedContact(1e5, 20.0),
        PowerLawDamping(6.0, 1.5),
        PowerLawDamping(1.0, 0.5, v_reg=1e-9),
    ):
        for a in (1e-4, 5e-4, 2e-3):
            x, v = a * np.cos(theta), -a * omega * np.sin(theta)
            if isinstance(joint, PowerLawDamping):
                force = joint.coefficient * np.abs(v) ** joint.exponent * np.sign(v)
            elif isinstance(joint, Clearance):
                force = joint.contact_stiffness * np.sign(x) * np.maximum(abs(x) - joint.gap_m, 0)
            else:
                force = np.maximum(joint.contact_stiffness * x, -joint.preload)
            k_eq = 2 * np.mean(force * np.cos(theta)) / a
            c_eq = -2 * np.mean(force * np.sin(theta)) / (a * omega)
            k, c = joint.describing(a, omega)
            assert k == pytest.approx(k_eq, rel=1e-6, abs=1e-9 * K0)
            assert c == pytest.approx(c_eq, rel=1e-4, abs=1e-12)


# --------------------------------------------------------------------------
# Iwan joint and power-law damping: dissipation


def test_iwan_dissipation_per_cycle_is_segalmans_power_law():
    """Below macroslip the Iwan element dissipates 4R·a^(χ+3)/((χ+2)(χ+3)) per cycle (Segalman)."""
    chi, phi_max, k_t = -0.5, 3e-3, 0.1 * K0
    macroslip = k_t * phi_max * (chi + 1) / (chi + 2)  # β = 0: F_S = ∫φρ dφ
    iwan = IwanJoint(k_t, macroslip, chi=chi, beta=0.0, n_sliders=50)
    assert iwan.slip_displacement_max == pytest.approx(phi_max)
    zeta = 0.001  # light viscous damping: the joint's share of the measured damping is large
    rig = LabRig.for_amplitudes(
        _linear(zeta, K0 - k_t), [1e-4, 3e-4, 1e-3], joints=(iwan,), **QUIET
    )
    series = rig.run(rig.nominal)
    record = rig.campaign(assemblies=1)[0][0]
    curve = extract_backbone(record)
    density = k_t * (chi + 1) / phi_max ** (chi + 1)  # R
    peaks, dissipated = [], []
    for level, (a, f, measured) in enumerate(
        zip(curve.amplitude_m, curve.frequency_hz, curve.damping_ratio, strict=True)
    ):
        x = series.x[_hold_window(rig, level)]
        peaks.append(0.5 * (x.max() - x.min()))
        w = 2 * math.pi * f
        # power balance: the input per cycle is 2πω²a²ζ, the viscous damper takes c·π·ω·a²
        viscous = 2 * zeta * math.sqrt(K0)
        dissipated.append(2 * math.pi * w**2 * a**2 * measured - viscous * math.pi * w * a**2)
    peaks, dissipated = np.array(peaks), np.array(dissipated)
    segalman = 4 * density * peaks ** (chi + 3) / ((chi + 2) * (chi + 3))
    np.testing.assert_allclose(dissipated, segalman, rtol=0.02)
    slope = np.polyfit(np.log(peaks), np.log(dissipated), 1)[0]
    assert slope == pytest.approx(chi + 3, abs=0.02)
    # the discretised element's own sum agrees with the continuous density where it is fine
    np.testing.assert_allclose(iwan.dissipation_per_cycle(peaks[1:]), segalman[1:], rtol=5e-3)
    k, f_s = iwan.sliders()
    assert k.sum() == pytest.approx(k_t) and f_s.sum() == pytest.approx(macroslip)


def test_power_law_damping_matches_its_energy_per_cycle_by_quadrature():
    alpha, coefficient, zeta = 1.5, 6.2, 0.001
    joint = PowerLawDamping(coefficient, alpha)
    rig = LabRig.for_amplitudes(_linear(zeta), [1e-4, 3e-4, 1e-3], joints=(joint,), **QUIET)
    curve = extract_backbone(rig.campaign(assemblies=1)[0][0])
    for a, f, measured in zip(
        curve.amplitude_m, curve.frequency_hz, curve.damping_ratio, strict=True
    ):
        w = 2 * math.pi * f
        energy = (
            integrate.quad(
                lambda t, a=a, w=w: coefficient * abs(a * w * math.sin(t)) ** (alpha + 1),
                0,
                2 * math.pi,
            )[0]
            / w
        )
        c_eq = energy / (math.pi * a * a * w)
        assert measured == pytest.approx((2 * zeta * 2 * math.pi * F0 + c_eq) / (2 * w), rel=0.005)
        # and the Γ-function describing function is that quadrature
        gamma = (
            2
            * special.gamma((alpha + 2) / 2)
            / (math.sqrt(math.pi) * special.gamma((alpha + 3) / 2))
        )
        assert joint.describing(a, w)[1] == pytest.approx(c_eq, rel=1e-8)
        assert gamma == pytest.approx(c_eq / (coefficient * (a * w) ** (alpha - 1)), rel=1e-8)


# --------------------------------------------------------------------------
# Controller ripple, shaker distortion, drift, dropouts


@pytest.mark.parametrize("reference", ["command", "base"])
def test_frequency_ripple_at_two_omega_is_what_a_first_order_low_pass_lets_through(reference):
    """y·sin θ and y·cos θ carry (Y/2)·cos(2θ+…); a first-order low pass H(s) = ω_f/(s + ω_f)
    passes |H(2iω)| of it into the phase estimate and the PI controller multiplies it by
    |K_p + K_i/(2iω)|; against the base (in quadrature) both estimates ripple."""
    controller = Controller(
        detector_cutoff_hz=15.0,
        detector_order=1,
        reference=reference,
        proportional_gain_hz_per_deg=0.2,
        integral_gain_hz_per_deg_s=2.0,
    )
    rig = LabRig.for_amplitudes(_linear(), [5e-4], controller=controller, **QUIET)
    series = rig.run(rig.nominal)
    window = _hold_window(rig, 0, periods=100)
    ripple = abs(_harmonics(series.theta[window], series.frequency_hz[window], (2,))[0])
    kp, ki = 0.2 * 360, 2.0 * 360  # Hz/deg → rad/s per rad
    w2, w_f = 2 * 2 * math.pi * F0, 2 * math.pi * 15.0
    expected = abs(kp + ki / (1j * w2)) * abs(w_f / (1j * w2 + w_f)) / (2 * math.pi)
    expected *= 2 if reference == "base" else 1
    assert ripple == pytest.approx(expected, rel=0.03)
    assert controller.predicted_ripple_hz(F0, F0, ZETA) == pytest.approx(expected, rel=1e-9)
    assert ripple > 0.5  # a lab-sized ripple, not a rounding error


def test_shaker_distortion_shows_in_the_recorded_base_channels_as_asked():
    shaker = Shaker(
        distortion={2: 0.04, 3: 0.03}, distortion_phase_deg={2: 30.0, 3: -60.0}, centring_hz=0.0
    )
    # base channels at 1e-5 m/s RMS: the 2nd harmonic of the base velocity is only 6e-5 m/s
    rig = LabRig.for_amplitudes(_linear(), [1e-3], shaker=shaker, noise_m_s=1e-5, hold_s=2.0)
    record = rig.campaign(assemblies=1)[0][0]
    window = _hold_window(rig, 0)
    theta = np.unwrap(np.radians(record.phase_deg[window]))
    velocity = _harmonics(theta, record.excitation_velocity[window])
    acceleration = velocity * 1j * np.arange(1, 4)  # d/dt of e^{ikθ} is ikω e^{ikθ}
    # A (sin θ + d_k sin(kθ + ψ_k)) against the oscillator's θ: C_k / C_1 = d_k e^{iψ_k}
    ratio = acceleration[1:] / acceleration[0]
    np.testing.assert_allclose(np.abs(ratio), [0.04, 0.03], rtol=0.01)
    np.testing.assert_allclose(np.degrees(np.angle(ratio)), [30.0, -60.0], atol=1.0)


def test_drift_shows_as_a_difference_between_up_and_down_steps():
    """Natural-frequency and gain drift within a run: the same level measured on the way up
    and on the way down differs by exactly the drift between the two times."""
    drift = Drift(frequency_over_run=0.005, gain_over_run=0.03)
    rig = LabRig.for_amplitudes(_linear(), [2e-4, 1e-3], drift=drift, schedule="up-down", **QUIET)
    assert len(rig.levels_v) == 3 and rig.levels_v[0] == rig.levels_v[2]
    curve = extract_backbone(rig.campaign(assemblies=1)[0][0])
    ramp, hold = rig._samples()
    n = 3 * (ramp + hold)
    # time of each point: the middle of its last 70 periods, as a fraction of the record
    fraction = np.array([(k + 1) * (ramp + hold) - 0.5 * 70 * rig.fs / F0 for k in (0, 2)]) / n
    natural = 1 + 0.005 * fraction
    gain = 1 + 0.03 * fraction
    up, down = 0, 2
    measured = curve.frequency_hz[down] / curve.frequency_hz[up]
    assert measured == pytest.approx(natural[1] / natural[0], abs=2e-5)
    assert measured - 1 > 0.003  # hysteresis in time, not in amplitude
    # the same base acceleration holds the viscous oscillator at A_b/(c ω_n): the stiffer
    # structure moves less, and the response sensor's gain scales what is measured
    amplitude = curve.amplitude_m[down] / curve.amplitude_m[up]
    assert amplitude == pytest.approx(gain[1] / gain[0] * natural[0] / natural[1], rel=2e-4)


def test_dropouts_and_per_channel_noise_are_as_stated():
    noise = tuple(np.linspace(5e-5, 3e-4, 15))
    sensors = Sensors(
        panel_noise_m_s=noise, base_noise_m_s=2e-5, dropout_rate_hz=2.0, dropout_spike_m_s=0.4
    )
    rig = LabRig.for_amplitudes(_linear(), [1e-3], sensors=sensors, noise_m_s=1e-4, hold_s=3.0)
    record, truth = rig.campaign(assemblies=1, seed=4)[0]
    velocities = record.data[:, 1:18]
    dropouts = truth["lab"]["dropouts"]
    hit = np.zeros(velocities.shape, dtype=bool)
    for channel, start, length in dropouts:
        hit[start : start + length, channel] = True
    assert np.abs(velocities[hit]).max() <= 0.4  # spikes within the decoder's range
    # White noise from 4th differences, which a 100 Hz sinusoid sampled at 10 kHz leaves
    # below 1e-5 m/s; var(Δ⁴n) = 70σ². Differences touching a dropout are left out.
    fourth = np.diff(velocities, n=4, axis=0)
    touched = np.lib.stride_tricks.sliding_window_view(hit, 5, axis=0).any(axis=-1)
    estimate = np.sqrt(np.nanmean(np.where(touched, np.nan, fourth) ** 2, axis=0) / 70)
    np.testing.assert_allclose(estimate, [*noise, 2e-5, 2e-5], rtol=0.03)
    counts = np.bincount([d[0] for d in dropouts], minlength=17)
    assert counts[15:].sum() == 0  # the base points are not vibrometers here
    expected = 2.0 * record.time_s[-1]  # Poisson counts: each channel inside its 99.99 % band
    low, high = stats.poisson.ppf(5e-5, expected), stats.poisson.isf(5e-5, expected)
    assert np.all((counts[:15] >= low) & (counts[:15] <= high)), counts


# --------------------------------------------------------------------------
# A second mode


def test_second_resonance_is_where_the_modal_parameters_put_it():
    """Two linear modes seen at the centre: the loop started near either locks where the
    closed-form two-mode FRF crosses −90° against the base velocity."""
    mode = SecondMode(frequency_ratio=1.2, damping_ratio=0.005, participation=0.5, centre_shape=0.5)
    w1, w2 = 2 * math.pi * F0, 2 * math.pi * F0 * 1.2

    def phase(w):  # arg(V_centre/V_base) + 90°, V_centre/V_base = ω²(H₁ + Γ₂c₂H₂)
        total = 1 / (w1**2 - w**2 + 2j * ZETA * w1 * w) + 0.25 / (
            w2**2 - w**2 + 2j * 0.005 * w2 * w
        )
        return np.angle(total) + 0.5 * np.pi

    grid = np.linspace(0.9 * w1, 1.1 * w2, 200_001)
    values = phase(grid)
    # the loop holds where the phase falls through −90° (dφ/dω < 0, as at a resonance)
    falls = grid[1:][(values[:-1] > 0) & (values[1:] <= 0)]
    assert falls.size == 2
    for start_hz in (F0, 1.2 * F0):
        controller = Controller(initial_frequency_hz=start_hz)
        rig = LabRig.for_amplitudes(
            _linear(), [5e-4], second_mode=mode, controller=controller, **QUIET
        )
        series = rig.run(rig.nominal)
        locked = 2 * math.pi * series.frequency_hz[_hold_window(rig, 0)].mean()
        guess = falls[np.argmin(np.abs(falls - 2 * math.pi * start_hz))]
        root = optimize.brentq(phase, guess - 1e-3 * w1, guess + 1e-3 * w1)
        assert locked == pytest.approx(root, abs=2 * math.pi * 1e-3)
    assert abs(root - w2) < 0.01 * w2
    modes = rig.modes()
    assert modes.frequencies_hz[1] == pytest.approx(1.2 * F0)


# --------------------------------------------------------------------------
# Presets, campaigns, truth


def test_lab_presets_are_reachable_and_say_what_is_hidden():
    for name in (*LAB_NULL_SCENARIOS, *LAB_HIDDEN_SCENARIOS, *LAB_OUT_OF_CATALOGUE_SCENARIOS):
        preset = RIG_PRESETS[name]
        assert preset.lab is not None and not name.startswith("hidden-")
        rig = rig_for_preset(name, levels=4)
        assert isinstance(rig, LabRig) and rig.name == name
        if name in LAB_NULL_SCENARIOS:
            assert preset.model.effects == preset.base_model.effects
            assert not (rig.joints or rig.second_mode or preset.hidden_effects)
        elif name in LAB_HIDDEN_SCENARIOS:
            assert len(preset.hidden_effects) == 1 and not (rig.joints or rig.second_mode)
        else:
            assert preset.model == preset.base_model
            assert bool(rig.joints) != (rig.second_mode is not None)
    # every catalogue effect beyond the linear ones is hidden in one lab scenario
    hidden = {RIG_PRESETS[n].hidden_effects[0] for n in LAB_HIDDEN_SCENARIOS}
    from identification.effects import CATALOGUE

    assert hidden == set(CATALOGUE) - {"linear_stiffness", "viscous_damping"}
    assert isinstance(rig_for_preset("hidden-cubic"), Rig) and not isinstance(
        rig_for_preset("hidden-cubic"), LabRig
    )
    with pytest.raises(ValueError, match="lab scenario"):
        Rig.preset("lab-iwan")


def test_lab_campaign_truth_and_workers_equal_serial(tmp_path):
    rig = rig_for_preset("lab-iwan", levels=2, hold_s=0.8)
    assert rig.levels_v[:2] == rig.levels_v[:-3:-1]  # up then down
    rig.write_campaign(tmp_path / "serial", assemblies=2, seed=5)
    with ThreadPoolExecutor(2) as executor:
        rig.write_campaign(tmp_path / "pool", assemblies=2, seed=5, executor=executor)
    serial, pool = Campaign(tmp_path / "serial"), Campaign(tmp_path / "pool")
    for a, b in zip(serial, pool, strict=True):
        np.testing.assert_array_equal(a.data, b.data)
    truth = read_ground_truth(tmp_path / "serial")
    assert truth == read_ground_truth(tmp_path / "pool")
    first, last = truth["Config1_PRT_Assemb1"].lab, truth["Config1_PRT_Assemb2"].lab
    assert (first["position"], last["position"]) == (0.0, 1.0)
    assert last["natural_frequency_drift"][0] == pytest.approx(0.002)  # _LAB: +0.2 % / campaign
    assert last["sensor_gain"][0] == pytest.approx(1.02)
    sidecar = json.loads((tmp_path / "serial" / "ground_truth.json").read_text())
    joint = sidecar["rig"]["lab"]["joints"][0]
    assert joint_from_dict(joint) == rig.joints[0]
    drawn = sidecar["records"]["Config1_PRT_Assemb1"]["joints"][0]
    assert drawn["macroslip_force"] != joint["macroslip_force"]  # reassembly spread
    assert sidecar["rig"]["lab"]["controller"]["detector_order"] == 1


def test_the_rig_command_writes_a_lab_campaign(tmp_path):
    from pm_joint.cli import main

    out = tmp_path / "campaign"
    assert (
        main(["rig", "lab-dropouts", "--out", str(out), "--assemblies", "1", "--levels", "1"]) == 0
    )
    (truth,) = read_ground_truth(out).values()
    assert truth.lab["channel_noise_m_s"][2] == pytest.approx(3e-4)  # per-channel noise
    assert Campaign(out)[0].data.shape == (26_000, 20)


def test_bad_lab_settings_are_refused_with_their_name():
    with pytest.raises(ValueError, match="pll_options belong to Rig"):
        LabRig(_linear(), (1.0,), pll_options={"harmonics": 2})
    with pytest.raises(ValueError, match="at most one joint of each kind"):
        LabRig(_linear(), (1.0,), joints=(Clearance(1e-4, 1e4), Clearance(2e-4, 1e4)))
    with pytest.raises(ValueError, match=r"unknown parameter 'iwan\.stiffness'"):
        LabRig(_linear(), (1.0,), variability={"iwan.stiffness": 0.1})
    with pytest.raises(ValueError, match=r"Shaker\.distortion"):
        Shaker(distortion={1: 0.1})
    with pytest.raises(ValueError, match="needs a wider detector"):
        Controller(detector_cutoff_hz=2.0, loop_pole_hz=2.0).gains(F0, ZETA)
    with pytest.raises(ValueError, match="both hand-tuned gains or neither"):
        Controller(proportional_gain_hz_per_deg=0.1)
    with pytest.raises(ValueError, match="needs v_reg > 0"):
        PowerLawDamping(1.0, 0.5)
    with pytest.raises(ValueError, match=r"chi must be in \(−1, 0\]"):
        IwanJoint(1e4, 10.0, chi=0.5)
    with pytest.raises(ValueError, match="schedule must be"):
        LabRig.for_amplitudes(_linear(), [1e-3], schedule="down")


@pytest.mark.slow
@pytest.mark.parametrize(
    "name", [*LAB_NULL_SCENARIOS, *LAB_OUT_OF_CATALOGUE_SCENARIOS, *LAB_HIDDEN_SCENARIOS]
)
def test_every_lab_preset_locks_over_its_range(name):
    """A full-size record of every lab scenario locks at every level (phase within the
    scenario's offset plus a few degrees) and spans its amplitude range."""
    rig = rig_for_preset(name, levels=10)
    record, _ = rig.campaign(assemblies=1, seed=2)[0]
    curve = extract_backbone(record)
    offset = rig.controller.phase_offset_deg
    assert np.abs(curve.phase_error_deg - offset).max() < 6.0
    assert curve.amplitude_mm.min() < 0.07
    assert curve.amplitude_mm.max() > (1.2 if name == "lab-second-mode" else 1.6)
