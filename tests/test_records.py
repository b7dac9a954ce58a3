"""TRC record I/O: round trips, foreign files, campaigns, and clear errors."""

from pathlib import Path

import numpy as np
import pytest

from identification.measurements.records import (
    DATA_COLUMNS,
    Campaign,
    Hold,
    Modes,
    Record,
    StepSchedule,
    read_modes,
    read_record,
    read_steps,
    record_name,
    write_record,
)

FS = 10_000.0


def _record(name="Config1_PRT_Assemb2_3", n=2_000, seed=0, modes=True) -> Record:
    rng = np.random.default_rng(seed)
    data = rng.standard_normal((n, len(DATA_COLUMNS))) * 10.0 ** rng.integers(-6, 1, (n, 20))
    data[:, 0] = 12.5 + np.arange(n) / FS  # a clock that does not start at 0
    data[:, -2] = 100 + rng.random(n)
    t_end = data[-1, 0]
    mid = 0.5 * (12.5 + t_end)
    steps = StepSchedule([12.5, mid, mid + 1e-3, t_end], [0.1, 0.1, 0.25, 0.25])
    shapes = rng.standard_normal((15, 2)) + 1j * rng.standard_normal((15, 2))
    return Record(data, steps, name, modes=Modes(shapes, [101.2, 250.0]) if modes else None)


def _as_written(values, precision=9):
    """What a %.{precision}e text file holds, parsed by Python's own float()."""
    return np.vectorize(lambda x: float(f"{x:.{precision}e}"))(values)


@pytest.mark.parametrize(("comma", "extension"), [(False, ""), (False, ".txt"), (True, ".csv")])
def test_round_trip(tmp_path, comma, extension):
    record = _record()
    path = write_record(record, tmp_path, comma=comma, extension=extension)
    assert path.name == f"Config1_PRT_Assemb2_3{extension}"
    assert (tmp_path / f"Config1_PRT_amplitude_steps{extension}").is_file()
    back = read_record(path)
    np.testing.assert_array_equal(back.data, _as_written(record.data))
    np.testing.assert_array_equal(back.steps.time_s, _as_written(record.steps.time_s))
    np.testing.assert_array_equal(back.steps.level, record.steps.level)
    np.testing.assert_array_equal(back.modes.shapes.real, _as_written(record.modes.shapes.real))
    np.testing.assert_array_equal(back.modes.shapes.imag, _as_written(record.modes.shapes.imag))
    np.testing.assert_array_equal(back.modes.frequencies_hz, record.modes.frequencies_hz)
    assert (back.name, back.config, back.assembly, back.run) == (record.name, "1", "2", "3")
    assert back.path == path


def test_record_is_read_only_and_keeps_callers_array():
    data = _record().data.copy()
    record = Record(data, _record().steps, "Config1_PRT_Assemb1")
    data[0, 1] = 99.0  # the record made its own copy
    assert record.data[0, 1] != 99.0
    with pytest.raises(ValueError, match="read-only"):
        record.data[0, 1] = 1.0


def test_foreign_comma_separated_file(tmp_path):
    """A file written by another program: header line, blanks after commas, CRLF."""
    rows = []
    for i in range(50):
        t = 0.5 + i * 1e-4
        panel = [0.01 * p + 0.001 * i for p in range(1, 16)]
        base = [0.002 + 1e-5 * i, 0.004 + 1e-5 * i]
        rows.append([t, *panel, *base, 101.25, -170.0 + 7 * i])
    header = "t," + ",".join(f"v{p}" for p in range(1, 18)) + ",f,phi"
    lines = [header] + [", ".join(f"{x:.6f}" for x in r) for r in rows]
    (tmp_path / "Config7_PRT_Assemb3.csv").write_text("\r\n".join(lines) + "\r\n")
    (tmp_path / "Config7_PRT_amplitude_steps.csv").write_text("0.0,0.5\n0.6,0.5\n")

    record = read_record(tmp_path / "Config7_PRT_Assemb3.csv")

    expected = np.round(np.array(rows), 6)
    np.testing.assert_allclose(record.data, expected, rtol=0, atol=1e-15)
    assert (record.config, record.assembly, record.run) == ("7", "3", None)
    np.testing.assert_allclose(record.excitation_velocity, (expected[:, 16] + expected[:, 17]) / 2)
    np.testing.assert_allclose(
        record.response_velocity, expected[:, 8] - record.excitation_velocity
    )
    assert record.sampling_rate_hz == pytest.approx(1e4, rel=1e-9)
    assert record.modes is None
    assert record.steps.holds() == [Hold(0.5, 0.0, 0.6)]


