"""Benchmark: the N-mode backbone graph for 1000 parameter sets × 41 amplitudes.

The model and parameter sets of ``bench/multimode_harmonic.py`` (a 100 Hz and a
199 Hz mode, near 1:2, a cubic joint element on ``q = η1 + 0.4 η2`` and the
coupling potential ``κ η1² η2``; frequencies, damping ratios, element and
couplings varied by ±10 %), locked on mode 1. Timed, after compiling:

* the two-mode graph (:func:`pm_joint.forward.modal_harmonic.modal_backbone_graph`),
  its value and its value with the gradient of the summed frequencies (what NUTS
  asks for);
* the one-mode graph (:func:`pm_joint.forward.harmonic.harmonic_backbone_graph`) of
  the same mode-1 oscillator and element, on the same grid;
* beside them, the AFT harmonic balance's time for the same work, read from
  ``bench/results/multimode_harmonic.json`` (not re-run: 20–30 s), and its
  accuracy against the graph on the first ``N_CHECK`` sets, solved here.

The ±10 % sets straddle the 1:2 resonance (f2/f1 from 1.63 to 2.43): the graph
reports the points where it does not settle (NaN), and the JSON gives their share.

One core (threads pinned to 1 before numpy loads).
Run: ``PYTHONPATH=. .venv/bin/python bench/modal_graph.py [N_SETS]``.
Prints a table, then one JSON line; writes ``bench/results/modal_graph.json``.
"""

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytensor  # noqa: E402
import pytensor.tensor as pt  # noqa: E402
from harmonic import median_time  # noqa: E402  bench/harmonic.py, beside this script
from multimode_harmonic import (  # noqa: E402  the same model and sets
    AMPLITUDES_M,
    CUBIC,
    F1,
    HARMONICS,
    K3,
    ZETA,
    parameter_sets,
    two_mode,
)

from identification.effects import LINEAR_STIFFNESS, VISCOUS_DAMPING  # noqa: E402
from identification.model import JointModel  # noqa: E402
from identification.multimode import HarmonicSettings, phase_resonance  # noqa: E402
from pm_joint.forward import harmonic_backbone_graph, modal_backbone_graph  # noqa: E402

RESULTS = Path(__file__).parent / "results"
#: Sets solved by the AFT balance here for the accuracy figure.
N_CHECK = 20


def main() -> None:
    n_sets = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    model = two_mode()
    values, names = parameter_sets(model, n_sets)
    theta = pt.dmatrix("theta")
    out = modal_backbone_graph(model, theta, names, AMPLITUDES_M)
    start = time.perf_counter()
    value = pytensor.function([theta], [out.backbone, out.converged])
    value(values[:2])  # the scan's inner function compiles on its first call
    compile_s = time.perf_counter() - start
    frequency_sum = pt.sum(pt.switch(out.converged, out.frequency_hz, 0.0))
    start = time.perf_counter()
    with_gradient = pytensor.function([theta], [out.backbone, pt.grad(frequency_sum, theta)])
    with_gradient(values[:2])
    gradient_compile_s = time.perf_counter() - start

    one_mode = JointModel(
        {LINEAR_STIFFNESS: (2 * np.pi * F1) ** 2, VISCOUS_DAMPING: 2 * ZETA * 2 * np.pi * F1,
         CUBIC: K3}
    )  # fmt: skip
    one_values = np.column_stack(
        [(2 * np.pi * values[:, 0]) ** 2, 2 * values[:, 2] * 2 * np.pi * values[:, 0], values[:, 4]]
    )
    one_theta = pt.dmatrix("one_theta")
    one_graph = pytensor.function(
        [one_theta],
        harmonic_backbone_graph(
            one_mode, one_theta, [LINEAR_STIFFNESS, VISCOUS_DAMPING, CUBIC], AMPLITUDES_M
        ),
    )
    one_graph(one_values[:2])

    graph_s, (backbone, converged) = median_time(lambda: value(values), 5)
    gradient_s, _ = median_time(lambda: with_gradient(values), 3)
    one_s, _ = median_time(lambda: one_graph(one_values), 5)

    check = phase_resonance(
        model, AMPLITUDES_M, settings=HarmonicSettings(HARMONICS),
        parameters=values[:N_CHECK], names=names,
    )  # fmt: skip
    both = converged[:N_CHECK] & check.converged
    gap = np.abs(backbone[:N_CHECK, :, 1] / check.frequency_hz - 1)[both]
    aft = json.loads((RESULTS / "multimode_harmonic.json").read_text())

    rows = [
        ("two modes, graph (value)", graph_s),
        ("two modes, graph (value + gradient)", gradient_s),
        ("one mode, graph (value)", one_s),
        ("two modes, AFT phase resonance (H=5)*", aft["two_mode_phase_resonance_s"]),
    ]
    print(f"{n_sets} parameter sets × {AMPLITUDES_M.size} amplitudes, one core, compiled")
    print(f"{'case':40} {'time':>9} {'per set':>10}")
    for case, seconds in rows:
        print(f"{case:40} {seconds:>8.4f}s {seconds / n_sets * 1e3:>8.4f}ms")
    print(f"* from bench/results/multimode_harmonic.json ({aft['_run']['date']})")
    print(
        f"graph compile {compile_s:.1f} s (with gradient {gradient_compile_s:.1f} s); points "
        f"settled {converged.mean():.4f}; max |Δf/f| to the AFT balance on {N_CHECK} sets "
        f"{gap.max():.2e} (median {np.median(gap):.1e}, {both.mean():.3f} of points in both)"
    )
    figures = {
        "n_sets": n_sets,
        "n_amplitudes": int(AMPLITUDES_M.size),
        "two_mode_graph_s": round(graph_s, 4),
        "two_mode_graph_ms_per_set": round(graph_s / n_sets * 1e3, 4),
        "two_mode_graph_with_gradient_s": round(gradient_s, 4),
        "two_mode_graph_compile_s": round(compile_s, 1),
        "two_mode_graph_with_gradient_compile_s": round(gradient_compile_s, 1),
        "two_mode_graph_settled_fraction": float(converged.mean()),
        "one_mode_graph_s": round(one_s, 4),
        "two_mode_aft_phase_resonance_s": aft["two_mode_phase_resonance_s"],
        "two_mode_aft_source": "bench/results/multimode_harmonic.json",
        "aft_check_sets": N_CHECK,
        "aft_check_max_rel_frequency_gap": float(gap.max()),
        "aft_check_median_rel_frequency_gap": float(np.median(gap)),
        "aft_check_points_in_both_fraction": float(both.mean()),
        "threads": 1,
    }
    print(json.dumps(figures))
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "modal_graph.json").write_text(json.dumps(figures, indent=1) + "\n")


if __name__ == "__main__":
    main()
