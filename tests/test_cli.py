"""The ``pm-joint`` command, subcommand by subcommand.

Two kinds of campaign folders: one written by ``pm-joint rig``, and one written
here by plain Python string formatting in the TRC layout (as another program
would), with the analytical steady state of linear oscillators at phase
resonance, so that the expected backbones and model are known exactly.
"""

import argparse
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import cumulative_trapezoid

from identification.measurements.backbone import BackboneSet
from identification.model import JointModel
from pm_joint import cli
from pm_joint.cli import EXIT_NOT_CONVERGED, build_parser, main
from pm_joint.html import missing_links
from pm_joint.inference import load_posterior
from surrogates.dataset import BackboneDataset

sys.path.insert(0, str(Path(__file__).parent))
from browser import assert_page_works, find_browser, require_browser

FS = 10_000.0
ZETA = 0.005
LEVELS = [0.5, 0.8, 1.3, 2.0, 3.0, 4.5]  # shaker volts
SHAPE = np.sin(np.pi * np.linspace(0.15, 0.85, 5))[:, None] * np.array([0.9, 1.0, 0.9])


def _write_hand_made_record(folder: Path, name: str, f0: float, levels: list[float]) -> None:
    """A linear oscillator ẍ + 2ζω₀ẋ + ω₀²x = −a_base, stepped along its backbone.

    The relative displacement is x = a(t) cos ω₀t with a(t) held at the resonant
    amplitude of each level and moved between levels by raised-cosine ramps;
    the base acceleration is what the equation of motion needs for exactly that
    motion, so the record is consistent everywhere, ramps included.
    """
    omega = 2 * np.pi * f0
    hold_s, ramp_s = 1.0, 0.1
    t = np.arange(int(len(levels) * hold_s * FS)) / FS
    target = 2.0 * np.asarray(levels) / (2 * ZETA * omega**2)  # gain 2 m/s² per volt
    amplitude = np.full_like(t, target[0])
    rate = np.zeros_like(t)
    curvature = np.zeros_like(t)
    for k in range(1, len(levels)):
        s = np.clip((t - k * hold_s) / ramp_s, 0, 1)
        jump = target[k] - target[k - 1]
        amplitude += jump * 0.5 * (1 - np.cos(np.pi * s))
        inside = (s > 0) & (s < 1)
        rate += np.where(inside, jump * 0.5 * np.pi / ramp_s * np.sin(np.pi * s), 0)
        curvature += np.where(inside, jump * 0.5 * (np.pi / ramp_s) ** 2 * np.cos(np.pi * s), 0)
    sin, cos = np.sin(omega * t), np.cos(omega * t)
    relative_velocity = rate * cos - amplitude * omega * sin
    base_acceleration = (2 * ZETA * omega**2 * amplitude + 2 * omega * rate) * sin - (
        curvature + 2 * ZETA * omega * rate
    ) * cos
    base_velocity = -(2 * ZETA * omega * target[0]) + cumulative_trapezoid(
        base_acceleration, t, initial=0
    )
    shape = SHAPE.ravel() / SHAPE.ravel()[7]
    panel = shape[:, None] * relative_velocity + base_velocity
    phase = np.degrees(omega * t) % 360
    rows = np.column_stack([t, panel.T, base_velocity, base_velocity, np.full_like(t, f0), phase])
    lines = [",".join(f"{v:.9e}" for v in row) for row in rows]
    (folder / f"{name}.csv").write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def hand_made(tmp_path_factory):
    folder = tmp_path_factory.mktemp("hand_made")
    steps = []
    for i, value in enumerate(LEVELS):  # holds after 0.1 s ramps
        steps += [f"{i * 1.0 + (0.1 if i else 0):.6f} {value}", f"{i + 1.0 - 1e-4:.6f} {value}"]
    (folder / "Config7_PRT_amplitude_steps.txt").write_text("\n".join(steps) + "\n")
    for k, f0 in enumerate([99.5, 100.0, 100.5], start=1):
        _write_hand_made_record(folder, f"Config7_PRT_Assemb{k}", f0, LEVELS)
    return folder


