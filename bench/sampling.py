"""Benchmark: every sampler on the same updating posterior, one row per forward model.

The posterior: a ``trc-like`` rig campaign of 25 assemblies (the rig's
reassembly draws, PLL backbones at its 12 levels), the paper's population
matching (frequency at 9 amplitude levels, Gaussian copula of the fitted
marginals) and uniform priors on every coefficient of the model structure
(:func:`identification.fitting.least_squares.default_free`). Boxes: ± 4
population spreads for the coefficients the rig varies, ± 10 % for the
microslip stiffness. The same posterior is sampled through two forward models:

- ``surrogate``: a network trained here on that box (harmonic-balance backbones
  on 41 response amplitudes over those ≥ 3 measured curves cover, with the ``has_backbone``
  mask, as the demo's; its size, in weights and layers, is printed and in the
  JSON), run by onnxruntime for the Metropolis samplers and compiled as a
  native pytensor graph (:class:`pm_joint.forward.SurrogateGraph`) for the
  gradient samplers;
- ``harmonic``: the native single-harmonic-balance graph.

Samplers, each a fresh :func:`pm_joint.sample` call with 2 chains on the 2
cores: ``metropolis`` (pm-joint's: PyMC's Metropolis, proposal covariance
learned while tuning), ``metropolis_paper`` (the paper's coordinate-wise
Metropolis, for the record), ``demetropolisz``, ``nuts`` (PyMC's) and
``nutpie`` (numba backend). Wall time is the whole call (compilation, process
start, sampling); min ESS is arviz's minimum bulk ESS over the parameters, per
second of wall time. The machine is shared: the load average is printed.

Run: ``.venv/bin/python bench/sampling.py``. Prints a table, then one JSON line.
"""

from __future__ import annotations

import json
import logging
import os
import resource
import tempfile
import time
import warnings

import numpy as np
import torch

from identification.analytical.pll import pll_backbones
from identification.fitting.least_squares import default_free
from identification.measurements.backbone import Backbone, BackboneSet
from identification.rig import RIG_PRESETS, Rig
from pm_joint.analysis import convergence_verdict
from pm_joint.inference import GRADIENT_SAMPLERS, SAMPLER_DEFAULTS, build_model, sample
from surrogates import (
    NetConfig,
    SurrogateRuntime,
    TrainingConfig,
    export_surrogate,
    train_surrogate,
)
from surrogates.dataset import generate_dataset
from surrogates.grid import measured_grid

#: Relative half-width of the box of the coefficient the rig does not vary.
FIXED_SPREAD = 0.1
NAMES = default_free(RIG_PRESETS["trc-like"].model)
ASSEMBLIES = 25
TRAINING_CURVES = 500  # the paper's 25 measured + 475 analytical
NET = NetConfig(latent_dim=32, conv_filters=(32, 16), ffnn_width=128, ffnn_depth=3)
#: name: (sampler, draws, tuning steps, step options); the same runs on each forward model.
RUNS = {
    "metropolis": ("metropolis", 30_000, 5_000, {}),
    "metropolis_paper": ("metropolis", 10_000, 2_000, {"adapt_covariance": False}),
    "demetropolisz": ("demetropolisz", 30_000, 5_000, {}),
    "nuts": ("nuts", 1_000, 1_000, {}),
    "nutpie": ("nutpie", 1_000, 1_000, {}),
}  # fmt: skip
FORWARD_MODELS = ("surrogate", "harmonic")


def campaign(rig: Rig) -> BackboneSet:
    """PLL backbones of the rig's first 25 assemblies (the records minus the file round trip)."""
    names = sorted(rig.variability)
    models = [rig.draw(np.random.default_rng([0, a]))[0] for a in range(1, ASSEMBLIES + 1)]
    values = np.array([[m.parameters[n] for n in names] for m in models])
    levels = rig.shaker_gain * np.asarray(rig.levels_v)
    result = pll_backbones(rig.model, levels, values, names, progress=False)
    return BackboneSet(
        Backbone(a, f, d, label=f"Assemb{i + 1}")
        for i, (a, f, d) in enumerate(
            zip(result.amplitude_m, result.frequency_hz, result.damping_ratio, strict=True)
        )
    )


