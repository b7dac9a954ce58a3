"""Backbone extraction from phase-resonance records: the points, the harmonics their
hold fits keep, and the table round trip of what was extracted."""

import dataclasses
import warnings

import numpy as np
import pytest
from independent_sim import forced_steady_state
from scipy.integrate import cumulative_trapezoid
from scipy.optimize import minimize_scalar

from identification.measurements.backbone import TABLE_COLUMNS, Backbone, BackboneSet
from identification.measurements.extraction import extract_backbone, extract_backbones, hold_point
from identification.measurements.records import Campaign, Record, StepSchedule, write_record
from identification.rig import RIG_PRESETS, rig_for_preset, trc_channels

FS = 10_000.0
HOLD_S = 0.8  # 80 periods at 100 Hz: room for the 70 measured ones
RAMP_S = 0.05


def synthetic_record(
    amplitudes_m,
    frequencies_hz,
    damping,
    phase_errors_deg=None,
    third_harmonic=0.0,
    drive_v=None,
    name="Config1_PRT_Assemb1",
    hold_s=HOLD_S,
) -> Record:
    """Pure harmonic steady states per hold, built from the definitions.

    Relative displacement x = a cos θ, base displacement x_b = 2ζa·cos(θ + 90° − ε)
    (leading x by 90° at phase resonance, ε the phase error), velocities their
    time derivatives at constant frequency; ramps interpolate linearly. The
    power balance then gives ζ·cos ε and the amplitude a. An optional third
    harmonic in the response tests that it does not leak into the fundamental.
    """
    n = len(amplitudes_m)
    eps = np.radians(np.zeros(n) if phase_errors_deg is None else phase_errors_deg)
    drive_v = np.arange(1, n + 1) * 0.1 if drive_v is None else np.asarray(drive_v)
    breakpoints = np.ravel(
        [[k * (hold_s + RAMP_S), k * (hold_s + RAMP_S) + hold_s] for k in range(n)]
    )
    t = np.arange(round(breakpoints[-1] * FS) + 1) / FS
    per_sample = [np.interp(t, breakpoints, np.repeat(v, 2)) for v in
                  (amplitudes_m, frequencies_hz, damping, eps)]  # fmt: skip
    a, f, zeta, e = per_sample
    theta = 2 * np.pi * cumulative_trapezoid(f, t, initial=0.0) + 0.7
    w = 2 * np.pi * f
    v_rel = -a * w * np.sin(theta) - third_harmonic * a * 3 * w * np.sin(3 * theta + 0.4)
    v_base = -2 * zeta * a * w * np.sin(theta + np.pi / 2 - e)
    shape = np.linspace(0.3, 1.0, 15)
    shape[7] = 1.0  # the centre point
    base = np.column_stack([v_base + 2e-3, v_base - 2e-3])  # their mean is the base motion
    phase_deg = np.degrees(np.angle(np.exp(1j * theta)))
    data = np.column_stack([t, np.outer(v_rel, shape) + v_base[:, None], base, f, phase_deg])
    return Record(data, StepSchedule(breakpoints, np.repeat(drive_v, 2)), name)


AMPLITUDES = np.array([2e-5, 1.5e-4, 8e-4, 2.1e-3])
FREQUENCIES = np.array([101.3, 99.7, 103.2, 109.9])
DAMPING = np.array([0.002, 0.0065, 0.004, 0.0031])


def test_extraction_recovers_the_known_backbone():
    record = synthetic_record(AMPLITUDES, FREQUENCIES, DAMPING, third_harmonic=0.05)
    backbone = extract_backbone(record)
    np.testing.assert_allclose(backbone.amplitude_m, AMPLITUDES, rtol=1e-6)
    np.testing.assert_allclose(backbone.frequency_hz, FREQUENCIES, rtol=1e-6)
    np.testing.assert_allclose(backbone.damping_ratio, DAMPING, rtol=1e-6)
    np.testing.assert_allclose(backbone.phase_error_deg, 0, atol=1e-6)
    np.testing.assert_allclose(backbone.excitation_level, [0.1, 0.2, 0.3, 0.4])
    assert backbone.label == "Config1_PRT_Assemb1"
    np.testing.assert_allclose(backbone.amplitude_mm, 1e3 * AMPLITUDES, rtol=1e-6)


def test_phase_error_and_active_power():
    errors = np.array([4.0, -7.0, 0.5, 12.0])
    record = synthetic_record(AMPLITUDES, FREQUENCIES, DAMPING, phase_errors_deg=errors)
    backbone = extract_backbone(record, n_periods=50)
    np.testing.assert_allclose(backbone.phase_error_deg, errors, rtol=1e-6)
    # only the in-phase part of the excitation supplies power
    np.testing.assert_allclose(
        backbone.damping_ratio, DAMPING * np.cos(np.radians(errors)), rtol=1e-6
    )


