"""Benchmark: PLL phase-resonance backbones (41 levels) of a two-mode model, the one-mode beside.

The two-mode model is that of ``bench/multimode_harmonic.py`` (a 100 Hz
bending-like mode, a 199 Hz torsion-like mode near 1:2, a cubic joint element on
``q = η1 + 0.4 η2`` and the quadratic coupling of ``κ η1² η2``); the loop locks
mode 1. The one-mode figure is that of the same mode-1 oscillator and element
without the second mode, run by the one-mode PLL
(:func:`identification.analytical.pll.simulate_pll`) and by the N-mode PLL on its
one-mode :class:`~identification.multimode.ModalModel`.

1. One backbone (serial path): the 41 levels are spaced geometrically between the
   base accelerations that hold 0.05 mm and 1 mm on the phase-resonant harmonic
   balance of mode 1; a warm-up call compiles (or loads) the kernels; the figure
   is the median of 3 runs. Its frequency, damping and mode 2's harmonic-2
   participation against the harmonic balance (H = 5) at the measured amplitudes.
2. A batch of ``N_SETS`` parameter sets (first argument, default 200; frequencies,
   damping ratios, element and coupling varied by ±10 %) on numba threads
   (``NUMBA_NUM_THREADS=2``, set before numba loads), warmed up on 2 sets; the
   one-mode batch of the same mode-1 sets beside.
3. A virtual two-mode TRC campaign (``pm-joint rig --preset two-mode``: the lab's PLL
   around the N-mode integrator, 15-point channels, lab artefacts; one record of
   ``RIG_LEVELS`` levels held ``RIG_HOLD_S`` each, in memory) beside the one-mode lab
   rig's record of the same levels, shaker and controller on the bending mode alone
   (its microslip and cubic terms on the mode); the two-mode record's ground truth (the
   harmonic balance of the locked mode's backbone, 81 points) is timed apart.

Wall and CPU seconds are both printed: the machine is shared.

Run: ``PYTHONPATH=. .venv/bin/python bench/multimode_pll.py [N_SETS]``. Prints a
table, then one JSON line, also written to ``bench/results/multimode_pll.json``.
"""

import os

for _var in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"
os.environ["NUMBA_NUM_THREADS"] = "2"

import dataclasses  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from multimode_harmonic import F1, K3, ZETA, parameter_sets, two_mode  # noqa: E402

from identification.analytical.pll import pll_backbones, simulate_pll  # noqa: E402
from identification.effects import CATALOGUE, LINEAR_STIFFNESS, VISCOUS_DAMPING  # noqa: E402
from identification.model import JointModel  # noqa: E402
from identification.multimode import (  # noqa: E402
    HarmonicSettings,
    ModalModel,
    modal_pll_backbones,
    phase_resonance,
    simulate_modal_pll,
)

N_LEVELS = 41
RIG_LEVELS, RIG_HOLD_S = 6, 2.5
CUBIC = CATALOGUE["cubic_stiffness"].name
SETTINGS = HarmonicSettings(5)


def timed(run, repeats: int):
    """Median wall and CPU seconds of ``repeats`` calls, and the last result."""
    walls, cpus = [], []
    for _ in range(repeats):
        start, cpu_start = time.perf_counter(), time.process_time()
        result = run()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - cpu_start)
    return float(np.median(walls)), float(np.median(cpus)), result