def test_modes_in_matlab_and_pair_forms(tmp_path):
    shape = np.linspace(0.1, 1.0, 15) * (1 - 0.02j)
    matlab = [f"{z.real:.6f}{z.imag:+.6f}i" for z in shape] + ["98.5"]
    (tmp_path / "m_complex").write_text("\n".join(matlab) + "\n")
    pairs = [f"{z.real:.6f}\t{z.imag:.6f}" for z in shape] + ["98.5\t0"]
    (tmp_path / "m_pairs").write_text("% exported modes\n" + "\n".join(pairs) + "\n")

    for modes in (read_modes(tmp_path / "m_complex"), read_modes(tmp_path / "m_pairs", pairs=True)):
        np.testing.assert_allclose(
            modes.first_bending, np.round(shape.real, 6) + 1j * np.round(shape.imag, 6)
        )
        np.testing.assert_array_equal(modes.frequencies_hz, [98.5])


def test_hold_phases_from_breakpoints_and_from_a_sampled_signal():
    breakpoints = StepSchedule([0, 1, 1.2, 2, 2.0, 3], [1, 1, 2, 2, 0.5, 0.5])
    assert breakpoints.holds() == [Hold(1, 0, 1), Hold(2, 1.2, 2), Hold(0.5, 2, 3)]
    t = np.arange(0, 3, 0.5)
    sampled = StepSchedule(t, [1, 1, 1, 2, 2, 2])
    assert sampled.holds() == [Hold(1, 0, 1), Hold(2, 1.5, 2.5)]
    np.testing.assert_allclose(breakpoints.level_at([0.5, 1.1]), [1, 1.5])


def test_campaign_groups_and_orders_records(tmp_path):
    for config, assembly, run in [(1, 10, None), (1, 2, None), (2, 1, 2), (2, 1, 1)]:
        name = record_name(config, assembly, run)
        write_record(_record(name, n=300, modes=config == 1), tmp_path, extension=".dat")
    (tmp_path / "ground_truth.json").write_text("{}")
    (tmp_path / ".Config1_PRT_Assemb2.dat.tmp").write_text("partial")

    campaign = Campaign(tmp_path)

    expected = ["Config1_PRT_Assemb2", "Config1_PRT_Assemb10",
                "Config2_PRT_Assemb1_1", "Config2_PRT_Assemb1_2"]  # fmt: skip
    assert campaign.names == expected
    assert len(campaign) == 4
    assert [r.name for r in campaign] == expected
    assert campaign["Config2_PRT_Assemb1_2"].run == "2"
    assert campaign[0].modes is not None and campaign[-1].modes is None
    assert [r.name for r in campaign[1:3]] == expected[1:3]


def test_campaign_without_step_file(tmp_path):
    write_record(_record("Config3_PRT_Assemb1", n=100), tmp_path)
    (tmp_path / "Config3_PRT_amplitude_steps").unlink()
    with pytest.raises(
        ValueError, match=r"Config3_PRT_Assemb1: no step file Config3_PRT_amplitude"
    ):
        Campaign(tmp_path)
    with pytest.raises(ValueError, match="no step file"):
        read_record(tmp_path / "Config3_PRT_Assemb1")
    with pytest.raises(ValueError, match="no TRC data files"):
        Campaign(tmp_path / "..")


def test_records_of_a_config_must_share_the_step_file(tmp_path):
    write_record(_record("Config1_PRT_Assemb1", n=300), tmp_path)
    with pytest.raises(ValueError, match="must share one step schedule"):
        write_record(_record("Config1_PRT_Assemb2", n=400), tmp_path)


