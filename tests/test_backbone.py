"""Backbone containers and their extraction from phase-resonance records."""

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pandas as pd
import pytest
from scipy.integrate import cumulative_trapezoid

from identification.measurements.backbone import (
    TABLE_COLUMNS,
    Backbone,
    BackboneSet,
    extract_backbone,
    extract_backbones,
)
from identification.measurements.records import Campaign, Record, StepSchedule, write_record

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


# ---------------------------------------------------------------------------
# Containers


def _curve(label="a", amplitude_mm=(0.1, 0.5, 1.0, 2.0), freq=(101, 100, 103, 110), **kw):
    return Backbone(
        amplitude_m=1e-3 * np.asarray(amplitude_mm),
        frequency_hz=freq,
        damping_ratio=kw.pop("damping", (0.002, 0.006, 0.005, 0.004)),
        label=label,
        **kw,
    )


@pytest.mark.parametrize("field", ["amplitude_m", "frequency_hz", "damping_ratio",
                                   "excitation_level", "phase_error_deg"])  # fmt: skip
def test_non_finite_values_name_the_field(field):
    values = {
        "amplitude_m": [1e-4, 2e-4], "frequency_hz": [100.0, 101.0], "damping_ratio": [0.01, 0.01],
        "excitation_level": [1.0, 2.0], "phase_error_deg": [0.0, 0.0],
    }  # fmt: skip
    values[field][1] = np.nan
    with pytest.raises(ValueError, match=rf"backbone 'x': {field}\[1\] is not finite"):
        Backbone(**values, label="x")


def test_invalid_backbones():
    with pytest.raises(ValueError, match=r"amplitude_m\[0\] is negative"):
        _curve(amplitude_mm=(-0.1, 0.5, 1.0, 2.0))
    with pytest.raises(ValueError, match="frequency_hz has 3 values, expected 4"):
        _curve(freq=(1, 2, 3))
    with pytest.raises(ValueError, match=r"frequency_hz\[1\] is not positive"):
        _curve(freq=(100, 0, 100, 100))


def test_interpolation_matches_piecewise_linear():
    curve = _curve()
    query = 1e-3 * np.array([0.1, 0.3, 0.75, 2.0])
    expected = np.interp(query, curve.amplitude_m, curve.frequency_hz)
    np.testing.assert_allclose(curve.frequency_at(query), expected, rtol=1e-12)
    np.testing.assert_allclose(
        curve.damping_at(query), np.interp(query, curve.amplitude_m, curve.damping_ratio)
    )
    with pytest.raises(ValueError, match=r"amplitude 2.5 mm is outside the curve's range 0.1–2 mm"):
        curve.frequency_at(2.5e-3)
    # extrapolation continues the last segment: 103 → 110 Hz over 1 → 2 mm
    assert curve.frequency_at(2.5e-3, extrapolate=True) == pytest.approx(113.5)


def test_up_and_down_stepping_interpolates_the_sorted_branch():
    curve = _curve(amplitude_mm=(0.1, 1.0, 2.0, 1.0, 0.1), freq=(101, 103, 110, 105, 101),
                   damping=(0.002, 0.005, 0.004, 0.007, 0.002))  # fmt: skip
    with pytest.warns(UserWarning, match="not monotonic"):
        assert curve.frequency_at(1e-3) == pytest.approx(104.0)  # mean of up and down
    assert curve.damping_at(1.5e-3) == pytest.approx((0.006 + 0.004) / 2)
    assert len(curve) == 5  # storage keeps both branches


def test_set_range_matrix_and_labels():
    curves = BackboneSet([_curve("a"), _curve("b", amplitude_mm=(0.2, 0.6, 1.2, 1.5)),
                          _curve("", amplitude_mm=(0.05, 0.5, 1.0, 3.0))])  # fmt: skip
    assert curves.labels == ["a", "b", "curve2"]
    lo, hi = curves.common_range()
    assert (lo, hi) == pytest.approx((0.2e-3, 1.5e-3))
    grid = np.linspace(lo, hi, 5)
    matrix = curves.frequency_matrix(grid)
    assert matrix.shape == (3, 5)
    np.testing.assert_allclose(matrix[1], curves["b"].frequency_at(grid))
    assert curves.damping_matrix(grid).shape == (3, 5)
    with pytest.raises(ValueError, match="duplicated curve labels"):
        BackboneSet([_curve("a"), _curve("a")])
    with pytest.raises(ValueError, match="share no amplitude range"):
        BackboneSet([_curve("a"), _curve("c", amplitude_mm=(3, 4, 5, 6))]).common_range()


def test_table_and_csv_round_trip(tmp_path):
    record = synthetic_record(AMPLITUDES, FREQUENCIES, DAMPING, phase_errors_deg=[1, 2, 3, 4])
    curves = BackboneSet([extract_backbone(record, n_periods=40), _curve("model")])
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


def test_bad_tables_name_the_problem(tmp_path):
    with pytest.raises(ValueError, match=r"missing column\(s\) \['damping_ratio'\]"):
        BackboneSet.from_table(pd.DataFrame({"curve": ["a"], "amplitude_mm": [1.0],
                                             "frequency_hz": [100.0]}))  # fmt: skip
    path = tmp_path / "t.csv"
    path.write_text("curve,amplitude_mm,frequency_hz,damping_ratio\na,0.1,100,0.01\na,0.2,,0.01\n")
    with pytest.raises(ValueError, match=r"t.csv: curve 'a': .*frequency_hz\[1\] is not finite"):
        BackboneSet.from_csv(path)


def test_plot_draws_frequency_and_damping():
    curves = BackboneSet([_curve("a"), _curve("b", freq=(100, 99, 101, 104))])
    freq_ax, damp_ax = curves.plot()
    assert len(freq_ax.lines) == 2 and len(damp_ax.lines) == 2
    np.testing.assert_allclose(freq_ax.lines[1].get_ydata(), [100, 99, 101, 104])
    np.testing.assert_allclose(damp_ax.lines[0].get_xdata(), [0.1, 0.5, 1.0, 2.0])
    assert damp_ax.get_ylabel() == "damping ratio (%)"