def test_short_hold_phases(tmp_path):
    record = synthetic_record(AMPLITUDES, FREQUENCIES, DAMPING, hold_s=0.5)
    written = write_record(record, tmp_path)
    campaign = Campaign(tmp_path)
    with pytest.raises(ValueError) as error:
        extract_backbone(campaign[0])
    assert str(error.value) == (
        f"{written}: hold phase at level 0.1 (0–0.5 s) holds 50.6 periods, "
        "fewer than n_periods = 70"
    )
    with pytest.warns(UserWarning) as caught:
        relaxed = extract_backbone(campaign[0], strict=False)
    drive_v = (0.1, 0.2, 0.3, 0.4)
    assert all(f"level {v} (" in str(w.message) for w, v in zip(caught, drive_v, strict=True))
    assert "using its 50 whole periods" in str(caught[0].message)
    np.testing.assert_allclose(relaxed.frequency_hz, FREQUENCIES, rtol=1e-6)


def test_channel_sign_error_is_reported():
    record = synthetic_record(AMPLITUDES[:2], FREQUENCIES[:2], DAMPING[:2])
    flipped = record.data.copy()
    flipped[:, 16:18] *= -1  # base channels wired with the wrong sign
    flipped[:, 1:16] -= 2 * record.base_velocity[:, :1]
    with pytest.raises(ValueError, match=r"from phase resonance .* check the signs"):
        extract_backbone(Record(flipped, record.steps, record.name))


def test_extract_backbones_of_a_campaign(tmp_path):
    for i, name in enumerate(["Config2_PRT_Assemb1", "Config2_PRT_Assemb2"]):
        write_record(
            synthetic_record(AMPLITUDES * (1 + i), FREQUENCIES, DAMPING, name=name), tmp_path
        )
    curves = extract_backbones(Campaign(tmp_path), n_periods=60)
    assert curves.labels == ["Config2_PRT_Assemb1", "Config2_PRT_Assemb2"]
    np.testing.assert_allclose(curves[1].amplitude_m, 2 * AMPLITUDES, rtol=1e-6)


def test_table_and_csv_round_trip(tmp_path):
    record = synthetic_record(AMPLITUDES, FREQUENCIES, DAMPING, phase_errors_deg=[1, 2, 3, 4])
    model = Backbone(1e-3 * np.array([0.1, 0.5, 1.0, 2.0]), [101, 100, 103, 110],
                     [0.002, 0.006, 0.005, 0.004], label="model")  # fmt: skip
    curves = BackboneSet([extract_backbone(record, n_periods=40), model])
    table = curves.to_table()
    assert list(table.columns) == list(TABLE_COLUMNS)
    assert len(table) == 8 and table["phase_error_deg"].isna().sum() == 4

    path = curves.to_csv(tmp_path / "backbones.csv")
    back = BackboneSet.from_csv(path)

    assert back.labels == curves.labels
    for a, b in zip(curves, back, strict=True):
        np.testing.assert_array_equal(a.frequency_hz, b.frequency_hz)
        np.testing.assert_allclose(a.amplitude_m, b.amplitude_m, rtol=1e-15)
        np.testing.assert_array_equal(a.damping_ratio, b.damping_ratio)
        assert a.source == b.source
    assert back["model"].phase_error_deg is None
    np.testing.assert_array_equal(back[0].phase_error_deg, curves[0].phase_error_deg)
    # what the hold fits measured reads back exactly; the model curve has none of it
    for name in ("harmonics", "harmonic_standard_error", "excitation_harmonics", "time_s",
                 "settled", "dropped_samples"):  # fmt: skip
        np.testing.assert_array_equal(getattr(back[0], name), getattr(curves[0], name))
        assert getattr(back["model"], name) is None
    assert back[0].settled.dtype == bool and back[0].dropped_samples.dtype.kind == "i"
    assert back[0].mean_offset_m is None and back["model"].mean_offset_m is None


# ---------------------------------------------------------------------------
# The harmonics a backbone point keeps


def harmonic_record(harmonics, amplitude=1e-3, f=101.0, noise=0.0, seconds=1.0, fs=10_000.0):
    """A one-hold record whose relative displacement has known harmonics
    ``{h: C_h - i S_h}`` (relative to the fundamental a cos θ), at an arbitrary phase."""
    t = np.arange(int(seconds * fs)) / fs
    theta = 2 * np.pi * f * t + 0.7
    w = 2 * np.pi * f
    v = -amplitude * w * np.sin(theta)
    for h, q in harmonics.items():
        c, s = amplitude * q.real, -amplitude * q.imag
        v += h * w * (-c * np.sin(h * theta) + s * np.cos(h * theta))
    base = -1e-3 * np.cos(theta)  # leads the relative velocity by 90°: phase resonance
    data = trc_channels(t, v, base, np.full(t.size, f), theta, noise_m_s=noise,
                        rng=np.random.default_rng(1))  # fmt: skip
    steps = StepSchedule([t[0], t[-1]], [1.0, 1.0])
    return Record(data, steps, "Config1_PRT_Assemb1")