def rig_campaigns() -> dict[str, float]:
    """Seconds of a two-mode rig record, of its truth and of a one-mode lab record."""
    from identification.rig import LabRig, ModalRig
    from identification.rig.conditions import Drift

    two = ModalRig.preset("two-mode", levels=RIG_LEVELS, hold_s=RIG_HOLD_S, drift=Drift(),
                          schedule="up")  # fmt: skip
    model = two.model
    mode = model.modes[0]
    k = (2 * np.pi * mode.frequency_hz) ** 2
    terms = {LINEAR_STIFFNESS: k, VISCOUS_DAMPING: 2 * mode.damping_ratio * np.sqrt(k)}
    for element in model.elements:  # joint shape 1 on mode 1: the same terms on the mode
        terms[element.effect] = {"coefficient": element.coefficient, **element.shape}
    lab = {f.name: getattr(two, f.name) for f in dataclasses.fields(two)
           if f.name in ("shaker", "controller", "sensors", "hold_s", "ramp_s", "fs",
                         "noise_m_s", "shaker_gain")}  # fmt: skip
    one = LabRig(JointModel(terms), levels_v=two.levels_v, drift=Drift(), **lab)
    name = "Config1_PRT_Assemb1"

    def record(rig, structure):
        return rig.simulate(structure, two.shaker_gain, np.random.default_rng(0), name)

    record(two, model)  # warm-up
    record(one, one.model)
    two_s, two_cpu, _ = timed(lambda: record(two, model), 1)
    truth_s, truth_cpu, _ = timed(lambda: two.truth_backbones(model), 1)
    one_s, one_cpu, _ = timed(lambda: record(one, one.model), 1)
    return {
        "rig_levels": RIG_LEVELS,
        "rig_hold_s": RIG_HOLD_S,
        "two_mode_rig_record_s": round(two_s, 3),
        "two_mode_rig_record_cpu_s": round(two_cpu, 3),
        "two_mode_rig_truth_s": round(truth_s, 3),
        "two_mode_rig_truth_cpu_s": round(truth_cpu, 3),
        "one_mode_lab_rig_record_s": round(one_s, 3),
        "one_mode_lab_rig_record_cpu_s": round(one_cpu, 3),
    }