@pytest.fixture(scope="module")
def rig_campaign(tmp_path_factory):
    folder = tmp_path_factory.mktemp("rig") / "campaign"
    assert (
        main(["rig", "trc-like", "--out", str(folder), "--assemblies", "3", "--levels", "6"]) == 0
    )
    return folder


def _without_clock(report):
    """A criticism report without its clock readings (the calibration's seconds)."""
    if isinstance(report, dict):
        return {k: _without_clock(v) for k, v in report.items() if k != "seconds"}
    if isinstance(report, list):
        return [_without_clock(v) for v in report]
    return report


def test_every_subcommand_has_help():
    for command in ("effects", "model", "rig", "backbones", "identify", "train-surrogate",
                    "criticize", "update", "report", "demo"):  # fmt: skip
        done = subprocess.run(
            [sys.executable, "-m", "pm_joint.cli", command, "--help"],
            capture_output=True,
            text=True,
        )
        assert done.returncode == 0, done.stderr
        assert "usage: pm-joint" in done.stdout


@pytest.mark.parametrize(
    ("argv", "reason"),
    [
        (["backbones", "/no/such/folder"], "campaign folder not found"),
        (["backbones", "."], "no TRC data files"),
        (["model", "--json", "/no/such/model.json"], "model.json"),
        (["update", "/no/such/folder", "--forward", "surrogate", "--out", "p.nc"], "--surrogate"),
    ],
)
def test_bad_input_exits_with_a_one_line_reason(argv, reason, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # "." is an empty folder
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and reason in err


def test_unknown_effect_is_refused(hand_made, capsys):
    with pytest.raises(SystemExit) as info:
        main(["identify", str(hand_made), "--effects", "linear_stiffness,nope", "--out", "m.json"])
    assert info.value.code == 2
    assert "unknown effect 'nope'" in capsys.readouterr().err


def test_hand_made_records_give_the_known_backbones_and_model(hand_made, tmp_path, capsys):
    csv = tmp_path / "backbones.csv"
    assert main(["backbones", str(hand_made), "--out", str(csv)]) == 0
    said = capsys.readouterr().out  # how the points were measured, counted
    assert "18 point(s) in 3 curve(s)" in said
    assert "0 of 18 point(s) more than ±5° from phase resonance" in said
    assert "0 of 18 point(s) not settled" in said and "0 sample(s) dropped as spikes" in said
    table = __import__("pandas").read_csv(csv)
    assert len(table) == 18
    for (_, curve), f0 in zip(table.groupby("curve"), [99.5, 100.0, 100.5], strict=True):
        np.testing.assert_allclose(curve["frequency_hz"], f0, rtol=1e-6)
        # the record's base velocity comes from the trapezoid rule: (ωΔt)²/12 ≈ 3e-4
        np.testing.assert_allclose(curve["damping_ratio"], ZETA, rtol=1e-3)

    model_path = tmp_path / "model.json"
    argv = [
        "identify",
        str(hand_made),
        "--effects",
        "linear_stiffness,viscous_damping,cubic_stiffness",
    ]
    assert main([*argv, "--out", str(model_path), "--records", "1"]) == 0
    model = JointModel.from_json(model_path)
    omega = 2 * np.pi * 99.5
    assert model.effects == ["linear_stiffness", "viscous_damping"]
    assert model.coefficient("linear_stiffness") == pytest.approx(omega**2, rel=1e-3)
    assert model.coefficient("viscous_damping") == pytest.approx(2 * ZETA * omega, rel=2e-2)

    crit = tmp_path / "crit"
    assert main(["criticize", str(hand_made), "--model", str(model_path), "--out", str(crit)]) == 0
    assert json.loads((crit / "criticism.json").read_text())["significant"] is False


def test_a_record_file_is_a_campaign_of_one(hand_made, tmp_path):
    csv = tmp_path / "one.csv"
    assert main(["backbones", str(hand_made / "Config7_PRT_Assemb2.csv"), "--out", str(csv)]) == 0
    table = __import__("pandas").read_csv(csv)
    assert len(table) == 6 and set(table["curve"]) == {"Config7_PRT_Assemb2"}
    np.testing.assert_allclose(table["frequency_hz"], 100.0, rtol=1e-6)


def test_rig_campaign_through_every_stage(rig_campaign, tmp_path, capsys):
    assert main(["backbones", str(rig_campaign)]) == 0
    assert (rig_campaign / "backbones.csv").exists()

    model = tmp_path / "model.json"
    effects = "linear_stiffness,viscous_damping,cubic_stiffness"
    assert main(["identify", str(rig_campaign), "--effects", effects, "--out", str(model)]) == 0

    surrogate = tmp_path / "surrogate"
    argv = ["train-surrogate", str(rig_campaign), "--model", str(model), "--out", str(surrogate)]
    assert main([*argv, "--curves", "80", "--epochs", "40"]) == 0
    assert (surrogate / "surrogate.onnx").exists()
    # The amplitude grid: every analytical curve requested is generated and used, the
    # measured curves are added or named as left out, and the sidecar carries the
    # independent test split's figures beside the linear baseline.
    dataset = BackboneDataset.load(surrogate / "dataset.npz")
    counts, offered = dataset.provenance["counts"], 3
    assert dataset.spec.representation == "amplitude_grid"
    assert counts["requested"] == counts["generated"] == 80 - offered
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
    argv_dask = [*argv[:-1], str(on_dask), "--curves", "80", "--epochs", "1", "--workers", "2"]
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
    assert main([*argv, "--draws", "400", "--tune", "400", "--chains", "1"]) == EXIT_NOT_CONVERGED
    assert "NOT CONVERGED" in capsys.readouterr().err
    # the draws went to posterior.zarr as they were taken; --resume carries the run on
    assert load_posterior(posterior.with_suffix(".zarr")).posterior.sizes["draw"] == 400
    assert main([*argv, "--draws", "600", "--chains", "1"]) == 2  # never overwritten
    resume = [*argv, "--draws", "600", "--chains", "1", "--resume"]
    assert main(resume) == EXIT_NOT_CONVERGED
    resumed = load_posterior(posterior).posterior["linear_stiffness"]
    assert resumed.sizes == {"chain": 1, "draw": 600}

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
    # The candidates refitted on a two-worker dask LocalCluster: the same report.
    on_dask = tmp_path / "criticism_dask"
    argv = ["criticize", str(rig_campaign), "--model", str(model), "--out", str(on_dask)]
    assert main([*argv, "--rounds", "1", "--workers", "2"]) == 0
    assert _without_clock(json.loads((on_dask / "criticism.json").read_text())) == (
        _without_clock(report)
    )
    assert capsys.readouterr().out.replace("criticism_dask", "criticism") == printed

    out = tmp_path / "report"
    argv = ["report", str(rig_campaign / "backbones.csv"), "--posterior", str(posterior)]
    assert main([*argv, "--criticism", str(crit), "--out", str(out)]) == 0
    index = out / "index.html"
    assert index.exists()
    assert missing_links(index) == []
    assert "<img" in index.read_text()


def test_the_cli_names_the_samplers_and_population_models_the_library_has():
    from pm_joint import cli, inference

    assert cli.SAMPLERS == inference.SAMPLERS
    assert cli.POPULATION_MODELS == inference.POPULATION_MODELS


def test_each_warning_is_printed_once():
    """Libraries reset Python's once-per-place memory (any catch_warnings block does): the
    same warning, raised three times from one place, is still printed once."""
    script = (
        "import warnings\n"
        "from pm_joint import cli\n"
        "def noisy(args):\n"
        "    for _ in range(3):\n"
        "        with warnings.catch_warnings():\n"
        "            pass\n"
        "        warnings.warn('object mode, again', UserWarning)\n"
        "    warnings.warn('another one', UserWarning)\n"
        "cli._cmd_effects = noisy\n"
        "raise SystemExit(cli.main(['effects']))\n"
    )
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          timeout=600)  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
    lines = done.stderr.splitlines()
    assert lines.count("pm-joint effects: UserWarning: object mode, again") == 1, lines
    assert lines.count("pm-joint effects: UserWarning: another one") == 1, lines


