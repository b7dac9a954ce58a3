"""Benchmark: harmonic-balance backbones for 1000 parameter sets × 41 amplitudes.

One core (threads pinned to 1 before numpy/numba load). Parameter sets: the
``pandey2025`` preset with every coefficient varied uniformly by ±10 %, and a
Duffing + microslip model varied the same way (multi-harmonic path). The numba
kernels are compiled (or loaded from cache) by a warm-up call before timing.

Run: ``.venv/bin/python bench/harmonic.py``. Prints a table, then one JSON line.
"""

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import json  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from identification.analytical.harmonic import backbone, default_time_samples  # noqa: E402
from identification.model import JointModel  # noqa: E402

N_SETS = 1000
AMPLITUDES_M = np.linspace(0.05e-3, 2.0e-3, 41)
HARMONICS = 5
SINGLE_TARGET_MS = 50.0
MULTI_TARGET_S = 5.0


def varied_sets(model: JointModel, seed: int) -> tuple[list[str], np.ndarray]:
    """±10 % uniform variation of every parameter of ``model``."""
    names = model.parameter_names
    nominal = np.array([model.parameters[n] for n in names])
    return names, nominal * np.random.default_rng(seed).uniform(0.9, 1.1, (N_SETS, len(names)))


def median_time(run, repeats: int) -> tuple[float, object]:
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), result


def duffing_microslip() -> JointModel:
    w0 = 2 * np.pi * 100.0
    return JointModel(
        {
            "linear_stiffness": w0**2,
            "viscous_damping": 2 * 0.002 * w0,
            "cubic_stiffness": 1e11,
            "microslip": {"coefficient": 1.0, "k_t": 0.3 * w0**2, "F_s": 0.3 * w0**2 * 2e-4},
        },
        name="duffing+microslip",
    )


def main() -> None:
    pandey = JointModel.preset("pandey2025")
    names, sets = varied_sets(pandey, seed=0)
    ms_model = duffing_microslip()
    ms_names, ms_sets = varied_sets(ms_model, seed=1)

    # Warm-up: numba compilation / cache load, not timed.
    backbone(pandey, AMPLITUDES_M, parameters=sets[:2], names=names, method="multi")
    backbone(ms_model, AMPLITUDES_M, parameters=ms_sets[:2], names=ms_names, method="multi")

    def single():
        return backbone(pandey, AMPLITUDES_M, parameters=sets, names=names)

    def multi():
        return backbone(pandey, AMPLITUDES_M, parameters=sets, names=names, method="multi",
                        harmonics=HARMONICS)  # fmt: skip

    def multi_ms():
        return backbone(ms_model, AMPLITUDES_M, parameters=ms_sets, names=ms_names,
                        method="multi", harmonics=HARMONICS)  # fmt: skip

    single_s, single_result = median_time(single, repeats=7)
    multi_s, multi_result = median_time(multi, repeats=3)
    ms_s, ms_result = median_time(multi_ms, repeats=3)

    gap_f = np.nanmax(np.abs(multi_result.frequency_hz / single_result.frequency_hz - 1))
    gap_d = np.nanmax(np.abs(multi_result.damping_ratio / single_result.damping_ratio - 1))
    rows = [
        ("pandey2025 ±10 %, single", f"{single_s * 1e3:.1f} ms", f"≤ {SINGLE_TARGET_MS:.0f} ms",
         single_result.converged.mean(), "-"),
        (f"pandey2025 ±10 %, H={HARMONICS}", f"{multi_s:.2f} s", f"≤ {MULTI_TARGET_S:.0f} s",
         multi_result.converged.mean(), default_time_samples(pandey, HARMONICS)),
        (f"duffing+microslip ±10 %, H={HARMONICS}", f"{ms_s:.2f} s", "-",
         ms_result.converged.mean(), default_time_samples(ms_model, HARMONICS)),
    ]  # fmt: skip
    print(f"{N_SETS} backbones × {AMPLITUDES_M.size} amplitudes "
          f"({AMPLITUDES_M[0] * 1e3:.2f}–{AMPLITUDES_M[-1] * 1e3:.2f} mm), one core, "
          "after a numba warm-up call")  # fmt: skip
    print(f"{'case':34} {'time':>10} {'target':>9} {'converged':>10} {'n_time':>7}")
    for case, t, target, conv, n_time in rows:
        print(f"{case:34} {t:>10} {target:>9} {conv:>10.4f} {n_time!s:>7}")
    print(f"pandey2025 H={HARMONICS} vs single: max |Δf/f| = {gap_f:.2e}, max |ΔD/D| = {gap_d:.2e}")
    print(json.dumps({
        "single_1000x41_ms": round(single_s * 1e3, 2),
        "single_target_ms": SINGLE_TARGET_MS,
        "multi_h5_1000x41_s": round(multi_s, 3),
        "multi_target_s": MULTI_TARGET_S,
        "multi_h5_n_time": default_time_samples(pandey, HARMONICS),
        "multi_h5_converged_fraction": float(multi_result.converged.mean()),
        "multi_h5_duffing_microslip_1000x41_s": round(ms_s, 3),
        "multi_h5_duffing_microslip_converged_fraction": float(ms_result.converged.mean()),
        "multi_vs_single_max_rel_frequency_gap": float(gap_f),
        "multi_vs_single_max_rel_damping_gap": float(gap_d),
        "threads": 1,
    }))  # fmt: skip


if __name__ == "__main__":
    main()
