"""Real-file papercuts: what lab software writes that the readers must take as it is.

* A TRC folder exported in a German locale (decimal commas, semicolons between
  columns) gives the backbones of the original to the last digit written, the
  decimal comma detected or stated (``--decimal-comma``).
* Time stamps rounded when written (7 significant digits: steps of 0.0001953 and
  0.0001954 s at 5120 Hz, then 0.000195 and 0.000196 s past one second) are read on
  the uniform grid of their mean rate, said in one warning; a real gap (a missing
  sample, a jump of steps) is still refused.
"""

import warnings

import numpy as np
import pandas as pd
import pytest
from independent_sim import free_decay
from oscillators import duffing

from identification.measurements.columns import (
    ColumnCampaign,
    ColumnLayout,
    ColumnRecord,
    read_columns,
)
from identification.rig import Rig
from pm_joint.cli import main

# ---------------------------------------------------------------------------
# TRC folders with decimal commas and semicolons


@pytest.fixture(scope="module")
def trc_folders(tmp_path_factory):
    """A small rig campaign in the TRC layout, and the same files in a German locale."""
    original = tmp_path_factory.mktemp("trc") / "campaign"
    rig = Rig(duffing(), levels_v=(0.05, 0.1, 0.2), hold_s=0.4, ramp_s=0.05)
    rig.write_campaign(original, assemblies=2, seed=4)
    german = tmp_path_factory.mktemp("trc_german") / "campaign"
    german.mkdir()
    for path in original.iterdir():
        text = path.read_text()
        if path.name.startswith("Config"):  # the TRC files; ground_truth.json stays as it is
            text = text.replace(".", ",").replace(" ", ";")
        (german / path.name).write_text(text)
    return original, german


def _backbones_csv(folder, tmp_path, *options):
    out = tmp_path / f"{folder.parent.name}{len(options)}.csv"
    assert main(["backbones", str(folder), "--periods", "20", "--out", str(out), *options]) == 0
    # the source column names the file read: the same name in another folder
    return out.read_text().replace(str(folder), "CAMPAIGN")


def test_a_german_locale_trc_folder_gives_the_same_backbones(trc_folders, tmp_path):
    original, german = trc_folders
    sample = (german / "Config1_PRT_Assemb1").read_text().splitlines()[0]
    assert ";" in sample and "," in sample and "." not in sample
    reference = _backbones_csv(original, tmp_path)
    assert len(reference.splitlines()) == 1 + 2 * 3  # a header, 3 holds of 2 records
    assert _backbones_csv(german, tmp_path) == reference
    assert _backbones_csv(german, tmp_path, "--decimal-comma") == reference


def test_a_stated_decimal_comma_with_comma_columns_is_refused(tmp_path, capsys):
    folder = tmp_path / "campaign"
    rig = Rig(duffing(), levels_v=(0.05,), hold_s=0.3, ramp_s=0.05)
    rig.write_campaign(folder, assemblies=1, comma=True)
    assert main(["backbones", str(folder), "--decimal-comma"]) == 2
    err = capsys.readouterr().err
    assert "a decimal comma cannot go with comma-separated columns" in err


# ---------------------------------------------------------------------------
# Time stamps rounded when written

FS = 5120.0
OMEGA0 = 2 * np.pi * 105.0


def _force(x, v):
    return OMEGA0**2 * x + 2 * 0.004 * OMEGA0 * v + 4.0e10 * x**3


@pytest.fixture(scope="module")
def ring():
    decay = free_decay(_force, 1.0e-3, 0.0, fs_hz=FS, duration_s=1.6)
    return pd.DataFrame({"time": decay["time_s"], "displacement": decay["displacement_m"]})


def _write(table, path, time_format=None):
    table = table.copy()
    if time_format:  # the time column as the lab's software wrote it; the rest in full
        table["time"] = table["time"].map(time_format.format).astype(float)
    table.to_csv(path, index=False)
    return path


LAYOUT = ColumnLayout(test="free-decay", quantity="displacement")