def test_backbone_points_keep_known_harmonics_and_their_error():
    known = {2: 0.03 - 0.01j, 3: -0.004 + 0.002j}
    record = harmonic_record(known)
    h = extract_backbone(record, n_periods=70)
    assert h.amplitude_m[0] == pytest.approx(1e-3, rel=1e-9)
    np.testing.assert_allclose(h.harmonics[0], [known[2], known[3]], atol=1e-9)
    assert h.harmonic_orders == (2, 3)
    # With sensor noise: the reported standard error is the least-squares one,
    # σ_v √(2/N) / (h ω a) with σ_v² = σ² (1 + 1/2) (centre minus the mean of two bases).
    noisy = extract_backbone(harmonic_record(known, noise=1e-3))
    n = round(70 / 101.0 * 10_000)
    w = 2 * np.pi * 101.0
    expected = 1e-3 * np.sqrt(1.5) * np.sqrt(2 / n) / (np.array([2, 3]) * w * 1e-3)
    np.testing.assert_allclose(noisy.harmonic_standard_error[0], expected, rtol=0.1)
    error = np.abs(noisy.harmonics[0] - [known[2], known[3]])
    assert np.all(error < 5 * np.sqrt(2) * expected)


FS_LAB = 10_000.0
F_LAB = 101.0
A_LAB = 1e-3  # relative-displacement fundamental (m)
B_LAB = 0.02  # base-velocity fundamental (m/s): damping ratio B / (2 a ω) ≈ 1.6 %
RESPONSE_HARMONICS = {2: 0.03 - 0.01j, 3: -0.004 + 0.002j}  # (C_h − i S_h) / a
BASE_HARMONICS = {2: 0.04 * np.exp(0.3j), 3: 0.03 * np.exp(-1.1j)}  # of the base acceleration


def lab_hold(noise_m_s: float, seed: int, seconds: float = 1.0) -> Record:
    """One hold as a lab records it, written from the definitions (not by the rig):
    a relative displacement with known 2nd and 3rd harmonics and a slow drift of its
    mean (20 µm at 0.3 Hz), a shaker whose base acceleration carries 4 % and 3 % of
    2nd and 3rd harmonic, independent white noise on every velocity channel."""
    t = np.arange(int(seconds * FS_LAB)) / FS_LAB
    w = 2 * np.pi * F_LAB
    theta = w * t + 0.7
    # x = Re(Σ X_h e^{ihθ}) with X_1 = a, X_h = a q_h: the fundamental is a cos θ
    phasors = {1: A_LAB} | {h: A_LAB * q for h, q in RESPONSE_HARMONICS.items()}
    v_rel = sum(np.real(1j * h * w * x * np.exp(1j * h * theta)) for h, x in phasors.items())
    v_rel = v_rel + 20e-6 * 2 * np.pi * 0.3 * np.cos(2 * np.pi * 0.3 * t + 0.4)  # mean drift
    # base acceleration phasors: fundamental −iBω (base velocity −B cos θ, phase resonance),
    # harmonics p_h |A_1| e^{ih arg A_1} so that relative to its own fundamental they are p_h
    a1 = -1j * B_LAB * w
    accel = {1: a1} | {h: p * abs(a1) * np.exp(1j * h * np.angle(a1))
                       for h, p in BASE_HARMONICS.items()}  # fmt: skip
    v_base = sum(np.real(a / (1j * h * w) * np.exp(1j * h * theta)) for h, a in accel.items())
    rng = np.random.default_rng(seed)
    shape = np.linspace(0.3, 1.0, 15)
    shape[7] = 1.0  # the centre point
    panel = np.outer(v_rel, shape) + v_base[:, None] + noise_m_s * rng.standard_normal((t.size, 15))
    base = v_base[:, None] + noise_m_s * rng.standard_normal((t.size, 2))
    phase_deg = np.degrees(np.angle(np.exp(1j * theta)))
    data = np.column_stack([t, panel, base, np.full(t.size, F_LAB), phase_deg])
    return Record(data, StepSchedule([t[0], t[-1]], [1.0, 1.0]), "Config1_PRT_Assemb1")


