"""Records in the column layout: the files labs write, read through the command line.

One free decay of the independent simulator (scipy, nothing of pm-joint) is written here by
plain libraries as a lab's software would write it: CSV with a header, a German-locale export
(semicolons, decimal comma), MAT v5 (scipy.io), MAT v7.3 (HDF5 with MATLAB's 512-byte header,
n×1 arrays) and HDF5 (h5py). Each goes through ``pm-joint backbones FILE --test free-decay``
and must give the same backbone table to the last digit written.
"""

import subprocess
import sys

import h5py
import numpy as np
import pandas as pd
import pytest
import scipy.io
from independent_sim import free_decay

from identification.measurements.columns import ColumnLayout, read_columns
from pm_joint.cli import main

FS = 10_000.0
OMEGA0 = 2 * np.pi * 105.0


def _force(x, v):
    return OMEGA0**2 * x + 2 * 0.004 * OMEGA0 * v - 2.0e8 * x * x + 4.0e10 * x**3


@pytest.fixture(scope="module")
def ring():
    decay = free_decay(_force, 1.0e-3, 0.0, fs_hz=FS, duration_s=0.8)
    rng = np.random.default_rng(3)
    return {
        "time": decay["time_s"],
        "displacement": decay["displacement_m"] + 1e-4 + rng.normal(0, 1e-7, decay["time_s"].size),
    }


def _write_csv(ring, path):
    pd.DataFrame(ring).to_csv(path, index=False)  # full precision (repr of every float)


def _write_german(ring, path):
    # what a German-locale export writes: "Zeit [s];Weg [m]" header, 0,0001 for 0.0001
    text = pd.DataFrame(ring).to_csv(index=False, sep=";", decimal=",")
    path.write_text(text.replace("time;", "Time [s];"))


def _write_mat5(ring, path):
    scipy.io.savemat(path, {"time": ring["time"][:, None], "displacement": ring["displacement"]})


def _write_mat73(ring, path):
    # MATLAB's -v7.3: HDF5 with a 512-byte text header and each n×1 double stored as 1×n
    with h5py.File(path, "w", userblock_size=512) as fh:
        for name, values in ring.items():
            dataset = fh.create_dataset(name, data=values[None, :])
            dataset.attrs["MATLAB_class"] = np.bytes_(b"double")
    header = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 12:00:00 2026 HDF5"
    with open(path, "r+b") as fh:
        fh.write(header.ljust(128, b" "))


def _write_hdf5(ring, path):
    with h5py.File(path, "w") as fh:
        group = fh.create_group("measurement")
        for name, values in ring.items():
            group.create_dataset(name, data=values)


WRITERS = {
    "ring.csv": _write_csv,
    "ring_german.csv": _write_german,
    "ring.mat": _write_mat5,
    "ring73.mat": _write_mat73,
    "ring.h5": _write_hdf5,
}


@pytest.fixture(scope="module")
def backbone_tables(ring, tmp_path_factory):
    tables = {}
    for name, write in WRITERS.items():
        folder = tmp_path_factory.mktemp(name.replace(".", "_"))
        path = folder / name
        write(ring, path)
        out = folder / "backbones.csv"
        argv = ["backbones", str(path), "--test", "free-decay", "--response", "displacement",
                "--quantity", "displacement", "--out", str(out)]  # fmt: skip
        assert main(argv) == 0, name
        tables[name] = pd.read_csv(out).drop(columns=["curve", "source"], errors="ignore")
    return tables


def test_every_format_gives_the_same_backbone(backbone_tables):
    reference = backbone_tables["ring.csv"]
    assert len(reference) >= 20 and reference["mean_offset_mm"].notna().all()
    for name, table in backbone_tables.items():
        pd.testing.assert_frame_equal(table, reference, check_exact=True, obj=name)


def test_the_decimal_comma_is_detected_and_can_be_stated(ring, tmp_path):
    path = tmp_path / "ring.csv"
    _write_german(ring, path)
    detected = read_columns(path, ColumnLayout(test="free-decay", quantity="displacement"))
    stated = read_columns(path, ColumnLayout(test="free-decay", quantity="displacement",
                                             decimal_comma=True))  # fmt: skip
    np.testing.assert_array_equal(detected.response, ring["displacement"])
    np.testing.assert_array_equal(stated.time_s, ring["time"])
    assert detected.response_name == "displacement"


