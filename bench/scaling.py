"""Benchmark: surrogate dataset generation on 1 and 2 workers, serial, process pool and dask.

Generates the same ``--n``-curve amplitude-grid dataset (harmonic balance on 41
response amplitudes, :func:`surrogates.dataset.generate_dataset`) of the
``trc-like`` rig model, by default multi-harmonic (5 harmonics, as a model with
even terms needs), over a ±20 % box:

- in this process (the serial reference),
- on a ``concurrent.futures.ProcessPoolExecutor`` with 1 and 2 processes,
- on a dask ``LocalCluster`` with 1 and 2 single-threaded worker processes,

and checks that every run gives the serial dataset bit for bit. Every process
runs one thread (``NUMBA_NUM_THREADS=1``), so the worker count is the only
parallelism. Each pool is warmed up first (worker start and numba's first call
are not timed). Figures:
wall seconds, the speed-up of 1 → 2 workers, CPU seconds per curve (summed over
the worker processes, from ``resource.getrusage``: what the machine's load does
not inflate), and the projected time for a 10⁵-curve dataset per worker count,
from the measured per-worker throughput. The old representation (harmonic
balance inverted onto 41 excitation levels) on the same parameter sets, serial,
is the peer on the same work.

The machine is stated (CPU model, cores, load average before and after): on a
shared machine the wall-clock speed-up is a lower bound of what idle cores give.

Prints a table, then ONE JSON line with every figure (units in the keys).

    .venv/bin/python bench/scaling.py [--n 2000] [--harmonic multi|single]
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import multiprocessing
import os
import platform
import resource
import time

# One thread per process (the multi-harmonic solver would use one per core): the worker
# count is then the only parallelism. Set before numba is imported; workers inherit it.
os.environ["NUMBA_NUM_THREADS"] = "1"

import numpy as np

from identification.fitting.least_squares import default_free
from identification.rig import RIG_PRESETS
from surrogates.dataset import BackboneDataset, generate_dataset

PROJECTED_CURVES = 100_000


def parse_args() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2000, help="curves in the dataset")
    parser.add_argument("--harmonic", choices=["multi", "single"], default="multi")
    parser.add_argument("--spread", type=float, default=0.2, help="relative half-width of the box")
    parser.add_argument("--chunk-size", type=int, default=16)
    parser.add_argument("--skip-peer", action="store_true", help="skip the excitation-level peer")
    return parser.parse_args()


def cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            for line in info:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def own_cpu_seconds() -> float:
    """CPU seconds (user + system) of the calling process."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def same(reference: BackboneDataset, other: BackboneDataset) -> bool:
    arrays = ("X", "Y", "observed", "non_monotone")
    if any(not np.array_equal(getattr(reference, a), getattr(other, a)) for a in arrays):
        return False
    strip = ("created",)
    return {k: v for k, v in reference.provenance.items() if k not in strip} == {
        k: v for k, v in other.provenance.items() if k not in strip
    }


