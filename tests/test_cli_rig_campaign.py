"""``pm-joint`` subcommand after subcommand on one campaign written by ``pm-joint rig``:
backbones, identify, train-surrogate (serial and on dask), update (population matching with
--resume, the hierarchical model), criticize (serial and on dask) and report.

Its own file (tests/test_cli.py holds the others) so that pytest-xdist's ``--dist loadfile``
can run it beside them: it is among the longest checks of the suite.
"""

import json
import math

import numpy as np
import pytest

from identification.measurements.backbone import BackboneSet
from pm_joint.cli import EXIT_NOT_CONVERGED, main
from pm_joint.html import missing_links
from pm_joint.inference import load_posterior
from surrogates.dataset import BackboneDataset


@pytest.fixture(scope="module")
def rig_campaign(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rig") / "campaign"
    assert (
        main(["rig", "trc-like", "--out", str(folder), "--assemblies", "3", "--levels", "6"]) == 0
    )
    return folder


def _without_clock(report):
    """A criticism report without its clock readings (the calibration's seconds) and without
    the models' digests (a digest of the coefficients compared beside it, which rounding in
    the last digit changes whole)."""
    if isinstance(report, dict):
        skipped = ("seconds", "content_sha256")
        return {k: _without_clock(v) for k, v in report.items() if k not in skipped}
    if isinstance(report, list):
        return [_without_clock(v) for v in report]
    return report


def _differences(a, b, rel: float = 1e-6, path: str = "") -> list[str]:
    """Where ``a`` and ``b`` differ beyond rounding: structure and strings exactly, floats
    beyond ``rel`` of each other."""
    if isinstance(a, dict) and isinstance(b, dict):
        if a.keys() != b.keys():
            return [f"{path}: keys {sorted(a)} != {sorted(b)}"]
        return [d for k in a for d in _differences(a[k], b[k], rel, f"{path}.{k}")]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} != {len(b)} items"]
        pairs = enumerate(zip(a, b, strict=True))
        return [d for i, (x, y) in pairs for d in _differences(x, y, rel, f"{path}[{i}]")]
    if isinstance(a, float) and isinstance(b, float):
        close = math.isclose(a, b, rel_tol=rel, abs_tol=1e-12) or (a != a and b != b)
        return [] if close else [f"{path}: {a!r} != {b!r}"]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]


