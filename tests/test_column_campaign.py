"""A folder of column files is a campaign: one record per file, each file one assembly.

A small virtual TRC campaign (three assemblies, six levels, short holds) is written by the rig,
and its records are copied, sample for sample, into folders of column files by plain libraries
as a lab's software would write them: CSV (pandas, full precision), HDF5 (h5py) and MAT v5
(scipy.io). Each file holds the time, the centre point's velocity relative to the base, the
base velocity, the controller's frequency and the commanded level, so that read with
``--relative-response`` it holds the very samples the TRC reader makes of the TRC file. Every
command is then run on the column folder and its results are held against the TRC folder's:
the same samples give the same numbers, the assemblies labelled by the file names.
"""

import json
import shutil

import h5py
import numpy as np
import pandas as pd
import pytest
import scipy.io

from identification.measurements.records import Campaign
from identification.rig import Rig
from pm_joint.cli import main
from pm_joint.pipeline import label_records
from pm_joint.workspace import Workspace

FORMATS = ("csv", "h5", "mat")
ASSEMBLIES = ["assembly1", "assembly2", "assembly3"]
EFFECTS = "linear_stiffness,viscous_damping,cubic_stiffness"
#: The column files hold the relative velocity, as the TRC reader makes it.
RELATIVE = ["--relative-response"]


def _columns(record) -> dict[str, np.ndarray]:
    return {
        "time": record.time_s,
        "velocity": record.response_velocity,
        "base_velocity": record.excitation_velocity,
        "frequency": record.frequency_hz,
        "level": record.steps.level_at(record.time_s),
    }


def _write(columns: dict[str, np.ndarray], path) -> None:
    if path.suffix == ".csv":
        pd.DataFrame(columns).to_csv(path, index=False)  # repr of every float: exact
    elif path.suffix == ".h5":
        with h5py.File(path, "w") as fh:
            for name, values in columns.items():
                fh[name] = values
    else:
        scipy.io.savemat(path, columns)


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """The TRC campaign and its copies as folders of column files, by format."""
    root = tmp_path_factory.mktemp("campaigns")
    rig = Rig.preset("trc-like", levels=6, hold_s=1.0, ramp_s=0.05)
    rig.write_campaign(root / "trc", assemblies=3, seed=5, progress=False)
    paths = {"trc": root / "trc"}
    for fmt in FORMATS:
        paths[fmt] = root / fmt
        paths[fmt].mkdir()
    for record in Campaign(root / "trc"):
        columns = _columns(record)
        for fmt in FORMATS:
            _write(columns, paths[fmt] / f"assembly{record.assembly}.{fmt}")
    return paths


def _fresh(folders, fmt, tmp_path):
    """A copy of a campaign folder (commands write their backbones into it)."""
    return shutil.copytree(folders[fmt], tmp_path / fmt)


def _backbones(folder) -> pd.DataFrame:
    assert main(["backbones", str(folder), "--periods", "30", *RELATIVE]) == 0
    return pd.read_csv(folder / "backbones.csv")


@pytest.fixture(scope="module")
def trc_backbones(folders, tmp_path_factory):
    return _backbones(_fresh(folders, "trc", tmp_path_factory.mktemp("trc")))


@pytest.mark.parametrize("fmt", FORMATS)
def test_backbones_of_a_column_folder_are_the_trc_folders(fmt, folders, trc_backbones, tmp_path):
    table = _backbones(_fresh(folders, fmt, tmp_path))
    assert list(dict.fromkeys(table["curve"])) == ASSEMBLIES  # labels: the file names
    expected = trc_backbones.drop(columns=["curve", "source"])
    pd.testing.assert_frame_equal(table.drop(columns=["curve", "source"]), expected)
    assert table.groupby("curve").size().tolist() == [6, 6, 6]  # one backbone per file


def test_identify_on_a_column_folder_gives_the_trc_model(folders, tmp_path):
    models = {}
    for fmt in ("trc", "csv"):
        out = tmp_path / f"{fmt}.json"
        folder = _fresh(folders, fmt, tmp_path)
        assert main(["identify", str(folder), "--effects", EFFECTS, "--out", str(out),
                     *RELATIVE]) == 0  # fmt: skip
        models[fmt] = json.loads(out.read_text())
    assert models["csv"] == models["trc"]


