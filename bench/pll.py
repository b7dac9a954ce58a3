"""Benchmark: PLL phase-resonance backbones (41 levels) of the ``pandey2025`` model.

1. One backbone on one core (``NUMBA_NUM_THREADS=1`` set before numba loads;
   the single-model path is serial anyway). The 41 levels are spaced
   geometrically between the base accelerations that hold 0.05 mm and 1 mm on
   the multi-harmonic backbone. Compilation (or cache load) is a warm-up call,
   not timed; the figure is the median of 5 runs.
2. A batch of 500 parameter sets (every coefficient varied uniformly by ±10 %)
   on both cores: numba threads (``prange`` over sets) in a child process
   started with ``NUMBA_NUM_THREADS=2``, warmed up on 2 sets first.

Wall and CPU seconds are both printed: the machine is shared, and the CPU
time shows the cost when other work slows the wall clock.

Run: ``.venv/bin/python bench/pll.py``. Prints a table, then one JSON line.
"""

import os
import sys

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"
if "--batch" not in sys.argv:  # the batch child gets its thread count from the parent
    os.environ["NUMBA_NUM_THREADS"] = "1"

import json  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from identification.analytical.harmonic import backbone  # noqa: E402
from identification.analytical.pll import pll_backbones, simulate_pll  # noqa: E402
from identification.model import JointModel  # noqa: E402

N_LEVELS = 41
N_SETS = 500
VARIATION = 0.10
BACKBONE_TARGET_S = 0.1
BATCH_TARGET_S = 40.0
BATCH_CORES = 2


def levels_for(model: JointModel, low_m: float = 0.05e-3, high_m: float = 1e-3) -> np.ndarray:
    """Base-acceleration levels (m/s²) spanning the amplitudes ``low_m`` to ``high_m``."""
    ends = backbone(model, [low_m, high_m], method="multi").base_acceleration
    return np.geomspace(ends[0], ends[1], N_LEVELS)


def varied_sets(model: JointModel) -> tuple[list[str], np.ndarray]:
    names = model.parameter_names
    nominal = np.array([model.parameters[n] for n in names])
    rng = np.random.default_rng(0)
    return names, nominal * rng.uniform(1 - VARIATION, 1 + VARIATION, (N_SETS, len(names)))


def batch() -> dict:
    """Child process: the 500-set batch on numba threads."""
    import numba

    model = JointModel.preset("pandey2025")
    levels = levels_for(model)
    names, sets = varied_sets(model)
    pll_backbones(model, levels, sets[:2], names, progress=False)  # warm-up, not timed
    start, cpu_start = time.perf_counter(), time.process_time()
    result = pll_backbones(model, levels, sets, names, progress=False)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    return {
        "batch_500_s": round(seconds, 2),
        "batch_500_cpu_s": round(cpu, 2),
        "batch_threads": numba.get_num_threads(),
        "batch_locked_fraction": round(float(result.locked.mean()), 4),
    }


def main() -> None:
    model = JointModel.preset("pandey2025")
    levels = levels_for(model)
    simulate_pll(model, levels[:2])  # warm-up: compilation or cache load
    times, cpu_times = [], []
    for _ in range(5):
        start, cpu_start = time.perf_counter(), time.process_time()
        result = simulate_pll(model, levels)
        times.append(time.perf_counter() - start)
        cpu_times.append(time.process_time() - cpu_start)
    backbone_s, backbone_cpu_s = float(np.median(times)), float(np.median(cpu_times))
    reference = backbone(model, result.amplitude_m, method="multi")
    frequency_error = np.abs(result.frequency_hz / reference.frequency_hz - 1).max()
    damping_error = np.abs(result.damping_ratio / reference.damping_ratio - 1).max()
    record = simulate_pll(model, levels, record=True).time_series

    child = subprocess.run(
        [sys.executable, __file__, "--batch"],
        env={**os.environ, "NUMBA_NUM_THREADS": str(BATCH_CORES)},
        capture_output=True,
        text=True,
        check=True,
    )
    figures = json.loads(child.stdout.strip().splitlines()[-1])
    load = os.getloadavg()[0]

    rows = [
        ("levels", f"{N_LEVELS}: {levels[0]:.3g}–{levels[-1]:.3g} m/s²"),
        (
            "amplitudes",
            f"{result.amplitude_m.min() * 1e3:.3f}–{result.amplitude_m.max() * 1e3:.3f} mm",
        ),
        ("locked", f"{int(result.locked.sum())}/{N_LEVELS}"),
        ("simulated time", f"{record.t[-1]:.1f} s ({record.t.size} samples at {record.fs:g} Hz)"),
        (
            "one backbone, 1 core",
            f"{backbone_s:.3f} s wall, {backbone_cpu_s:.3f} s CPU (target ≤ {BACKBONE_TARGET_S} s)",
        ),
        ("max |Δf| vs multi-HB", f"{frequency_error * 100:.4f} %"),
        ("max |ΔD| vs multi-HB", f"{damping_error * 100:.3f} %"),
        ("load average (1 min)", f"{load:.2f} on {os.cpu_count()} cores (shared machine)"),
        (
            f"{N_SETS} sets, {figures['batch_threads']} threads",
            f"{figures['batch_500_s']:.1f} s wall, {figures['batch_500_cpu_s']:.1f} s CPU "
            f"(target ≤ {BATCH_TARGET_S} s wall), "
            f"{figures['batch_locked_fraction'] * 100:.1f} % levels locked",
        ),
    ]
    width = max(len(r[0]) for r in rows)
    print("PLL backbone benchmark (pandey2025; compile warm-up excluded)")
    for name, value in rows:
        print(f"  {name:<{width}}  {value}")
    print(
        json.dumps(
            {
                "bench": "pll",
                "n_levels": N_LEVELS,
                "amplitude_min_mm": round(float(result.amplitude_m.min() * 1e3), 4),
                "amplitude_max_mm": round(float(result.amplitude_m.max() * 1e3), 4),
                "simulated_s": round(float(record.t[-1]), 2),
                "backbone_s": round(backbone_s, 4),
                "backbone_cpu_s": round(backbone_cpu_s, 4),
                "backbone_target_s": BACKBONE_TARGET_S,
                "frequency_error_vs_multi_hb_pct": round(float(frequency_error * 100), 5),
                "damping_error_vs_multi_hb_pct": round(float(damping_error * 100), 4),
                **figures,
                "batch_500_target_s": BATCH_TARGET_S,
                "load_average_1min": round(load, 2),
                "paper": "Simulink PLL model 'computationally exhaustive' (no figure given)",
            }
        )
    )


if __name__ == "__main__":
    if "--batch" in sys.argv:
        print(json.dumps(batch()))
    else:
        main()