def main() -> None:
    args = parse_args()
    model = RIG_PRESETS["trc-like"].model
    names = default_free(model)
    options = {
        "representation": "amplitude_grid",
        "spread": args.spread,
        "harmonic": args.harmonic,
        "harmonics": 5,
        "chunk_size": args.chunk_size,
        "progress": False,
        "seed": 0,
    }
    machine = {
        "cpu_model": cpu_model(),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "load_average_before": list(os.getloadavg()),
    }
    generate_dataset(model, names, 4, **options)  # numba's first call, here

    runs: dict[str, dict] = {}
    start_cpu, start = own_cpu_seconds(), time.perf_counter()
    serial = generate_dataset(model, names, args.n, **options)
    runs["serial"] = {
        "workers": 1,
        "wall_s": time.perf_counter() - start,
        "cpu_s": own_cpu_seconds() - start_cpu,
        "identical": True,
    }

    context = multiprocessing.get_context("forkserver")
    for workers in (1, 2):
        with concurrent.futures.ProcessPoolExecutor(workers, mp_context=context) as pool:
            generate_dataset(model, names, 2 * workers * args.chunk_size, **options, executor=pool)
            start = time.perf_counter()
            data = generate_dataset(model, names, args.n, **options, executor=pool)
            wall = time.perf_counter() - start
        # (its workers' CPU time is not reachable from here: forkserver children)
        runs[f"process_pool_{workers}"] = {
            "workers": workers,
            "wall_s": wall,
            "cpu_s": None,
            "identical": same(serial, data),
        }

    from dask.distributed import Client, LocalCluster

    for workers in (1, 2):
        with (
            LocalCluster(
                n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            Client(cluster) as client,
        ):
            generate_dataset(
                model, names, 2 * workers * args.chunk_size, **options, executor=client
            )
            before = sum(client.run(own_cpu_seconds).values())
            start = time.perf_counter()
            data = generate_dataset(model, names, args.n, **options, executor=client)
            wall = time.perf_counter() - start
            cpu = sum(client.run(own_cpu_seconds).values()) - before
        runs[f"dask_{workers}"] = {
            "workers": workers,
            "wall_s": wall,
            "cpu_s": cpu,
            "identical": same(serial, data),
        }

    peer = None
    if not args.skip_peer:
        levels_options = {k: v for k, v in options.items() if k != "representation"}
        start_cpu, start = own_cpu_seconds(), time.perf_counter()
        old = generate_dataset(model, names, args.n, **levels_options)
        peer = {
            "representation": "excitation_levels",
            "workers": 1,
            "wall_s": time.perf_counter() - start,
            "cpu_s": own_cpu_seconds() - start_cpu,
            "kept": len(old),
            "failed": int(old.failed_reasons.size),
        }
    machine["load_average_after"] = list(os.getloadavg())

    n = args.n
    dask_1, dask_2 = runs["dask_1"], runs["dask_2"]
    cpu_per_curve = dask_2["cpu_s"] / n
    per_worker = {
        "wall_curves_per_s_1_worker": n / dask_1["wall_s"],
        "wall_curves_per_s_per_worker_2_workers": n / dask_2["wall_s"] / 2,
        "cpu_s_per_curve": cpu_per_curve,
        "cpu_curves_per_s": 1 / cpu_per_curve,
    }
    speedup = {
        "dask_1_to_2": dask_1["wall_s"] / dask_2["wall_s"],
        "process_pool_1_to_2": runs["process_pool_1"]["wall_s"] / runs["process_pool_2"]["wall_s"],
    }
    # 10^5 curves: at the per-worker throughput measured with 2 workers (wall), and at the
    # CPU cost per curve (what idle cores would give, scheduling overhead aside).
    projected = {
        f"{w}_workers": {
            "wall_s_at_measured_throughput": PROJECTED_CURVES
            / (w * per_worker["wall_curves_per_s_per_worker_2_workers"]),
            "wall_s_at_cpu_cost": PROJECTED_CURVES * cpu_per_curve / w,
        }
        for w in (1, 2, 8, 32)
    }

    load = (machine["load_average_before"][0], machine["load_average_after"][0])
    print(
        f"machine: {machine['cpu_model']}, {machine['cpu_count']} cores, load "
        f"{load[0]:.1f} → {load[1]:.1f}"
    )
    print(f"dataset: {n} curves, trc-like, {args.harmonic}-harmonic, ±{args.spread:g} box")
    print(f"{'run':<18s}{'workers':>8s}{'wall s':>9s}{'CPU s':>9s}{'identical':>11s}")
    for name, run in runs.items():
        cpu = "—" if run["cpu_s"] is None else f"{run['cpu_s']:.1f}"
        print(
            f"{name:<18s}{run['workers']:>8d}{run['wall_s']:>9.1f}{cpu:>9s}"
            f"{run['identical']!s:>11s}"
        )
    if peer:
        print(
            f"{'levels (peer)':<18s}{1:>8d}{peer['wall_s']:>9.1f}{peer['cpu_s']:>9.1f}"
            f"{'—':>11s}   kept {peer['kept']}, failed {peer['failed']}"
        )
    print(
        f"speed-up 1 → 2 workers: dask {speedup['dask_1_to_2']:.2f}×, process pool "
        f"{speedup['process_pool_1_to_2']:.2f}×"
    )
    print(
        f"CPU cost {1e3 * cpu_per_curve:.2f} ms per curve; 10⁵ curves on 8 workers: "
        f"{projected['8_workers']['wall_s_at_cpu_cost'] / 60:.1f} min at that cost, "
        f"{projected['8_workers']['wall_s_at_measured_throughput'] / 60:.1f} min at the "
        "measured wall throughput"
    )
    print(
        json.dumps(
            {
                "bench": "scaling",
                "dask_speedup_1_to_2": speedup["dask_1_to_2"],
                "cpu_ms_per_curve": 1e3 * cpu_per_curve,
                "n_curves": n,
                "model": "trc-like",
                "harmonic": args.harmonic,
                "spread_rel": args.spread,
                "n_amplitudes": 41,
                "chunk_size": args.chunk_size,
                "machine": machine,
                "runs": runs,
                "speedup_1_to_2": speedup,
                "per_worker": per_worker,
                "projected_1e5_curves": projected,
                "peer_excitation_levels_serial": peer,
                "all_identical": all(run["identical"] for run in runs.values()),
            }
        )
    )


if __name__ == "__main__":
    main()