def _help_of(option: str) -> str:
    """The ``pm-joint update`` help of one option, as argparse holds it."""
    parser = build_parser()
    update = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[
        "update"
    ]
    return next(a.help for a in update._actions if option in a.option_strings)


def _defaults_in_words(text: str) -> dict[tuple[str, str], str]:
    """``"V (p on f, p on f); W (p on f)"`` back into {(p, f): V}."""
    found = {}
    for value, pairs in re.findall(r"(\w+) \(([^()]*)\)", text):
        for population, forward in re.findall(r"(\w+) on (\w+)", pairs):
            found[population, forward] = value
    return found


def test_update_help_says_the_defaults_the_updating_uses():
    """The help is generated from SAMPLER_DEFAULTS; read back, it is the table, every pair."""
    from pm_joint.inference import SAMPLER_DEFAULTS
    from pm_joint.sampler_defaults import DEFAULT_FORWARD, sampler_reason

    for option, field in (("--sampler", "sampler"), ("--draws", "draws"), ("--tune", "tune")):
        said = _defaults_in_words(_help_of(option))
        table = {pair: str(getattr(d, field)) for pair, d in SAMPLER_DEFAULTS.items()}
        assert said == table, option
    forward = _help_of("--forward")
    for population, default in DEFAULT_FORWARD.items():
        assert f"{default} for {population}" in forward
        assert (population, default) in SAMPLER_DEFAULTS
    # The reason a report prints is the table's, for the table's sampler only.
    for (population, model), default in SAMPLER_DEFAULTS.items():
        assert default.reason in sampler_reason(population, model, default.sampler)
        other = next(s for s in cli.SAMPLERS if s != default.sampler)
        assert sampler_reason(population, model, other) == "chosen by the caller"


