"""Backbone extraction from phase-resonance records: the points, the harmonics their
hold fits keep, and the table round trip of what was extracted."""

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from identification.measurements.backbone import TABLE_COLUMNS, Backbone, BackboneSet
from identification.measurements.extraction import extract_backbone, extract_backbones
from identification.measurements.records import Campaign, Record, StepSchedule, write_record
from identification.rig import trc_channels

FS = 10_000.0
HOLD_S = 0.8  # 80 periods at 100 Hz: room for the 70 measured ones
RAMP_S = 0.05


def synthetic_record(
    amplitudes_m,
    frequencies_hz,
    damping,
    phase_errors_deg=None,
    third_harmonic=0.0,
    levels=None,
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
    levels = np.arange(1, n + 1) * 0.1 if levels is None else np.asarray(levels)
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
    return Record(data, StepSchedule(breakpoints, np.repeat(levels, 2)), name)


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
    levels = (0.1, 0.2, 0.3, 0.4)
    assert all(f"level {v} (" in str(w.message) for w, v in zip(caught, levels, strict=True))
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
    for name in ("harmonics", "harmonic_standard_error", "excitation_harmonics"):
        np.testing.assert_array_equal(getattr(back[0], name), getattr(curves[0], name))
        assert getattr(back["model"], name) is None
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
