"""Benchmark: the N-mode surrogate on the two-mode rig's decays (issue #27, item 4).

The campaign of the two-mode demo case: free decays of the ``two-mode`` rig preset (3
assemblies, seed 0), read mode by mode, ``identify --modes 2``. Then:

1. **Training** (``pm-joint train-surrogate`` with the ModalModel; 500 curves, the default
   training), timed. Per mode and channel (frequency, damping ratio): the test split's RMSE
   and its ratios to today's baselines — the per-point linear and cubic regressions on the
   parameters and the mean curve (:mod:`surrogates.baselines`) — and to the mode's
   assembly scatter at the worst amplitude; the targets are the one-mode surrogate's
   (:data:`surrogates.evaluate.TARGETS`: ÷ scatter ≤ 0.1, ÷ linear ≤ 0.1).
2. **Speed on the same work**: each mode's backbone at the points population matching
   reads, per call, by the surrogate's Op (onnxruntime) and by the best peer,
   :class:`~pm_joint.forward.modal_op.ModalHarmonicOp` (the recorded N-mode balance).
3. **Updating on it**: population matching on the surrogate (its default, Metropolis
   30 000 draws) beside the same on the N-mode balance (DEMetropolisZ 30 000): wall time,
   the convergence verdict, and per parameter the gap between the two posterior medians in
   the balance posterior's standard deviations. The hierarchical model on the surrogate
   (nutpie, 1 000 draws): wall time, verdict, draws outside the surrogate's box, and each
   mode's population frequency beside the rig's small-amplitude ones.

Run: ``PYTHONPATH=. nice -n 10 .venv/bin/python bench/modal_surrogate.py [--out FOLDER]``.
Prints one JSON line and writes ``bench/results/modal_surrogate.json``.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pytensor
import pytensor.tensor as pt

from identification.multimode.model import ModalModel
from identification.rig.modal_rig import (
    ModalRig,
    read_modal_ground_truth,
    small_amplitude_frequencies_hz,
)
from pm_joint.cli import main as cli
from pm_joint.inference import load_posterior
from pm_joint.inference.modal import build_modal_model, read_mode_backbones
from pm_joint.modal_surrogate import train_modal_surrogate
from pm_joint.modal_update import update_modes
from surrogates.evaluate import TARGETS

RESULTS = Path(__file__).parent / "results"
#: Calls timed per forward model and mode.
N_CALLS = 300


def _campaign(out: Path) -> tuple[ModalModel, dict]:
    records = out / "decays"
    ModalRig.preset("two-mode", test="free-decay").write_campaign(records, assemblies=3, seed=0)
    decay = ["--test", "free-decay"]
    cli(["backbones", str(records), *decay, "--modes", "2"])
    cli(["identify", str(records), *decay, "--modes", "2", "--out", str(out / "two.json")])
    return ModalModel.from_json(out / "two.json"), read_mode_backbones(records / "backbones.csv")


def _accuracy(surrogate) -> dict:
    figures = {}
    for mode, runtime in surrogate.runtimes.items():
        test = runtime.metadata["test"]["analytical"]
        for channel in ("frequency_hz", "damping_ratio"):
            ratios = test["ratios"][channel]
            models = test["models"]
            figures[f"mode{mode}.{channel}"] = {
                "rmse": models["surrogate"][channel]["rmse"],
                "rmse_linear": models["linear"][channel]["rmse"],
                "rmse_cubic": models["cubic"][channel]["rmse"],
                "rmse_mean_curve": models["mean_curve"][channel]["rmse"],
                "to_linear": ratios["to_linear"],
                "to_cubic": ratios["to_cubic"],
                "to_mean_curve": ratios["to_mean_curve"],
                "to_scatter_max": ratios.get("to_scatter_max"),
                "targets_met": test["targets_met"][channel],
            }
    return figures


def _per_call_ms(op, theta_sets: np.ndarray) -> float:
    theta = pt.dvector("theta")
    function = pytensor.function([theta], op(theta))
    function(theta_sets[0])
    start = time.perf_counter()
    for row in theta_sets:
        function(row)
    return 1e3 * (time.perf_counter() - start) / len(theta_sets)


def _speed(model, measured, surrogate) -> dict:
    names = list(surrogate.parameter_names)
    on_surrogate = build_modal_model(model, measured, surrogate=surrogate).forward_ops
    on_balance = build_modal_model(model, measured, names=names).forward_ops
    centre = np.array([np.mean(surrogate.bounds[n]) for n in names])
    sets = centre * np.random.default_rng(0).uniform(0.995, 1.005, (N_CALLS, centre.size))
    return {
        f"mode{m}": {
            "surrogate_ms_per_call": _per_call_ms(on_surrogate[m], sets),
            "modal_harmonic_op_ms_per_call": _per_call_ms(on_balance[m], sets),
        }
        for m in on_surrogate
    }


def _timed_update(model, measured, out: Path, **options) -> tuple[dict, object]:
    start = time.perf_counter()
    idata = update_modes(model, measured, out, progressbar=False, **options)
    seconds = time.perf_counter() - start
    verdict = json.loads(idata.attrs["convergence"])
    return {"wall_s": round(seconds, 1), "convergence": verdict}, load_posterior(out)


def main() -> None:
    warnings.filterwarnings("ignore")
    logging.getLogger("pymc").setLevel(logging.ERROR)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", help="working folder (default: a temporary one)")
    args = parser.parse_args()
    out = Path(args.out or tempfile.mkdtemp(prefix="modal_surrogate_"))
    out.mkdir(parents=True, exist_ok=True)
    model, measured = _campaign(out)
    start = time.perf_counter()
    surrogate = train_modal_surrogate(model, measured, out / "surrogate", progress=False)
    training_s = time.perf_counter() - start
    matching_surrogate, on_surrogate = _timed_update(
        model, measured, out / "matching_surrogate.nc", surrogate=surrogate
    )
    matching_balance, on_balance = _timed_update(model, measured, out / "matching_balance.nc")
    gaps = {}
    for name in surrogate.parameter_names:
        a = on_surrogate["posterior"][name].values.ravel()
        b = on_balance["posterior"][name].values.ravel()
        gaps[name] = round(float(abs(np.median(a) - np.median(b)) / np.std(b)), 3)
    hierarchical, on_population = _timed_update(
        model, measured, out / "hierarchical_surrogate.nc", surrogate=surrogate,
        population="hierarchical",
    )  # fmt: skip
    hierarchical["outside_surrogate_box"] = float(on_population.attrs["outside_surrogate_box"])
    truth = read_modal_ground_truth(out / "decays")
    rig = np.array([small_amplitude_frequencies_hz(t.model) for t in truth.values()])
    posterior = on_population["posterior"]
    hierarchical["population_frequency_hz"] = {
        f"mode{m}": {
            "median": round(float(np.median(posterior[f"mode{m}.frequency_hz_population"])), 3),
            "interval_90": np.round(
                np.quantile(posterior[f"mode{m}.frequency_hz_population"], [0.05, 0.95]), 3
            ).tolist(),
            "rig_assemblies_small_amplitude": np.round(rig[:, m - 1], 3).tolist(),
        }
        for m in surrogate.modes
    }
    figures = {
        "campaign": "two-mode rig, free decays, 3 assemblies, seed 0; identify --modes 2",
        "parameters": list(surrogate.parameter_names),
        "training_s": round(training_s, 1),
        "accuracy": _accuracy(surrogate),
        "targets": TARGETS,
        "speed": _speed(model, measured, surrogate),
        "matching_on_surrogate": matching_surrogate,
        "matching_on_modal_harmonic": matching_balance,
        "median_gap_in_balance_sd": gaps,
        "hierarchical_on_surrogate": hierarchical,
        "_run": {
            "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
            "load_average": os.getloadavg(),
            "command": "PYTHONPATH=. nice -n 10 .venv/bin/python bench/modal_surrogate.py",
        },
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "modal_surrogate.json").write_text(json.dumps(figures, indent=1) + "\n")
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