def test_a_hold_keeps_the_analytical_harmonics_of_response_and_excitation():
    truth = np.array([RESPONSE_HARMONICS[2], RESPONSE_HARMONICS[3]])
    base_truth = np.array([BASE_HARMONICS[2], BASE_HARMONICS[3]])
    clean = extract_backbone(lab_hold(0.0, seed=0))
    # the drift of the mean leaks below 1e-6 of the fundamental; nothing else is left
    np.testing.assert_allclose(clean.harmonics[0], truth, atol=1e-6)
    np.testing.assert_allclose(clean.excitation_harmonics[0], base_truth, atol=1e-6)
    assert clean.amplitude_m[0] == pytest.approx(A_LAB, rel=1e-6)
    assert clean.mean_offset_m is None  # velocity sensors do not observe the mean

    noise = 2e-3
    noisy = extract_backbone(lab_hold(noise, seed=1))
    n = round(70 / F_LAB * FS_LAB)
    w = 2 * np.pi * F_LAB
    orders = np.array([2, 3])
    # least-squares standard error: σ_v √(2/N) / (h ω a), σ_v² = σ² (1 + 1/2)
    se_truth = noise * np.sqrt(1.5) * np.sqrt(2 / n) / (orders * w * A_LAB)
    np.testing.assert_allclose(noisy.harmonic_standard_error[0], se_truth, rtol=0.05)
    deviation = noisy.harmonics[0] - truth
    assert np.all(np.abs(deviation.real) < 4 * noisy.harmonic_standard_error[0])
    assert np.all(np.abs(deviation.imag) < 4 * noisy.harmonic_standard_error[0])
    # the base acceleration's harmonics: base noise σ/√2, relative error h σ_b √(2/N) / B
    se_base = noise / np.sqrt(2) * np.sqrt(2 / n) * orders / B_LAB
    assert np.all(np.abs(noisy.excitation_harmonics[0] - base_truth) < 4 * np.sqrt(2) * se_base)


def test_the_harmonics_standard_error_is_calibrated():
    """Over 40 noise draws the errors of the 2nd and 3rd harmonics (cos and sin parts)
    divided by their reported standard errors scatter like N(0, 1): their RMS within
    [0.8, 1.2] (3.5 standard deviations of an RMS of 160 values) and no mean offset."""
    truth = np.array([RESPONSE_HARMONICS[2], RESPONSE_HARMONICS[3]])
    z = []
    for seed in range(40):
        point = extract_backbone(lab_hold(2e-3, seed=seed, seconds=0.75))
        deviation = point.harmonics[0] - truth
        se = point.harmonic_standard_error[0]
        z += [*(deviation.real / se), *(-deviation.imag / se)]
    z = np.array(z)
    assert 0.8 < np.sqrt(np.mean(z**2)) < 1.2, z
    assert abs(z.mean()) < 3.5 / np.sqrt(z.size)


# ---------------------------------------------------------------------------
# The reference a hold is fitted against: ripple-free, following a drifting PLL


RIPPLE_AMPLITUDES = np.array([1e-4, 6e-4, 2e-3])
RIPPLE_FREQUENCIES = np.array([101.0, 100.4, 103.0])
RIPPLE_DAMPING = np.array([0.004, 0.006, 0.003])


def with_frequency_channel(record: Record, channel_hz: np.ndarray) -> Record:
    """The same record with another instantaneous-frequency channel."""
    data = record.data.copy()
    data[:, 18] = channel_hz
    return Record(data, record.steps, record.name)