def train(
    rig: Rig, bounds: dict, measured: BackboneSet, folder: str
) -> tuple[SurrogateRuntime, dict]:
    """The amplitude-grid surrogate over the prior box, with its size and accuracy."""
    start = time.perf_counter()
    data = generate_dataset(
        rig.model, NAMES, TRAINING_CURVES, representation="amplitude_grid", bounds=bounds,
        amplitude_range_m=measured_grid(measured).range_m, progress=False,
    )  # fmt: skip
    config = TrainingConfig(net=NET, max_epochs=400, finetune_epochs=400, progress=False)
    trained = train_surrogate(data.X, data.Y, data.spec, config)
    runtime = SurrogateRuntime.load(export_surrogate(trained, folder), threads=1)
    weights = sum(p.numel() for p in trained.model.parameters())
    frequency = trained.metrics["frequency_hz"]  # validation split, amplitude-grid channels
    return runtime, {
        "surrogate_representation": data.spec.representation,
        "surrogate_curves": len(data),
        "surrogate_levels": data.spec.n_levels,
        "surrogate_weights": int(weights),
        "surrogate_net": NET.to_dict(),
        "surrogate_frequency_validation_mape_pct": frequency["mape_pct"],
        "surrogate_frequency_validation_rmse_hz": frequency["rmse"],
        "surrogate_train_s": time.perf_counter() - start,
    }