# ---------------------------------------------------------------------------
# Bad input


def _write_lines(path: Path, rows, sep=" "):
    path.write_text("".join(sep.join(str(x) for x in row) + "\n" for row in rows))
    return path


def _good_rows(n=20):
    return [[i * 1e-4] + [0.001 * i] * 17 + [100.0, 0.0] for i in range(n)]


@pytest.fixture
def steps_file(tmp_path):
    return _write_lines(tmp_path / "Config1_PRT_amplitude_steps", [[0, 1], [1, 1]])


def test_wrong_column_count(tmp_path, steps_file):
    rows = [r[:-1] for r in _good_rows()]
    path = _write_lines(tmp_path / "Config1_PRT_Assemb1", rows)
    with pytest.raises(ValueError, match=r"Config1_PRT_Assemb1: found 19 columns, expected 20"):
        read_record(path)


def test_row_with_extra_or_missing_column(tmp_path, steps_file):
    rows = _good_rows()
    rows[4] = [*rows[4], 7.0]
    path = _write_lines(tmp_path / "Config1_PRT_Assemb1", rows)
    with pytest.raises(ValueError, match=r"Assemb1: row 5 \(line 5\) has 21 columns, expected 20"):
        read_record(path)
    rows = _good_rows()
    rows[6] = rows[6][:15]
    _write_lines(path, rows, sep=",")
    with pytest.raises(ValueError, match=r"row 7 \(line 7\) has 15 columns, expected 20"):
        read_record(path)


BAD_TOKENS = [("nan", "non-finite"), ("inf", "non-finite"), ("abc", "non-numeric"),
              ("", "non-numeric")]  # fmt: skip


@pytest.mark.parametrize(("token", "problem"), BAD_TOKENS)
def test_bad_samples_name_the_row(tmp_path, steps_file, token, problem):
    rows = _good_rows()
    rows[2][5] = token
    path = _write_lines(tmp_path / "Config1_PRT_Assemb1.csv", rows, sep=",")
    with pytest.raises(ValueError, match=rf"Assemb1.csv: row 3 \(line 3\), column 6: {problem}"):
        read_record(path, steps=steps_file)


def test_time_stamps_must_increase(tmp_path, steps_file):
    rows = _good_rows()
    rows[8][0] = rows[7][0]
    path = _write_lines(tmp_path / "Config1_PRT_Assemb1", rows)
    with pytest.raises(ValueError, match=r"Assemb1: time stamps duplicated at row 9"):
        read_record(path)
    rows[8][0] = 0.0
    _write_lines(path, rows)
    with pytest.raises(ValueError, match=r"time stamps not increasing at row 9"):
        read_record(path)


def test_step_file_must_cover_the_data(tmp_path):
    steps = _write_lines(tmp_path / "Config1_PRT_amplitude_steps", [[0, 1], [1e-3, 1]])
    path = _write_lines(tmp_path / "Config1_PRT_Assemb1", _good_rows(20))
    with pytest.raises(ValueError, match=r"Assemb1: step file .*amplitude_steps does not cover"):
        read_record(path)
    assert read_steps(steps).covers(0, 1e-3)


def test_bad_step_and_modes_files(tmp_path):
    path = _write_lines(tmp_path / "steps", [[0, 1, 2], [1, 1, 2]])
    with pytest.raises(ValueError, match=r"steps: found 3 columns, expected 2"):
        read_steps(path)
    _write_lines(path, [[0, 1], [1, "nan"]])
    with pytest.raises(ValueError, match=r"steps: row 2 \(line 2\), column 2: non-finite"):
        read_steps(path)
    modes = _write_lines(tmp_path / "modes", [[1.0]] * 15)
    with pytest.raises(ValueError, match=r"modes: found 15 rows, expected 16"):
        read_modes(modes)
    with pytest.raises(ValueError, match="not a valid TRC record name"):
        record_name("1", "A B")