def test_frequency_channel_ripple_leaves_the_backbone_and_harmonics_unchanged():
    """Acceptance (#14): a frequency channel carrying a 2ω ripple of 3 Hz and a 1ω ripple
    of 18 Hz gives the backbone and harmonics (within 0.01 % of the fundamental) of the
    same response with a clean channel, and both are the truth the record was built from."""
    clean = synthetic_record(RIPPLE_AMPLITUDES, RIPPLE_FREQUENCIES, RIPPLE_DAMPING,
                             third_harmonic=0.01)  # fmt: skip
    theta = np.unwrap(np.radians(clean.phase_deg))
    ripple = 3.0 * np.sin(2 * theta + 0.3) + 18.0 * np.sin(theta - 1.1)
    rippled = with_frequency_channel(clean, clean.frequency_hz + ripple)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no reference warning: the channel is right on average
        reference, measured = extract_backbone(clean), extract_backbone(rippled)
    for name in ("amplitude_m", "frequency_hz", "damping_ratio"):
        np.testing.assert_allclose(getattr(measured, name), getattr(reference, name), rtol=1e-4)
    for name in ("harmonics", "excitation_harmonics"):
        np.testing.assert_allclose(getattr(measured, name), getattr(reference, name), atol=1e-4)
    # the truth: a 3rd harmonic of 1 % at −0.4 rad (x ∝ cos θ + 0.01 cos(3θ + 0.4)), no 2nd
    truth = [0, 0.01 * np.exp(0.4j)]
    np.testing.assert_allclose(measured.harmonics, np.tile(truth, (3, 1)), atol=1e-4)
    np.testing.assert_allclose(measured.amplitude_m, RIPPLE_AMPLITUDES, rtol=1e-4)
    # The phase integrated from the rippled channel (the reference before #14) makes a
    # clean sinusoid look distorted: this test would catch a return to it.
    window = slice(-round(70 / 103.0 * FS), None)
    last = rippled.steps.holds()[2]
    hold = slice(*np.searchsorted(rippled.time_s, [last.start_s, last.end_s], side="right"))
    phase = 2 * np.pi * cumulative_trapezoid(rippled.frequency_hz[hold], rippled.time_s[hold],
                                             initial=0.0)[window]  # fmt: skip
    basis = np.column_stack([np.ones_like(phase), *(f(k * phase) for k in (1, 2, 3)
                                                    for f in (np.cos, np.sin))])  # fmt: skip
    coef = np.linalg.lstsq(basis, rippled.response_velocity[hold][window], rcond=None)[0]
    assert np.hypot(*coef[5:7]) / np.hypot(*coef[1:3]) > 5e-3


def drifting_hold(drift_hz_per_s: float, channel_scale: float = 1.0, seconds: float = 1.0):
    """One hold whose true PLL frequency drifts linearly (100 Hz + drift·t), written from
    the definitions: x = a cos θ + 0.01 a cos(3θ + 0.4) with θ = 2π∫f dt, the base in
    quadrature (phase resonance, damping ratio 0.4 %). The channel is f·channel_scale."""
    t = np.arange(int(seconds * FS)) / FS
    f = 100.0 + drift_hz_per_s * t
    theta = 2 * np.pi * cumulative_trapezoid(f, t, initial=0.0) + 0.7
    w = 2 * np.pi * f
    a, zeta = 1e-3, 0.004
    v = -a * w * np.sin(theta) - 0.01 * a * 3 * w * np.sin(3 * theta + 0.4)
    v_base = -2 * zeta * a * w * np.sin(theta + np.pi / 2)
    shape = np.ones(15)
    phase_deg = np.degrees(np.angle(np.exp(1j * theta)))
    panel = np.outer(v, shape) + v_base[:, None]
    data = np.column_stack([t, panel, v_base, v_base, channel_scale * f, phase_deg])
    return Record(data, StepSchedule([t[0], t[-1]], [1.0, 1.0]), "Config1_PRT_Assemb1"), f