def cpu_seconds() -> float:
    """CPU time of this process and its finished children (the chain processes)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def run(pm_model, sampler: str, draws: int, tune: int, options: dict) -> dict:
    start, cpu = time.perf_counter(), cpu_seconds()
    idata = sample(
        pm_model, sampler=sampler, draws=draws, tune=tune, chains=2, cores=2,
        random_seed=1, progressbar=False, step_options=options,
    )  # fmt: skip
    wall, cpu = time.perf_counter() - start, cpu_seconds() - cpu
    verdict = convergence_verdict(idata, NAMES)
    figures = {
        "sampler": sampler,
        "draws": draws,
        "tune": tune,
        "wall_s": wall,
        "cpu_s": cpu,
        "ess_bulk_min": min(p["ess_bulk"] for p in verdict.parameters),
        "ess_tail_min": min(p["ess_tail"] for p in verdict.parameters),
        "r_hat_max": max(p["r_hat"] for p in verdict.parameters),
        "converged": verdict.converged,
        "divergences": verdict.divergences,
        "nan_rate": verdict.nan_rate,
        "means": {n: float(idata.posterior[n].mean()) for n in NAMES},
    }
    figures["ess_bulk_per_s"] = figures["ess_bulk_min"] / wall
    return figures


def main() -> None:
    torch.set_num_threads(1)
    warnings.filterwarnings("ignore", "Numba will use object mode", UserWarning)
    logging.getLogger("pymc").setLevel(logging.ERROR)
    rig = Rig.preset("trc-like", levels=12)
    spreads = {n: 4 * rig.variability.get(n, FIXED_SPREAD / 4) for n in NAMES}
    bounds = {
        n: (rig.model.parameters[n] * np.exp(-s), rig.model.parameters[n] * np.exp(s))
        for n, s in spreads.items()
    }
    measured = campaign(rig)
    only = os.environ.get("BENCH_SAMPLERS")  # e.g. "metropolis,nutpie" for a partial rerun
    runs = {k: v for k, v in RUNS.items() if not only or k in only.split(",")}
    results: dict[str, dict] = {}
    with tempfile.TemporaryDirectory() as folder:
        runtime, surrogate = train(rig, bounds, measured, folder)
        kwargs = {"names": NAMES, "bounds": bounds, "surrogate": runtime}
        for forward in FORWARD_MODELS:
            # Gradient samplers get the surrogate's network as a native graph; the others
            # call onnxruntime (the harmonic balance is one graph for all).
            models = {
                native: build_model(
                    rig.model, measured, forward=forward, native_graph=native, **kwargs
                )
                for native in (False, True)
            }
            results[forward] = {}
            for name, (sampler, draws, tune, options) in runs.items():
                pm_model = models[sampler in GRADIENT_SAMPLERS]
                results[forward][name] = run(pm_model, sampler, draws, tune, options)
                print(f"{forward} {name}: {results[forward][name]['wall_s']:.1f} s", flush=True)
    report(results, surrogate)


def report(results: dict, surrogate: dict) -> None:
    """The table per forward model, the verdicts, and the JSON line."""
    load = os.getloadavg()[0]
    print(
        f"\nposterior: {ASSEMBLIES} trc-like backbones, {len(NAMES)} parameters {NAMES}; "
        f"surrogate {surrogate['surrogate_weights']} weights ({NET.to_dict()}; "
        f"{surrogate['surrogate_curves']} curves × {surrogate['surrogate_levels']} levels, "
        f"validation frequency MAPE {surrogate['surrogate_frequency_validation_mape_pct']:.3f} %)"
    )
    summary = {}
    for forward, rows in results.items():
        print(f"\nforward model: {forward}")
        print(f"{'sampler':<18s}{'draws':>8s}{'wall s':>8s}{'CPU s':>8s}{'min ESS':>9s}"
              f"{'ESS/s':>8s}{'r_hat':>8s}{'div':>5s}  verdict")  # fmt: skip
        for name, f in rows.items():
            print(
                f"{name:<18s}{f['draws']:>8d}{f['wall_s']:>8.1f}{f['cpu_s']:>8.1f}"
                f"{f['ess_bulk_min']:>9.0f}{f['ess_bulk_per_s']:>8.2f}{f['r_hat_max']:>8.3f}"
                f"{f['divergences'] if f['divergences'] is not None else '':>5}  "
                f"{'converged' if f['converged'] else 'NOT CONVERGED'}"
            )
        best = max(rows, key=lambda n: rows[n]["ess_bulk_per_s"])
        summary[forward] = {"best_sampler": best}
        if "nutpie" in rows:
            for f in rows.values():
                f["ess_per_s_vs_nutpie"] = f["ess_bulk_per_s"] / rows["nutpie"]["ess_bulk_per_s"]
    default = SAMPLER_DEFAULTS["matching", "harmonic"].sampler
    harmonic = results.get("harmonic", {})
    if "nutpie" in harmonic and default in harmonic:
        ratio = harmonic[default]["ess_per_s_vs_nutpie"]
        summary["harmonic"]["default_vs_nutpie"] = ratio
        print(f"\nharmonic balance: pm-joint's default ({default}) at {ratio:.2f}× nutpie's "
              "min-ESS/s (target ≥ 1.0×)")  # fmt: skip
    print(f"load average (1 min): {load:.2f} on {os.cpu_count()} cores (shared machine)")
    # Flat figures for the README's table (bench/run_all.py).
    flat = {}
    for forward, rows in results.items():
        for name, f in rows.items():
            flat[f"{forward}_{name}_ess_per_s"] = f["ess_bulk_per_s"]
        if {"metropolis", "metropolis_paper"} <= set(rows):
            flat[f"{forward}_metropolis_vs_paper"] = (
                rows["metropolis"]["ess_bulk_per_s"] / rows["metropolis_paper"]["ess_bulk_per_s"]
            )
    if "default_vs_nutpie" in summary.get("harmonic", {}):
        flat["harmonic_default_vs_nutpie"] = summary["harmonic"]["default_vs_nutpie"]
    print(
        json.dumps(
            {
                **surrogate,
                **flat,
                "parameters": NAMES,
                "assemblies": ASSEMBLIES,
                "chains": 2,
                "forward_models": results,
                "summary": summary,
                "default_sampler": default,
                "default_vs_nutpie_target": 1.0,
                "load_average_1min": load,
                "cpu_count": os.cpu_count(),
            }
        )
    )


if __name__ == "__main__":
    main()
