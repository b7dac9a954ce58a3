"""Backbone containers: validation, interpolation, sets, tables and their CSV."""

import matplotlib

matplotlib.use("Agg")

import numpy as np
import pandas as pd
import pytest

from identification.measurements.backbone import TABLE_COLUMNS, Backbone, BackboneSet

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


# ---------------------------------------------------------------------------
# What the hold fits measured: harmonics, their standard errors, the mean offset

HARMONICS = np.array([[0.01 - 0.002j, 1e-3j], [0.02, -1e-3], [0.03 + 0.01j, 2e-3], [0.0, 0.0]])


def test_hold_fit_arrays_are_checked_and_frozen():
    curve = _curve(harmonics=HARMONICS, harmonic_standard_error=np.full((4, 2), 1e-5),
                   mean_offset_m=[np.nan, 1e-6, np.nan, 2e-6])  # fmt: skip
    assert curve.harmonic_orders == (2, 3)
    assert curve.harmonics.dtype == complex and not curve.harmonics.flags.writeable
    np.testing.assert_array_equal(curve.mean_offset_m, [np.nan, 1e-6, np.nan, 2e-6])
    # a curve whose sensor never observes the mean has none
    assert _curve(mean_offset_m=np.full(4, np.nan)).mean_offset_m is None
    assert _curve(harmonics=HARMONICS[:, 0]).harmonic_orders == (2,)  # one order as a vector
    with pytest.raises(ValueError, match=r"harmonics has shape \(3, 2\), expected \(4, n_orders\)"):
        _curve(harmonics=HARMONICS[:3])
    bad = HARMONICS.copy()
    bad[2, 1] = np.nan
    with pytest.raises(
        ValueError, match=r"backbone 'a': excitation_harmonics\[2, 1\] is not finite"
    ):
        _curve(excitation_harmonics=bad)
    with pytest.raises(ValueError, match="harmonic_standard_error needs harmonics"):
        _curve(harmonic_standard_error=np.full((4, 2), 1e-5))
    with pytest.raises(ValueError, match="harmonic_standard_error is negative"):
        _curve(harmonics=HARMONICS, harmonic_standard_error=np.full((4, 2), -1.0))
    with pytest.raises(ValueError, match="mean_offset_m must have 4 values"):
        _curve(mean_offset_m=[0.0, np.inf, 0.0, 0.0])
    stripped = BackboneSet([_curve(harmonics=HARMONICS, excitation_harmonics=HARMONICS)])
    stripped = stripped.without_harmonics()[0]
    assert stripped.harmonics is None and stripped.excitation_harmonics is None


def test_harmonic_columns_round_trip_and_old_tables_still_read(tmp_path):
    four = np.column_stack([HARMONICS, [1e-4, 2e-4, 0.0, -1e-4], [5e-5, 0.0, 0.0, 1e-5]])
    curves = BackboneSet([
        _curve("three", harmonics=HARMONICS, harmonic_standard_error=np.full((4, 2), 1e-5),
               excitation_harmonics=0.5 * HARMONICS, mean_offset_m=[np.nan, 1e-6, 0.0, 2e-6]),
        _curve("five", harmonics=four),
        _curve("none"),
    ])  # fmt: skip
    table = curves.to_table()
    # the cos part is the real part, the sin part minus the imaginary part (C_h − i S_h)
    rows = table[table.curve == "three"]
    np.testing.assert_array_equal(rows["harmonic2_cos"], HARMONICS[:, 0].real)
    np.testing.assert_array_equal(rows["harmonic2_sin"], -HARMONICS[:, 0].imag)
    np.testing.assert_array_equal(rows["mean_offset_mm"], [np.nan, 1e-3, 0.0, 2e-3])
    # orders above 3 add their columns after the standard ones
    assert list(table.columns[: len(TABLE_COLUMNS)]) == list(TABLE_COLUMNS)
    assert {"harmonic5_cos", "harmonic5_sin", "harmonic5_se"} <= set(table.columns)
    back = BackboneSet.from_csv(curves.to_csv(tmp_path / "backbones.csv"))
    for name in ("harmonics", "harmonic_standard_error", "excitation_harmonics"):
        for a, b in zip(curves, back, strict=True):
            if getattr(a, name) is None:
                assert getattr(b, name) is None, (a.label, name)
            else:
                np.testing.assert_array_equal(getattr(b, name), getattr(a, name))
    assert back["five"].harmonic_orders == (2, 3, 4, 5)
    np.testing.assert_array_equal(back["three"].mean_offset_m, curves["three"].mean_offset_m)
    # a table written before the harmonics were kept
    old = tmp_path / "old.csv"
    old.write_text("curve,amplitude_mm,frequency_hz,damping_ratio\na,0.1,100,0.01\na,0.2,99,0.01\n")
    (curve,) = BackboneSet.from_csv(old)
    assert curve.harmonics is None and curve.mean_offset_m is None