def test_rounded_time_stamps_are_read_at_the_mean_rate(ring, tmp_path):
    exact = _write(ring, tmp_path / "exact.csv")
    rounded = _write(ring, tmp_path / "rounded.csv", "{:.7g}")
    stamps = pd.read_csv(rounded)["time"].to_numpy()
    steps = np.round(np.diff(stamps), 10)
    assert {0.0001953, 0.0001954} <= set(steps) and {0.000195, 0.000196} <= set(steps)
    assert np.abs(np.diff(stamps) * FS - 1).max() > 1e-3  # refused before

    with pytest.warns(UserWarning) as caught:
        record = read_columns(rounded, LAYOUT)
    (message,) = [str(w.message) for w in caught]
    assert message.startswith(f"{rounded}: time stamps jitter by up to 0.")
    assert "rounded when written?" in message and "uniform grid of their mean rate" in message
    assert record.time_jitter > 1e-3
    assert record.sampling_rate_hz == pytest.approx(FS, rel=1e-6)  # the rounding of the ends
    np.testing.assert_allclose(np.diff(record.time_s) * FS, 1, atol=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # exact stamps: no warning
        assert read_columns(exact, LAYOUT).time_jitter == 0.0

    tables = {}
    for path in (exact, rounded):
        out = tmp_path / f"{path.stem}_backbones.csv"
        argv = ["backbones", str(path), "--test", "free-decay", "--quantity", "displacement"]
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            assert main([*argv, "--out", str(out)]) == 0
        said = [str(w.message) for w in caught if "rounded when written" in str(w.message)]
        assert len(said) == (path == rounded), said
        tables[path.stem] = pd.read_csv(out)
    reference, read = tables["exact"], tables["rounded"]
    assert len(reference) >= 10 and len(read) == len(reference)
    # The grid's rate is off by the rounding of the first and last stamp (5e-7 s in 1.6 s).
    for column, rtol in [("frequency_hz", 1e-6), ("damping_ratio", 1e-4), ("amplitude_mm", 1e-5)]:
        np.testing.assert_allclose(read[column], reference[column], rtol=rtol, err_msg=column)


def test_rounded_time_stamps_are_said_once_for_a_campaign(ring, tmp_path):
    for name in ("a.csv", "b.csv", "c.csv"):
        _write(ring, tmp_path / name, "{:.7g}")
    campaign = ColumnCampaign(tmp_path, LAYOUT)
    with pytest.warns(UserWarning) as caught:
        records = list(campaign) + list(campaign)
    assert all(r.time_jitter > 1e-3 for r in records)
    (message,) = [str(w.message) for w in caught]
    assert str(tmp_path / "a.csv") in message and f"the records of {tmp_path}" in message


@pytest.mark.parametrize(
    ("damage", "row"),
    [
        ("missing sample", 3001),  # one sample left out: a step of two
        ("jump", 3001),  # the clock jumps ahead by five steps
        ("second rate", 4001),  # the rest at 5000 Hz: every step 2.4 % long
    ],
)
@pytest.mark.parametrize("time_format", [None, "{:.7g}"])
def test_a_real_gap_is_refused(ring, tmp_path, damage, row, time_format):
    table = ring.copy()
    if damage == "missing sample":
        table = table.drop(index=3000)
    elif damage == "jump":
        table.loc[3000:, "time"] += 5 / FS
    else:
        table.loc[4000:, "time"] = table["time"][4000] + (np.arange(len(table) - 4000) / 5000.0)
    path = _write(table.reset_index(drop=True), tmp_path / "gap.csv", time_format)
    with pytest.raises(ValueError, match="not uniformly sampled") as error:
        read_columns(path, LAYOUT)
    message = str(error.value)
    assert message.startswith(f"{path}: ") and "resample first" in message
    if damage != "second rate":  # a change of rate shows where the drift is too large
        assert f"at row {row}," in message
    assert main(["backbones", str(path), "--test", "free-decay", "--quantity", "displacement"]) == 2


def test_exact_stamps_are_kept_as_written():
    t = 12.5 + np.arange(1000) / 1e4
    record = ColumnRecord(t, np.sin(2 * np.pi * 100 * t), "velocity", "r", test="free-decay")
    np.testing.assert_array_equal(record.time_s, t)
    assert record.time_jitter == 0.0
