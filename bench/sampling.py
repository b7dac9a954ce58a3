"""Benchmark: samplers on one updating posterior (the paper's Metropolis against the rest).

The posterior: a ``trc-like`` rig campaign of 25 assemblies (the rig's
reassembly draws, PLL backbones at its 12 levels), the paper's likelihood
(frequency at 9 amplitude levels, Gaussian copula of the fitted marginals) and
uniform priors on every coefficient of the model structure, as the paper
updates all of its model's: linear, viscous, cubic, and the microslip element's
stiffness and slip force (the Jenkins coefficient is redundant with those two,
:func:`identification.fitting.least_squares.default_free`). Boxes: ± 4 population spreads for the
coefficients the rig varies, ± 10 % for the microslip stiffness. The frequency
likelihood does not see viscous damping (as in the paper, flat directions come
with it). A surrogate is trained here first on that box (harmonic-balance
backbones on 41 excitation levels, amplitude and frequency: the paper's layout,
with a smaller network than the paper's; sizes printed), its levels reaching
0.03–3 mm on the nominal model so that the whole box covers the measured range.

Runs, each a fresh :func:`pm_joint.sample` call with 2 chains on the
2 cores, run lengths chosen so that fixed costs (compilation, process start)
weigh alike:

1. ``metropolis``: PyMC's Metropolis (one scalar coordinate at a time, all in
   one step) with the ONNX surrogate Op, 30 000 draws (the paper: 30 000
   samples in about 11 min);
2. ``metropolis_pymc_default``: the same with PyMC's default blocking (one
   Metropolis step, and one compiled logp, per variable);
3. ``demetropolisz`` with the surrogate Op;
4. ``nuts_harmonic``: NUTS through the native harmonic-balance graph;
5. ``nuts_surrogate``: NUTS with the surrogate Op (its gradient backpropagates
   through the network rebuilt in pytensor).

Wall time is the whole call (compilation, process start, sampling); CPU time
adds the chain processes; sampling time is PyMC's sampling loop alone. ESS is
arviz's minimum bulk ESS over the parameters, per second of wall time. The
machine is shared: the load average is printed, and CPU seconds show the cost
when other work slows the wall clock.

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

import arviz as az
import numpy as np
import torch

from identification.analytical.pll import pll_backbones
from identification.fitting.least_squares import default_free
from identification.measurements.backbone import Backbone, BackboneSet
from identification.rig import RIG_PRESETS, Rig
from pm_joint.inference import build_model, sample
from surrogates import (
    NetConfig,
    SurrogateRuntime,
    TrainingConfig,
    export_surrogate,
    train_surrogate,
)
from surrogates.dataset import generate_dataset

#: Relative half-width of the box of the coefficient the rig does not vary.
FIXED_SPREAD = 0.1
NAMES = default_free(RIG_PRESETS["trc-like"].model)
ASSEMBLIES = 25
TRAINING_CURVES = 500  # the paper's 25 measured + 475 analytical
#: Amplitudes (nominal model) of the surrogate's lowest and highest excitation levels: wide
#: enough that every parameter vector in the box reaches the measured range at both ends.
AMPLITUDE_RANGE_M = (3e-5, 3e-3)
NET = NetConfig(latent_dim=32, conv_filters=(32, 16), ffnn_width=128, ffnn_depth=3)
METROPOLIS_DRAWS = 30_000
METROPOLIS_TARGET_S = 120.0
PAPER_METROPOLIS_S = 11 * 60.0
ESS_RATIO_TARGET = 10.0
RUNS = {  # name: (forward model, sampler, draws, tuning steps, step options)
    "metropolis": ("surrogate", "metropolis", METROPOLIS_DRAWS, 2_000, {}),
    "metropolis_pymc_default": (
        "surrogate", "metropolis", METROPOLIS_DRAWS, 2_000, {"blocked": False},
    ),
    "demetropolisz": ("surrogate", "demetropolisz", 60_000, 5_000, {}),
    "nuts_harmonic": ("harmonic", "nuts", 20_000, 1_000, {}),
    "nuts_surrogate": ("surrogate", "nuts", 4_000, 1_000, {}),
}  # fmt: skip


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


def train(rig: Rig, bounds: dict, folder: str) -> tuple[SurrogateRuntime, dict]:
    """The surrogate over the prior box, with its size and accuracy."""
    start = time.perf_counter()
    data = generate_dataset(
        rig.model, NAMES, TRAINING_CURVES, bounds=bounds, amplitude_range_m=AMPLITUDE_RANGE_M,
        progress=False,
    )  # fmt: skip
    config = TrainingConfig(net=NET, max_epochs=400, finetune_epochs=400, progress=False)
    trained = train_surrogate(data.X, data.Y, data.spec, config)
    runtime = SurrogateRuntime.load(export_surrogate(trained, folder), threads=1)
    weights = sum(p.numel() for p in trained.model.parameters())
    channels = trained.metrics["channels"]
    return runtime, {
        "surrogate_curves": len(data),
        "surrogate_levels": data.spec.n_levels,
        "surrogate_weights": int(weights),
        "surrogate_net": NET.to_dict(),
        "surrogate_frequency_max_ape_pct": channels["frequency_hz"]["max_ape_pct"],
        "surrogate_amplitude_max_ape_pct": channels["amplitude_m"]["max_ape_pct"],
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
    ess = az.ess(idata, var_names=NAMES, method="bulk")
    rhat = az.rhat(idata, var_names=NAMES)
    stats = idata.sample_stats
    figures = {
        "draws": draws,
        "wall_s": wall,
        "cpu_s": cpu,
        "sampling_s": float(idata.posterior.attrs["sampling_time"]),
        "ess_bulk_min": float(min(ess[n] for n in NAMES)),
        "r_hat_max": float(max(rhat[n] for n in NAMES)),
        "means": {n: float(idata.posterior[n].mean()) for n in NAMES},
    }
    figures["ess_per_s"] = figures["ess_bulk_min"] / wall
    if "diverging" in stats:
        figures["divergences"] = int(stats["diverging"].sum())
    if "accepted" in stats:
        figures["acceptance"] = float(stats["accepted"].mean())
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
    with tempfile.TemporaryDirectory() as folder:
        runtime, surrogate = train(rig, bounds, folder)
        kwargs = {"names": NAMES, "bounds": bounds, "surrogate": runtime}
        models = {
            forward: build_model(rig.model, measured, forward=forward, **kwargs)
            for forward in ("surrogate", "harmonic")
        }
        results = {}
        for name, (forward, sampler, draws, tune, options) in RUNS.items():
            results[name] = run(models[forward], sampler, draws, tune, options)
            print(f"{name}: {results[name]['wall_s']:.1f} s", flush=True)
    report(results, surrogate)


def report(results: dict, surrogate: dict) -> None:
    """The table, the verdicts, and the JSON line."""
    for figures in results.values():
        for reference in ("metropolis", "metropolis_pymc_default"):
            ratio = figures["ess_per_s"] / results[reference]["ess_per_s"]
            figures[f"ess_per_s_vs_{reference}"] = ratio
    best = max(results, key=lambda n: results[n]["ess_per_s"])
    load = os.getloadavg()[0]
    print(
        f"\nposterior: {ASSEMBLIES} trc-like backbones, {len(NAMES)} parameters {NAMES}; "
        f"surrogate {surrogate['surrogate_weights']} weights ({surrogate['surrogate_curves']} "
        f"curves × {surrogate['surrogate_levels']} levels, trained in "
        f"{surrogate['surrogate_train_s']:.0f} s, frequency max error "
        f"{surrogate['surrogate_frequency_max_ape_pct']:.3f} %)"
    )
    print(
        f"{'run':<25s}{'draws':>8s}{'wall s':>8s}{'CPU s':>8s}{'loop s':>8s}{'min ESS':>9s}"
        f"{'ESS/s':>8s}{'×Metro':>8s}{'×default':>9s}{'r_hat':>7s}{'div':>5s}"
    )
    for name, f in results.items():
        print(
            f"{name:<25s}{f['draws']:>8d}{f['wall_s']:>8.1f}{f['cpu_s']:>8.1f}"
            f"{f['sampling_s']:>8.1f}{f['ess_bulk_min']:>9.0f}{f['ess_per_s']:>8.1f}"
            f"{f['ess_per_s_vs_metropolis']:>8.1f}{f['ess_per_s_vs_metropolis_pymc_default']:>9.1f}"
            f"{f['r_hat_max']:>7.3f}{f.get('divergences', ''):>5}"
        )
    print(f"load average (1 min): {load:.2f} on {os.cpu_count()} cores (shared machine)")
    metropolis_s = results["metropolis"]["wall_s"]
    print(
        f"Metropolis {METROPOLIS_DRAWS} draws: {metropolis_s:.1f} s "
        f"(target ≤ {METROPOLIS_TARGET_S:.0f} s; paper about {PAPER_METROPOLIS_S:.0f} s); "
        f"best sampler {best}: {results[best]['ess_per_s_vs_metropolis_pymc_default']:.1f}× "
        f"the ESS/s of PyMC's default Metropolis, "
        f"{results[best]['ess_per_s_vs_metropolis']:.1f}× ours (target ≥ {ESS_RATIO_TARGET:.0f}×)"
    )
    print(
        json.dumps(
            {
                **surrogate,
                "parameters": NAMES,
                "assemblies": ASSEMBLIES,
                "chains": 2,
                "runs": results,
                "metropolis_30000_s": metropolis_s,
                "metropolis_30000_target_s": METROPOLIS_TARGET_S,
                "metropolis_30000_paper_s": PAPER_METROPOLIS_S,
                "best_sampler": best,
                "best_ess_per_s_vs_metropolis_pymc_default": results[best][
                    "ess_per_s_vs_metropolis_pymc_default"
                ],
                "best_ess_per_s_vs_metropolis": results[best]["ess_per_s_vs_metropolis"],
                "ess_per_s_ratio_target": ESS_RATIO_TARGET,
                "load_average_1min": load,
                "cpu_count": os.cpu_count(),
            }
        )
    )


if __name__ == "__main__":
    main()