def main() -> None:
    n_sets = int(sys.argv[1]) if len(sys.argv) > 1 else 200
    model = two_mode()
    ends = phase_resonance(model, [0.05e-3, 1e-3], settings=SETTINGS).base_acceleration[:, 1]
    levels = np.geomspace(ends[0], ends[1], N_LEVELS)
    one_mode = JointModel(
        {
            LINEAR_STIFFNESS: (2 * np.pi * F1) ** 2,
            VISCOUS_DAMPING: 2 * ZETA * 2 * np.pi * F1,
            CUBIC: K3,
        }
    )
    one_modal = ModalModel.from_joint_model(one_mode)

    # Warm-up: compilation or cache load.
    simulate_modal_pll(model, levels[:2])
    simulate_pll(one_mode, levels[:2])
    two_s, two_cpu, result = timed(lambda: simulate_modal_pll(model, levels), 3)
    one_s, one_cpu, one = timed(lambda: simulate_pll(one_mode, levels), 3)
    one_modal_s, one_modal_cpu, one_by_modal = timed(
        lambda: simulate_modal_pll(one_modal, levels), 3
    )
    reference = phase_resonance(model, result.amplitude_m, settings=SETTINGS)
    frequency_error = np.nanmax(np.abs(result.frequency_hz / reference.frequency_hz - 1))
    damping_error = np.nanmax(np.abs(result.damping_ratio / reference.damping_ratio - 1))
    h2 = result.participation_amplitude_m[:, 1, 1]
    h2_reference = np.hypot(reference.coefficients[:, 1, 3], reference.coefficients[:, 1, 4])
    h2_error = np.nanmax(np.abs(h2 / h2_reference - 1))
    one_gap = np.nanmax(np.abs(one_by_modal.frequency_hz / one.frequency_hz - 1))

    values, names = parameter_sets(model, n_sets)
    one_values = np.column_stack(
        [(2 * np.pi * values[:, 0]) ** 2, 2 * values[:, 2] * 2 * np.pi * values[:, 0], values[:, 4]]
    )
    one_names = [LINEAR_STIFFNESS, VISCOUS_DAMPING, CUBIC]
    modal_pll_backbones(model, levels, values[:2], names)  # warm-up
    pll_backbones(one_mode, levels, one_values[:2], one_names, progress=False)
    batch_s, batch_cpu, batch = timed(lambda: modal_pll_backbones(model, levels, values, names), 1)
    one_batch_s, one_batch_cpu, one_batch = timed(
        lambda: pll_backbones(one_mode, levels, one_values, one_names, progress=False), 1
    )
    rig = rig_campaigns()
    load = os.getloadavg()[0]

    rows = [
        ("levels", f"{N_LEVELS}: {levels[0]:.3g}–{levels[-1]:.3g} m/s²"),
        (
            "amplitudes (mode 1)",
            f"{np.nanmin(result.amplitude_m) * 1e3:.3f}–"
            f"{np.nanmax(result.amplitude_m) * 1e3:.3f} mm",
        ),
        ("locked", f"{int(result.locked.sum())}/{N_LEVELS} (one mode {int(one.locked.sum())})"),
        ("two modes, one backbone", f"{two_s:.3f} s wall, {two_cpu:.3f} s CPU"),
        ("one mode, analytical.pll", f"{one_s:.3f} s wall, {one_cpu:.3f} s CPU"),
        (
            "one mode, multimode.pll",
            f"{one_modal_s:.3f} s wall, {one_modal_cpu:.3f} s CPU (max |Δf/f| {one_gap:.1e})",
        ),
        ("max |Δf| vs multimode HB", f"{frequency_error * 100:.5f} %"),
        ("max |ΔD| vs multimode HB", f"{damping_error * 100:.3f} %"),
        ("max |Δ mode-2 h2| vs HB", f"{h2_error * 100:.3f} %"),
        (
            f"two modes, {n_sets} sets, 2 threads",
            f"{batch_s:.1f} s wall, {batch_cpu:.1f} s CPU, "
            f"{batch.locked.mean() * 100:.1f} % locked",
        ),
        (
            f"one mode, {n_sets} sets, 2 threads",
            f"{one_batch_s:.1f} s wall, "
            f"{one_batch_cpu:.1f} s CPU, "
            f"{one_batch.locked.mean() * 100:.1f} % locked",
        ),
        (
            f"two-mode rig record ({RIG_LEVELS} × {RIG_HOLD_S} s)",
            f"{rig['two_mode_rig_record_s']:.1f} s wall "
            f"(its truth's balance {rig['two_mode_rig_truth_s']:.1f} s more)",
        ),
        ("one-mode lab rig record, same levels", f"{rig['one_mode_lab_rig_record_s']:.1f} s wall"),
        ("load average (1 min)", f"{load:.2f} on {os.cpu_count()} cores (shared machine)"),
    ]
    width = max(len(r[0]) for r in rows)
    print("N-mode PLL backbone benchmark (compile warm-up excluded)")
    for name, value in rows:
        print(f"  {name:<{width}}  {value}")
    figures = {
        "bench": "multimode_pll",
        "n_levels": N_LEVELS,
        "two_mode_backbone_s": round(two_s, 4),
        "two_mode_backbone_cpu_s": round(two_cpu, 4),
        "one_mode_backbone_s": round(one_s, 4),
        "one_mode_backbone_cpu_s": round(one_cpu, 4),
        "one_mode_by_multimode_backbone_s": round(one_modal_s, 4),
        "one_mode_paths_max_rel_frequency_gap": float(one_gap),
        "locked": int(result.locked.sum()),
        "frequency_error_vs_multimode_hb_pct": round(float(frequency_error * 100), 6),
        "damping_error_vs_multimode_hb_pct": round(float(damping_error * 100), 4),
        "mode2_h2_error_vs_multimode_hb_pct": round(float(h2_error * 100), 4),
        "n_sets": n_sets,
        "two_mode_batch_s": round(batch_s, 2),
        "two_mode_batch_cpu_s": round(batch_cpu, 2),
        "two_mode_batch_locked_fraction": round(float(batch.locked.mean()), 4),
        "one_mode_batch_s": round(one_batch_s, 2),
        "one_mode_batch_cpu_s": round(one_batch_cpu, 2),
        "one_mode_batch_locked_fraction": round(float(one_batch.locked.mean()), 4),
        "threads": 2,
        **rig,
        "load_average_1min": round(load, 2),
    }
    line = json.dumps(figures)
    print(line)
    results = Path(__file__).parent / "results" / "multimode_pll.json"
    results.write_text(json.dumps({**figures, "command": " ".join(sys.argv)}, indent=1) + "\n")


if __name__ == "__main__":
    main()