def test_a_file_cut_short_is_one_warning_naming_it(ring, tmp_path):
    path = tmp_path / "cut.csv"
    _write_csv(ring, path)
    text = path.read_text()
    path.write_text(text[: text.rfind("\n", 0, -1) + 8])  # the last line cut mid-number
    argv = ["backbones", str(path), "--test", "free-decay", "--quantity", "displacement"]
    # a process of its own: what the terminal shows (pytest records warnings in-process)
    done = subprocess.run([sys.executable, "-m", "pm_joint.cli", *argv], capture_output=True,
                          text=True, timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    # stderr also holds the progress bar, redrawn around the message on lines of its own
    err = [line for line in done.stderr.splitlines() if "Warning" in line or str(path) in line]
    assert len(err) == 1 and str(path) in err[0] and "left out" in err[0]
    assert err[0].startswith("pm-joint backbones: UserWarning:")


@pytest.mark.parametrize(
    ("text", "reason"),
    [
        ("time,a,b\n0,1,2\n1e-4,2,3\n2e-4,3,4\n", "which column is the response"),
        ("time,signal\n0,1\n1e-4,2\n2e-4,x\n", "row 3 (line 4), column 'signal': not a number"),
        ("time;signal\n0;1,5\n1e-4;2,5\n2e-4;3\n", "is the response 'signal' a displacement"),
    ],
)
def test_unreadable_tables_are_refused_with_a_reason(text, reason, tmp_path, capsys):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    assert main(["backbones", str(path), "--test", "free-decay"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if "pm-joint" in line]
    assert len(err) == 1 and reason in err[0] and str(path) in err[0]


def _steady(tmp_path, **extra):
    """A laser-velocity record of a beam driven at one frequency (1024 Hz, 2 s), no base."""
    t = np.arange(2048) / 1024.0
    columns = {"time": t, "velocity": 1e-3 * np.sin(2 * np.pi * 18.0 * t), **extra}
    path = tmp_path / "beam.csv"
    pd.DataFrame(columns).to_csv(path, index=False)
    return path


@pytest.mark.parametrize(
    ("options", "extra", "reason"),
    [
        # the measured bolted beam of the issue: the "linear frequency" would be the drive's
        ([], {}, "needs its excitation measured"),
        (["--test", "stepped-sine"], {}, "needs its excitation measured"),
        (["--test", "free-decay"], {}, "does not decay"),
        # a zero base channel: say that the base is zero, and what to do
        (["--excitation", "base_acceleration"], {"base_acceleration": 0.0},
         "'base_acceleration' (base-acceleration) is zero throughout"),
    ],
)  # fmt: skip
def test_what_cannot_be_identified_is_refused(options, extra, reason, tmp_path, capsys):
    path = _steady(tmp_path, **extra)
    argv = ["identify", str(path), "--quantity", "velocity", *options, "--out", "m.json"]
    assert main(argv) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if "pm-joint" in line]
    assert len(err) == 1 and reason in err[0] and str(path) in err[0]
    if extra:
        assert "--test free-decay" in err[0]


def test_a_decay_of_too_few_periods_is_refused(ring, tmp_path, capsys):
    path = tmp_path / "short.csv"
    pd.DataFrame({k: v[:400] for k, v in ring.items()}).to_csv(path, index=False)  # 4 periods
    assert (
        main(["backbones", str(path), *["--test", "free-decay", "--quantity", "displacement"]]) == 2
    )
    err = [line for line in capsys.readouterr().err.splitlines() if "pm-joint" in line]
    assert len(err) == 1 and "too few periods" in err[0]


def test_a_force_driven_stepped_sine_reads_the_linear_backbone(tmp_path):
    """Steady states of a linear oscillator ẍ + 2ζω₀ẋ + ω₀²x = g·F at five drive frequencies
    around resonance, one after the other with the controller's frequency channel: every hold,
    on or off resonance, reads ω₀ and ζ (equivalent linearisation of the fundamental balance),
    the force turned into modal units by the stated gain."""
    from independent_sim import forced_steady_state

    f0, zeta, gain, force_n = 100.0, 0.01, 10.0, 0.05
    omega0 = 2 * np.pi * f0

    def linear(x, v):
        return omega0**2 * x + 2 * zeta * omega0 * v

    parts = []
    for f in (97.0, 98.5, 100.0, 101.5, 103.0):
        w = 2 * np.pi * f
        steady = forced_steady_state(linear, lambda t, w=w: gain * force_n * np.cos(w * t),
                                     1 / f, settle_periods=300, record_periods=75)  # fmt: skip
        parts.append((steady, f))
    t = np.arange(sum(p["time_s"].size for p, _ in parts)) / FS
    table = pd.DataFrame({
        "time": t,
        "displacement": np.concatenate([p["displacement_m"] for p, _ in parts]),
        "force": np.concatenate([p["excitation"] / gain for p, _ in parts]),
        "frequency": np.concatenate([np.full(p["time_s"].size, f) for p, f in parts]),
    })  # fmt: skip
    path = tmp_path / "steps.csv"
    table.to_csv(path, index=False)
    out = tmp_path / "backbones.csv"
    argv = ["backbones", str(path), "--test", "stepped-sine", "--quantity", "displacement",
            "--excitation-kind", "force", "--forcing-gain", str(gain)]  # fmt: skip
    argv += ["--out", str(out)]
    assert main(argv) == 0
    curve = pd.read_csv(out)
    assert len(curve) == 5
    np.testing.assert_allclose(curve["frequency_hz"], f0, rtol=1e-5)
    np.testing.assert_allclose(curve["damping_ratio"], zeta, rtol=1e-3)