def test_the_help_check_reads_a_drifted_help_as_drifted():
    """The reader above is no echo of the generator: a hand-written help reads differently."""
    from pm_joint.inference import SAMPLER_DEFAULTS
    from pm_joint.sampler_defaults import default_help

    # The --draws help as it was written by hand before the table made it.
    drifted = (
        "draws per chain (default 30000 metropolis, 2000 matching on harmonic, 1000 hierarchical)"
    )
    assert _defaults_in_words(drifted) != {p: str(d.draws) for p, d in SAMPLER_DEFAULTS.items()}
    generated = f"draws per chain (default: {default_help('draws')})"
    assert _defaults_in_words(generated) == {p: str(d.draws) for p, d in SAMPLER_DEFAULTS.items()}


def test_demo_runs_end_to_end_at_small_size(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "pm_joint.cli", "demo", "--size", "small", "--out", str(tmp_path)],
        capture_output=True, text=True, timeout=1200,
    )  # fmt: skip
    # Small draws need not converge: then the report is written and the exit says so.
    assert done.returncode in (0, EXIT_NOT_CONVERGED), done.stderr[-3000:]
    if done.returncode == EXIT_NOT_CONVERGED:
        assert "pm-joint demo: NOT CONVERGED" in done.stderr
    index = tmp_path / "index.html"
    assert missing_links(index) == []
    page = index.read_text()
    for section in ("SINDy identification", "Neural surrogate", "Stochastic updating",
                    "PDFs at low, mid and high amplitude", "Model criticism"):  # fmt: skip
        assert section in page
    # The criticism leads with each round's finding; the final model's state comes after.
    criticism = page[page.index('id="model-criticism"') :]
    assert criticism.index("Round 1 of ") < criticism.index("The final model")
    assert re.search(r"mean acceptance \d\.\d\d\.", page)  # was 0.26176666666666665
    # Each warning once (pytensor's object-mode notice came once per compiled function).
    warned = [line for line in done.stderr.splitlines() if line.startswith("pm-joint demo: ")]
    assert len(warned) == len(set(warned)), warned
    # The page in a real browser: every image loads, nothing logged as an error.
    if find_browser() or os.environ.get("CI") == "true":
        assert_page_works(index, require_browser())
