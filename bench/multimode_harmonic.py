"""Benchmark: two-mode harmonic balance for 1000 parameter sets × 41 amplitudes.

The two-mode model: a 100 Hz bending-like mode and a 199 Hz torsion-like mode
(near 1:2, as on the TRC panel), a cubic joint element on ``q = η1 + 0.4 η2``
and the quadratic coupling of the potential ``κ η1² η2``. Every parameter set
varies the mode frequencies, damping ratios, the element and the coupling by
±10 % (uniform). Two problems of :mod:`identification.multimode`: the
phase-resonant backbone of mode 1 and its nonlinear mode (EPMC), H = 5, both
walked along the 41 amplitudes (natural continuation, all sets in one batch).
Beside them, the one-mode figure: the package's one-mode multi-harmonic
backbone (:func:`identification.analytical.harmonic.backbone`) of the same
mode-1 oscillator with the same element and no second mode, and this package's
one-mode path on it.

One core (threads pinned to 1 before numpy/numba load); a warm-up call compiles
the numba kernels first. ``N_SETS`` (first argument) sets the number of sets.

Run: ``PYTHONPATH=. .venv/bin/python bench/multimode_harmonic.py [N_SETS]``.
Prints a table, then one JSON line.
"""

import os

for _var in ("NUMBA_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS"):
    os.environ[_var] = "1"

import json  # noqa: E402
import sys  # noqa: E402

import numpy as np  # noqa: E402
from harmonic import median_time  # noqa: E402  bench/harmonic.py, beside this script

from identification.analytical.harmonic import backbone  # noqa: E402
from identification.effects import CATALOGUE, LINEAR_STIFFNESS, VISCOUS_DAMPING  # noqa: E402
from identification.model import JointModel  # noqa: E402
from identification.multimode import (  # noqa: E402
    Coupling,
    HarmonicSettings,
    JointElement,
    ModalModel,
    Mode,
    nonlinear_modes,
    phase_resonance,
)

AMPLITUDES_M = np.linspace(0.05e-3, 2.0e-3, 41)
HARMONICS = 5
CUBIC = CATALOGUE["cubic_stiffness"].name
F1, F2, ZETA, K3, KAPPA, SHAPE2 = 100.0, 199.0, 0.003, 1e11, 2e6, 0.4


def two_mode() -> ModalModel:
    return ModalModel(
        modes=(Mode(F1, ZETA, 1.0), Mode(F2, ZETA, 0.5)),
        joint_shapes=((1.0, SHAPE2),),
        elements=(JointElement(CUBIC, K3),),
        couplings=(Coupling(1, (1, 1), 2 * KAPPA), Coupling(2, (2, 0), KAPPA)),
    )


def parameter_sets(model: ModalModel, n_sets: int) -> tuple[np.ndarray, list[str]]:
    names = [
        "mode1.frequency_hz",
        "mode2.frequency_hz",
        "mode1.damping_ratio",
        "mode2.damping_ratio",
        f"joint1.{CUBIC}",
        "coupling1",
        "coupling2",
    ]
    nominal = np.array([F1, F2, ZETA, ZETA, K3, 2 * KAPPA, KAPPA])
    rng = np.random.default_rng(0)
    return nominal * rng.uniform(0.9, 1.1, (n_sets, nominal.size)), names


def main() -> None:
    n_sets = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    model = two_mode()
    values, names = parameter_sets(model, n_sets)
    settings = HarmonicSettings(HARMONICS)
    one_mode = JointModel(
        {
            LINEAR_STIFFNESS: (2 * np.pi * F1) ** 2,
            VISCOUS_DAMPING: 2 * ZETA * 2 * np.pi * F1,
            CUBIC: K3,
        }
    )
    one_values = np.column_stack(
        [(2 * np.pi * values[:, 0]) ** 2, 2 * values[:, 2] * 2 * np.pi * values[:, 0], values[:, 4]]
    )
    one_names = [LINEAR_STIFFNESS, VISCOUS_DAMPING, CUBIC]
    one_modal = ModalModel.from_joint_model(one_mode)
    one_modal_names = ["mode1.frequency_hz", "mode1.damping_ratio", f"joint1.{CUBIC}"]
    one_modal_values = values[:, [0, 2, 4]]

    def run_pr():
        return phase_resonance(
            model, AMPLITUDES_M, settings=settings, parameters=values, names=names
        )

    def run_nm():
        return nonlinear_modes(
            model, AMPLITUDES_M, settings=settings, parameters=values, names=names
        )

    def run_one():
        return backbone(
            one_mode,
            AMPLITUDES_M,
            parameters=one_values,
            names=one_names,
            method="multi",
            harmonics=HARMONICS,
        )

    def run_one_modal():
        return phase_resonance(
            one_modal,
            AMPLITUDES_M,
            settings=settings,
            parameters=one_modal_values,
            names=one_modal_names,
        )

    # warm-up: numba kernels
    phase_resonance(model, AMPLITUDES_M[:2], settings=settings)
    backbone(one_mode, AMPLITUDES_M[:2], method="multi", harmonics=HARMONICS)
    pr_s, pr = median_time(run_pr, 1)
    nm_s, nm = median_time(run_nm, 1)
    one_s, one = median_time(run_one, 3)
    one_modal_s, one_modal_result = median_time(run_one_modal, 1)
    gap = np.nanmax(np.abs(one_modal_result.frequency_hz / one.frequency_hz - 1))
    share = float(np.nanmax(pr.energy_share[..., 1]))
    rows = [
        ("two modes, phase resonance", pr_s, pr.converged.mean()),
        ("two modes, nonlinear mode (EPMC)", nm_s, nm.converged.mean()),
        ("one mode, analytical.harmonic multi", one_s, one.converged.mean()),
        ("one mode, multimode phase resonance", one_modal_s, one_modal_result.converged.mean()),
    ]
    print(
        f"{n_sets} parameter sets × {AMPLITUDES_M.size} amplitudes, H = {HARMONICS}, "
        f"n_time = {pr.n_time}, one core, after a warm-up call"
    )
    print(f"{'case':40} {'time':>9} {'per set':>10} {'converged':>10}")
    for case, seconds, converged in rows:
        print(f"{case:40} {seconds:>8.2f}s {seconds / n_sets * 1e3:>8.2f}ms {converged:>10.4f}")
    print(
        f"one-mode paths agree to max |Δf/f| = {gap:.1e}; mode 2's largest energy share "
        f"on the two-mode backbones {share:.3g}"
    )
    print(
        json.dumps(
            {
                "n_sets": n_sets,
                "n_amplitudes": int(AMPLITUDES_M.size),
                "harmonics": HARMONICS,
                "n_time": pr.n_time,
                "two_mode_phase_resonance_s": round(pr_s, 3),
                "two_mode_phase_resonance_ms_per_set": round(pr_s / n_sets * 1e3, 3),
                "two_mode_phase_resonance_converged_fraction": float(pr.converged.mean()),
                "two_mode_epmc_s": round(nm_s, 3),
                "two_mode_epmc_ms_per_set": round(nm_s / n_sets * 1e3, 3),
                "two_mode_epmc_converged_fraction": float(nm.converged.mean()),
                "one_mode_harmonic_multi_s": round(one_s, 3),
                "one_mode_harmonic_multi_ms_per_set": round(one_s / n_sets * 1e3, 3),
                "one_mode_multimode_s": round(one_modal_s, 3),
                "one_mode_paths_max_rel_frequency_gap": float(gap),
                "two_mode_max_mode2_energy_share": share,
                "threads": 1,
            }
        )
    )


if __name__ == "__main__":
    main()