@pytest.mark.heavy
def test_rig_campaign_through_every_stage(rig_campaign, tmp_path, capsys):
    assert main(["backbones", str(rig_campaign)]) == 0
    assert (rig_campaign / "backbones.csv").exists()

    model = tmp_path / "model.json"
    effects = "linear_stiffness,viscous_damping,cubic_stiffness"
    assert main(["identify", str(rig_campaign), "--effects", effects, "--out", str(model)]) == 0

    surrogate = tmp_path / "surrogate"
    argv = ["train-surrogate", str(rig_campaign), "--model", str(model), "--out", str(surrogate)]
    # 40 curves: what follows checks the dataset's counts and the stages' files, not the
    # surrogate's accuracy (tests/test_surrogate_grid.py and bench/surrogate.py do).
    assert main([*argv, "--curves", "40", "--epochs", "40"]) == 0
    assert (surrogate / "surrogate.onnx").exists()
    # The amplitude grid: every analytical curve requested is generated and used, the
    # measured curves are added or named as left out, and the sidecar carries the
    # independent test split's figures beside the linear baseline.
    dataset = BackboneDataset.load(surrogate / "dataset.npz")
    counts, offered = dataset.provenance["counts"], 3
    assert dataset.spec.representation == "amplitude_grid"
    assert counts["requested"] == counts["generated"] == 40 - offered
    left_out = dataset.provenance["measured"]["excluded"]
    assert counts["measured"] + len(left_out) == offered
    assert len(dataset) == counts["generated"] + counts["measured"]
    assert sum(dataset.split_counts()["all"].values()) == len(dataset)
    sidecar = json.loads((surrogate / "surrogate.json").read_text())
    assert sidecar["test"]["analytical"]["n_curves"] == dataset.split_counts()["analytical"]["test"]
    assert sidecar["test"]["analytical"]["ratios"]["frequency_hz"]["to_linear"] is not None
    assert set(sidecar["training"]["data"]["measured_curves"]) == {
        o.removeprefix("measured:") for o in dataset.origin[dataset.is_measured]
    }
    # Three curves, three needed at every grid amplitude: the grid is the range all share.
    shared = BackboneSet.from_csv(rig_campaign / "backbones.csv").common_range()
    grid = sidecar["training"]["data"]["grid"]
    assert grid["range_m"] == pytest.approx(shared, rel=1e-12)
    assert grid["curves_covering"] == [3] * dataset.spec.n_levels
    assert dataset.spec.amplitudes_m[[0, -1]] == pytest.approx(shared, rel=1e-12)
    # On a two-worker dask LocalCluster the dataset is the serial one, bit for bit.
    on_dask = tmp_path / "surrogate_dask"
    argv_dask = [*argv[:-1], str(on_dask), "--curves", "40", "--epochs", "1", "--workers", "2"]
    assert main(argv_dask) == 0
    serial, distributed = (BackboneDataset.load(f / "dataset.npz") for f in (surrogate, on_dask))
    for name in ("X", "Y", "origin", "non_monotone"):
        np.testing.assert_array_equal(getattr(distributed, name), getattr(serial, name))
    created = {"created"}  # the one provenance entry that is a clock reading
    assert {k: v for k, v in distributed.provenance.items() if k not in created} == {
        k: v for k, v in serial.provenance.items() if k not in created
    }

    posterior = tmp_path / "posterior.nc"
    argv = ["update", str(rig_campaign / "backbones.csv"), "--forward", "surrogate"]
    argv += ["--surrogate", str(surrogate), "--out", str(posterior)]
    argv += ["--sampler", "demetropolisz"]
    # One short chain cannot converge: the posterior is written, the exit code says so.
    assert main([*argv, "--draws", "200", "--tune", "200", "--chains", "1"]) == EXIT_NOT_CONVERGED
    assert "NOT CONVERGED" in capsys.readouterr().err
    # the draws went to posterior.zarr as they were taken; --resume carries the run on
    assert load_posterior(posterior.with_suffix(".zarr")).posterior.sizes["draw"] == 200
    assert main([*argv, "--draws", "300", "--chains", "1"]) == 2  # never overwritten
    resume = [*argv, "--draws", "300", "--chains", "1", "--resume"]
    assert main(resume) == EXIT_NOT_CONVERGED
    resumed = load_posterior(posterior).posterior["linear_stiffness"]
    assert resumed.sizes == {"chain": 1, "draw": 300}

    # The hierarchical model on the same campaign: a likelihood per point, LOO, new assemblies.
    hierarchical = tmp_path / "hierarchical.nc"
    argv = ["update", str(rig_campaign / "backbones.csv"), "--population", "hierarchical"]
    argv += ["--model", str(model), "--out", str(hierarchical), "--sampler", "nuts"]
    argv += ["--draws", "150", "--tune", "150", "--report", str(tmp_path / "h_report")]
    assert main(argv) in (0, EXIT_NOT_CONVERGED)
    idata = load_posterior(hierarchical)
    assert idata.attrs["population_model"] == "hierarchical"
    n_points = sum(len(b.amplitude_m) for b in BackboneSet.from_csv(rig_campaign / "backbones.csv"))
    assert idata.log_likelihood["frequency_hz"].sizes["point"] == n_points
    assert json.loads(idata.attrs["loo"])["n_points"] == n_points
    assert {"frequency_hz", "damping_ratio"} <= set(idata.posterior_predictive.data_vars)
    content = json.loads((tmp_path / "h_report" / "report.json").read_text())
    assert list(content)[:2] == ["convergence", "population_model"]
    assert content["loo"]["n_points"] == n_points

    crit = tmp_path / "criticism"
    capsys.readouterr()
    argv = ["criticize", str(rig_campaign), "--model", str(model), "--out", str(crit)]
    assert main([*argv, "--rounds", "1"]) == 0
    report = json.loads((crit / "criticism.json").read_text())
    first = report["rounds"][0]
    assert first["ranking"] and first["ranking"][0]["effect"] == "microslip"  # hidden physics
    # every round's calibrated verdict is printed, with what the decision rests on
    printed = capsys.readouterr().out
    assert printed.count("--- round ") == len(report["rounds"]) == 2
    assert f"--- round 1 of 2 (start): {first['verdict']}" in printed
    assert "--- round 2 of 2 (+ microslip)" in printed
    assert printed.count("verdict: ") == 2 and printed.count("counts: ") == 2
    assert f"{report['n_bootstrap']} bootstrap campaigns" in printed
    assert "data: 3 curves" in printed
    # The candidates refitted on a two-worker dask LocalCluster: the same first round (the
    # second round's refits go the same way; one round keeps the suite's time).
    on_dask = tmp_path / "criticism_dask"
    argv = ["criticize", str(rig_campaign), "--model", str(model), "--out", str(on_dask)]
    assert main([*argv, "--workers", "2"]) == 0
    # the same up to the refits' tolerance: a refit's least squares in another process sums
    # in another order (BLAS threads) and may stop at another point within its tolerance,
    # which moves what follows it (seen: 1e-9 relative alone, beyond 1e-6 under xdist)
    # (the round's summary words where the loop went next: compared apart)
    distributed = json.loads((on_dask / "criticism.json").read_text())["rounds"][0]
    assert distributed.pop("summary").split("\n")[:2] == first["summary"].split("\n")[:2]
    first = {k: v for k, v in first.items() if k != "summary"}
    differences = _differences(_without_clock(distributed), _without_clock(first), rel=1e-4)
    assert differences == [], differences[:20]
    assert capsys.readouterr().out.count("verdict: ") == 1

    out = tmp_path / "report"
    argv = ["report", str(rig_campaign / "backbones.csv"), "--posterior", str(posterior)]
    assert main([*argv, "--criticism", str(crit), "--out", str(out)]) == 0
    index = out / "index.html"
    assert index.exists()
    assert missing_links(index) == []
    assert "<img" in index.read_text()