def test_a_drifting_pll_frequency_within_a_hold_is_followed():
    """The PLL following the structure moves the frequency within a hold (legit): the
    reference follows it, so the point is the truth, not a smeared fit."""
    record, f = drifting_hold(0.8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        point = extract_backbone(record)
    window = slice(-round(70 / 100.75 * FS), None)
    assert point.amplitude_m[0] == pytest.approx(1e-3, rel=1e-6)
    assert point.damping_ratio[0] == pytest.approx(0.004, rel=1e-6)
    assert point.frequency_hz[0] == pytest.approx(f[window].mean(), abs=1e-3)
    np.testing.assert_allclose(point.harmonics[0], [0, 0.01 * np.exp(0.4j)], atol=1e-5)
    assert point.settled[0] and point.dropped_samples[0] == 0  # the displacement is steady
    # A constant-frequency reference (even at the window's mean) cannot follow it: the
    # phase walks 0.1 rad off at the window's ends, the 3rd harmonic turns by 0.3 rad and
    # a false 2nd harmonic appears.
    constant = extract_backbone(with_frequency_channel(record, np.full(f.size, f[window].mean())))
    assert np.abs(constant.harmonics[0] - [0, 0.01 * np.exp(0.4j)]).min() > 3e-4


def test_a_frequency_channel_off_the_base_motion_is_refined_on_it_and_warned_about():
    """A channel 0.3 % off (a scaled or foreign clock) would walk 1.3 rad over the window:
    the reference is refined on the base motion's own fundamental, with one warning line
    naming file and level."""
    record, _ = drifting_hold(0.0, channel_scale=1.003)
    with pytest.warns(UserWarning) as caught:
        point = extract_backbone(record)
    (message,) = [str(w.message) for w in caught]
    assert message.startswith("Config1_PRT_Assemb1: hold phase at level 1 (")
    assert "frequency channel is +0.3 Hz off the excitation's own fundamental" in message
    assert point.frequency_hz[0] == pytest.approx(100.0, abs=1e-4)
    assert point.amplitude_m[0] == pytest.approx(1e-3, rel=1e-5)
    np.testing.assert_allclose(point.harmonics[0], [0, 0.01 * np.exp(0.4j)], atol=1e-5)


def constant_frequency_fit(time_s, base, response, guess_hz, n_periods=70):
    """Frequency (Hz) and response displacement harmonics 2, 3 (fractions of the
    fundamental, in its own frame) of the last ``n_periods`` periods, fitted at one
    constant frequency that best fits the base signal (scipy's bounded scalar search
    within ±0.5 % of the guess): the textbook reference, written here apart from the
    package."""
    fs = 1 / np.median(np.diff(time_s))

    def fit(frequency, signal):
        n = round(n_periods / frequency * fs)
        theta = 2 * np.pi * frequency * time_s[-n:]
        basis = np.column_stack([np.ones(n), *(g(k * theta) for k in (1, 2, 3)
                                               for g in (np.cos, np.sin))])  # fmt: skip
        coef, residual, *_ = np.linalg.lstsq(basis, signal[-n:], rcond=None)
        return coef, residual.sum()

    frequency = minimize_scalar(lambda f: fit(f, base)[1], method="bounded",
                                bounds=(0.995 * guess_hz, 1.005 * guess_hz),
                                options={"xatol": 1e-8}).x  # fmt: skip
    coef = fit(frequency, response)[0]
    velocity = coef[1::2] - 1j * coef[2::2]
    displacement = velocity / (1j * np.arange(1, 4))
    k = np.arange(2, 4)
    own = displacement[1:] * np.exp(-1j * k * np.angle(displacement[0])) / abs(displacement[0])
    return frequency, own


def test_lab_ripple_gives_harmonics_at_the_noise_floor_like_a_constant_frequency_fit():
    """Acceptance (#14) on the lab rig: lab-ripple (a linear-viscous truth under a PLL whose
    frequency channel carries about 3 Hz of 2ω ripple) gives response harmonics at the
    noise floor, those of a constant-frequency fit of the same holds, without a reference
    warning. The phase integrated from the channel as recorded (the reference before #14)
    puts about 0.25 % of false 3rd harmonic on every point."""
    rig = rig_for_preset("lab-ripple", levels=4)
    record = rig.campaign(assemblies=1, seed=0)[0][0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        curve = extract_backbone(record)
    se = curve.harmonic_standard_error
    false_third = []
    for i, hold in enumerate(record.steps.holds()):
        rows = slice(*np.searchsorted(record.time_s, [hold.start_s, hold.end_s], "right"))
        t, base, response = (s[rows] for s in (record.time_s, record.excitation_velocity,
                                                record.response_velocity))  # fmt: skip
        channel = record.frequency_hz[rows]
        frequency, harmonics = constant_frequency_fit(t, base, response, np.median(channel))
        # within the fits' frequency noise (a few mHz at the lowest level's base noise)
        assert curve.frequency_hz[i] == pytest.approx(frequency, rel=1e-4)
        np.testing.assert_array_less(np.abs(curve.harmonics[i]), 4 * se[i] + 1e-6)
        np.testing.assert_array_less(np.abs(curve.harmonics[i] - harmonics), 3 * se[i])
        # the integrated channel as the reference
        n = round(70 / frequency * FS)
        phase = 2 * np.pi * cumulative_trapezoid(channel, t, initial=0.0)[-n:]
        basis = np.column_stack([np.ones(n), *(g(k * phase) for k in (1, 2, 3)
                                               for g in (np.cos, np.sin))])  # fmt: skip
        coef = np.linalg.lstsq(basis, response[-n:], rcond=None)[0]
        false_third.append(np.hypot(*coef[5:7]) / 3 / np.hypot(*coef[1:3]))
    assert min(false_third) > 1e-3 and (np.abs(curve.harmonics) < 1e-4).all()


# ---------------------------------------------------------------------------
# Vibrometer dropouts


def with_spikes(record: Record, seed: int, n_dropouts: int = 12) -> Record:
    """The record with speckle dropouts on the centre-point channel: runs of 1–4 samples
    replaced by values uniform within ±0.5 m/s."""
    rng = np.random.default_rng(seed)
    data = record.data.copy()
    for start in rng.choice(data.shape[0] - 4, n_dropouts, replace=False):
        length = int(rng.integers(1, 5))
        data[start : start + length, 8] = rng.uniform(-0.5, 0.5, length)
    return Record(data, record.steps, record.name)


def test_dropout_spikes_do_not_bias_a_hold_and_are_counted():
    clean_record = lab_hold(2e-3, seed=3)
    spiked_record = with_spikes(clean_record, seed=4)
    clean, spiked = extract_backbone(clean_record), extract_backbone(spiked_record)
    se = clean.harmonic_standard_error[0]
    assert clean.dropped_samples[0] == 0
    # every spike sample inside the window that stands out of the noise (10 σ; one that
    # lands on the signal can neither be seen nor matter) is dropped, few good ones with them
    window = slice(clean_record.time_s.size - round(70 / F_LAB * FS_LAB), None)
    error = np.abs(spiked_record.data[window, 8] - clean_record.data[window, 8])
    sigma = 2e-3 * np.sqrt(1.5)  # the relative velocity's noise
    assert np.count_nonzero(error > 10 * sigma) <= spiked.dropped_samples[0]
    assert spiked.dropped_samples[0] <= np.count_nonzero(error) + 2 * 12
    assert spiked.amplitude_m[0] == pytest.approx(clean.amplitude_m[0], rel=1e-5)
    assert spiked.damping_ratio[0] == pytest.approx(clean.damping_ratio[0], rel=1e-4)
    deviation = spiked.harmonics[0] - clean.harmonics[0]
    assert np.all(np.abs(deviation.real) < 0.3 * se) and np.all(np.abs(deviation.imag) < 0.3 * se)
    # what the spikes do to a plain least-squares fit: many standard errors
    plain = np.abs(_plain_third_harmonic(spiked_record) - _plain_third_harmonic(clean_record))
    assert plain > 3 * se[1]


def _plain_third_harmonic(record: Record) -> complex:
    """The response's 3rd harmonic (fraction of the fundamental) by a plain least-squares
    fit over the last 70 periods at the known constant frequency."""
    n = round(70 / F_LAB * FS_LAB)
    theta = 2 * np.pi * F_LAB * record.time_s[-n:]
    basis = np.column_stack([np.ones(n), *(f(k * theta) for k in (1, 2, 3)
                                           for f in (np.cos, np.sin))])  # fmt: skip
    coef = np.linalg.lstsq(basis, record.response_velocity[-n:], rcond=None)[0]
    return complex(coef[5] - 1j * coef[6]) / 3 / complex(coef[1] - 1j * coef[2])


def test_the_lab_rigs_dropouts_leave_the_backbone_of_the_same_record_without_them():
    """lab-dropouts (spikes to ±0.5 m/s at 0.5 per second per channel) against the same
    campaign without dropouts (same noise; the controller still reacts to the spikes it
    saw, so the physics differs a little): amplitude within 5e-4, damping 1e-3, harmonics
    within half their standard error. The plain fit was off by up to 0.8 % and 17 σ."""
    sensors = RIG_PRESETS["lab-dropouts"].lab["sensors"]
    for seed in (0, 3):
        curves = []
        for setting in (sensors, dataclasses.replace(sensors, dropout_rate_hz=0.0)):
            rig = rig_for_preset("lab-dropouts", levels=3, hold_s=1.5, sensors=setting)
            curves.append(extract_backbone(rig.campaign(assemblies=1, seed=seed)[0][0]))
        spiked, clean = curves
        np.testing.assert_allclose(spiked.amplitude_m, clean.amplitude_m, rtol=5e-4)
        # Damping within 1e-3 (a seventh of the damping floor): these 1.5 s holds have not
        # settled, and their stored-energy correction follows the amplitude trend, which a
        # spike's kick to the controller moves a little.
        np.testing.assert_allclose(spiked.damping_ratio, clean.damping_ratio, rtol=1e-3)
        deviation = np.abs(spiked.harmonics - clean.harmonics)
        assert np.all(deviation < 0.5 * clean.harmonic_standard_error)
        assert spiked.dropped_samples.sum() > 0 and clean.dropped_samples.sum() == 0


# ---------------------------------------------------------------------------
# How a point was measured: time, settling, lock


def test_points_carry_the_time_of_their_window_centre():
    record = synthetic_record(AMPLITUDES, FREQUENCIES, DAMPING)
    curve = extract_backbone(record, n_periods=50)
    hold_ends = np.arange(1, 5) * (HOLD_S + RAMP_S) - RAMP_S
    np.testing.assert_allclose(curve.time_s, hold_ends - 25 / FREQUENCIES, atol=1.5 / FS)


def base_excited_linear(frequency_hz: float, settle_periods: int, zeta: float = 0.01):
    """A linear oscillator (100 Hz, ζ) driven from rest by a_base = A sin ωt, simulated by
    the independent simulator; the record of 50 periods after ``settle_periods``."""
    omega_n, omega, amplitude = 2 * np.pi * 100.0, 2 * np.pi * frequency_hz, 10.0
    steady = forced_steady_state(
        lambda x, v: omega_n**2 * x + 2 * zeta * omega_n * v,
        lambda t: -amplitude * np.sin(omega * t),
        1 / frequency_hz,
        settle_periods=settle_periods,
        record_periods=50,
    )
    t = steady["time_s"]
    t_absolute = t + settle_periods / frequency_hz
    base_velocity = -amplitude / omega * np.cos(omega * t_absolute)
    return t, base_velocity, steady["velocity_m_s"], np.full(t.size, frequency_hz)


def test_a_hold_that_has_not_settled_is_flagged_with_its_amplitude_trend():
    """From rest at resonance the amplitude grows as 1 − e^{−ζω_n t}: 30 periods in, it
    still grows by about 8 % over a 40-period window (the least-squares slope of that
    envelope over the window, relative to its value at the centre); 400 periods in it has
    settled."""
    t, base, response, channel = base_excited_linear(100.0, settle_periods=30)
    point = hold_point(t, base, response, channel, n_periods=40)
    sigma = 0.01 * 2 * np.pi * 100.0
    start = 30 / 100.0 + t[-1] - 40 / 100.0  # absolute time of the window's start
    window = start + np.linspace(0, 40 / 100.0, 2001)
    envelope = 1 - np.exp(-sigma * window)
    slope = np.polyfit(window - window.mean(), envelope, 1)[0]
    expected = slope * 0.4 / (1 - np.exp(-sigma * window.mean()))
    assert expected > 0.05
    assert point.amplitude_change == pytest.approx(expected, rel=0.02)
    assert not point.settled
    t, base, response, channel = base_excited_linear(100.0, settle_periods=400)
    settled = hold_point(t, base, response, channel, n_periods=40)
    assert settled.settled and abs(settled.amplitude_change) < 1e-6


def test_the_power_balance_off_resonance_is_the_viscous_damping():
    """Detuned by 0.2 % (a PLL locked 11° off), the steady state of a viscously damped
    oscillator gives the phase error of the closed-form FRF and, through the power balance
    with cos(phase error), the damping ratio ζω_n/ω of an equivalent viscous damper."""
    zeta, f_n = 0.01, 100.0
    for frequency_hz in (100.2, 99.6):
        t, base, response, channel = base_excited_linear(frequency_hz, 400, zeta)
        point = hold_point(t, base, response, channel, n_periods=40)
        w, w_n = 2 * np.pi * frequency_hz, 2 * np.pi * f_n
        # V/V_b = −ω²X/A_b = ω²/(ω_n² − ω² + 2iζω_nω) for the relative velocity
        ratio = w**2 / (w_n**2 - w**2 + 2j * zeta * w_n * w)
        expected_error = np.degrees(np.angle(ratio * 1j))
        assert abs(expected_error) > 10
        assert point.phase_error_deg == pytest.approx(expected_error, abs=1e-3)
        assert point.damping_ratio == pytest.approx(zeta * w_n / w, rel=1e-5)
        assert point.settled


def test_a_lab_holds_settling_is_what_the_rigs_true_state_shows():
    """lab-lock (a slow loop): the amplitude change each point reports over its window is
    that of the rig's true displacement (its least-squares slope over the window's
    periods); with the preset's 1.5 s holds every point is still moving by about 10 % and
    flagged, with 3 s holds none is."""
    flags = []
    for hold_s in (1.5, 3.0):
        rig = rig_for_preset("lab-lock", levels=4, noise_m_s=0.0, hold_s=hold_s)  # the true run
        record, _ = rig.campaign(assemblies=1, seed=1)[0]
        curve, points = extract_backbone(record), []
        for hold in record.steps.holds():
            rows = slice(*np.searchsorted(record.time_s, [hold.start_s, hold.end_s], "right"))
            signals = (record.excitation_velocity, record.response_velocity, record.frequency_hz)
            points.append(hold_point(record.time_s[rows], *(s[rows] for s in signals)))
        series = rig.run(rig.draw_assembly(np.random.default_rng([1, 1])))  # seed 1, assembly 1
        ramp, hold = rig._samples()
        changes = []
        for level, point in enumerate(points):
            end = (level + 1) * (ramp + hold)
            x = series.x[end - round(70 * rig.fs / point.frequency_hz) : end]
            per_period = x.size // 70
            peaks = np.array([np.ptp(x[k * per_period : (k + 1) * per_period]) for k in range(70)])
            slope = np.polyfit(np.arange(70) - 34.5, peaks, 1)[0]
            changes.append(slope * 70 / peaks.mean())
        np.testing.assert_allclose([p.amplitude_change for p in points], changes, atol=2e-3)
        np.testing.assert_array_equal(curve.settled, np.abs(changes) <= 0.01)
        flags.append(curve.settled)
    assert not flags[0].any() and flags[1].all()