def test_surrogate_labels_of_a_column_folder_are_the_trc_folders(folders, tmp_path):
    model = tmp_path / "model.json"
    trc = _fresh(folders, "trc", tmp_path)
    assert main(["identify", str(trc), "--effects", EFFECTS, "--out", str(model)]) == 0
    labels = {}
    for fmt in ("trc", "h5"):
        workspace = Workspace(folders[fmt], model=model, **_relative_layout())
        assert workspace.campaign.names == (
            ASSEMBLIES if fmt != "trc" else [f"Config1_PRT_Assemb{i}" for i in (1, 2, 3)]
        )
        labels[fmt] = label_records(workspace, edge_periods=20.0, band_hz=None)
    np.testing.assert_array_equal(labels["h5"], labels["trc"])
    # Read without --relative-response the base velocity is taken off a second time: other
    # samples, other labels (what train-surrogate did before it took the record options).
    absolute = label_records(Workspace(folders["h5"], model=model), edge_periods=20.0)
    assert not np.allclose(absolute, labels["trc"], rtol=1e-3)


def _relative_layout():
    from identification.measurements.columns import ColumnLayout

    return {"layout": ColumnLayout(relative=True)}


def test_report_on_a_column_folder_lists_its_assemblies(folders, tmp_path):
    folder = _fresh(folders, "mat", tmp_path)
    out = tmp_path / "report"
    assert main(["report", str(folder), "--out", str(out), *RELATIVE]) == 0
    assert "3 backbones" in (out / "index.html").read_text()
    assert sorted(set(pd.read_csv(folder / "backbones.csv")["curve"])) == ASSEMBLIES


@pytest.mark.slow
def test_criticize_on_a_column_folder_gives_the_trc_verdict(folders, tmp_path):
    found = {}
    for fmt in ("trc", "csv"):
        folder = _fresh(folders, fmt, tmp_path)
        model = tmp_path / f"{fmt}.json"
        assert main(["identify", str(folder), "--effects", EFFECTS, "--out", str(model),
                     *RELATIVE]) == 0  # fmt: skip
        out = tmp_path / f"crit_{fmt}"
        assert main(["criticize", str(folder), "--model", str(model), "--out", str(out),
                     *RELATIVE]) == 0  # fmt: skip
        found[fmt] = json.loads((out / "criticism.json").read_text())
    assert found["csv"]["verdict"] == found["trc"]["verdict"]
    assert found["csv"]["p_value"] == found["trc"]["p_value"]


@pytest.mark.slow
def test_train_surrogate_and_update_on_a_column_folder(folders, tmp_path):
    folder = _fresh(folders, "csv", tmp_path)
    model, surrogate = tmp_path / "model.json", tmp_path / "surrogate"
    assert main(["identify", str(folder), "--effects", EFFECTS, "--out", str(model),
                 *RELATIVE]) == 0  # fmt: skip
    sizes = ["--curves", "20", "--epochs", "2", "--amplitudes", "5"]
    assert main(["train-surrogate", str(folder), "--model", str(model), "--out", str(surrogate),
                 *sizes, *RELATIVE]) == 0  # fmt: skip
    sidecar = json.loads(next(surrogate.glob("*.json")).read_text())
    assert sidecar["training"]["data"]["splits"]["measured"]["test"] == 3
    posterior = tmp_path / "posterior.nc"
    code = main(["update", str(folder), "--model", str(model), "--forward", "harmonic",
                 "--out", str(posterior), "--draws", "20", "--tune", "20", "--chains", "1",
                 "--sampler", "metropolis", *RELATIVE])  # fmt: skip
    assert code in (0, 3) and posterior.is_file()  # 3: not converged at 20 draws


def _error_lines(capsys) -> list[str]:
    """The lines of stderr but a progress bar's (drawn before the error), and no traceback."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return [line for line in err.splitlines() if line.startswith("pm-joint")]


def test_a_mixed_folder_is_one_error_line(folders, tmp_path, capsys):
    folder = _fresh(folders, "trc", tmp_path)
    shutil.copy(folders["csv"] / "assembly1.csv", folder)
    assert main(["backbones", str(folder)]) == 2
    (line,) = _error_lines(capsys)
    assert "mixed folder" in line and "assembly1.csv" in line


@pytest.mark.parametrize(
    ("files", "reason"),
    [
        ({}, "no TRC data files"),
        ({"a.h5": b"not hdf5"}, "a.h5: not readable as a .h5 file"),
        ({"a.mat": b"not mat"}, "a.mat: not readable as a .mat file"),
        ({"a.csv": b"x\n"}, "a.csv: needs a header line"),
    ],
)
@pytest.mark.parametrize("command", ["identify", "report"])
def test_a_folder_with_no_readable_file_is_one_error_line(files, reason, command, tmp_path,
                                                          capsys):  # fmt: skip
    folder = tmp_path / "campaign"
    folder.mkdir()
    for name, content in files.items():
        (folder / name).write_bytes(content)
    assert main([command, str(folder), "--out", str(tmp_path / "out")]) == 2
    (line,) = _error_lines(capsys)
    assert line.startswith(f"pm-joint {command}: error: ") and reason in line, line
