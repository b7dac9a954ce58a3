"""Two-mode against one-mode models: prediction error on held-out two-mode decays (issue 27).

Two cases, each identified on tuning-seed decays and predicted on held-out ones
(``--held-out-seed`` …, default ``HELD_OUT_SEED``), every step through the ``pm-joint`` command:

* **independent**: ring-downs of :mod:`studies.modal_identification`'s truth (two modes
  at 100 and 201 Hz, a ``κ q₁² q₂`` coupling, quadratic damping at a joint
  ``q = q₁ + 0.5 q₂``), from :mod:`independent.decays` (no code shared with the library),
  four displacement sensors; identification seeds ``0 … n−1``.
* **rig**: ``pm-joint rig --preset two-mode --test free-decay`` (bending and torsion near
  1:2, a microslip and hardening joint, the quadratic coupling, every lab artefact, 15
  velocity sensors): identification campaign ``--seed 0``, held-out campaign ``--seed``
  the held-out seed (the block ``1_000_000`` was seen while the damping selection was
  revised, ``2_000_000`` while the rig's limit was diagnosed, so the reported figures come
  from ``--held-out-seed 7000000 --held-out-assemblies 9``).

Each case: ``pm-joint identify --modes 2`` and ``pm-joint identify`` (today's one-mode
model) with the default library, then ``pm-joint predict`` of every held-out record with
both models. Printed per case: every record's NMTE (the ``NMTE x.xx %`` line's figure,
from ``FILE.json``), the means and their ratio. Target (fixed before the run, the issue's
acceptance): ratio ≤ 0.5. Anchor: SSMLearn's 3.65 % NMTE on held-out decays of a measured
1:2 jointed double beam.

The rig's floor: every assembly of a rig campaign draws its own modes (the preset's
``variability``: lognormal, σ 0.25 % on the frequencies, 5 % on the damping), and a decay
predicted by a model of the population's mean drifts in phase from a held-out assembly's
by its frequency offset. So the rig case also predicts every held-out record with the
preset's nominal truth (its exact physics without the assembly's draw, what a model
identified from other assemblies can at best be on average): ``nominal_truth_nmte_percent``
and ``floor_ratio`` (its mean NMTE over the one-mode model's), the ratio an identification
from other assemblies is not expected to beat on that block.

Run: ``nice -n 10 .venv/bin/python bench/identify_modes.py [--work DIR] [--held-out-seed S]
[--held-out-assemblies K]``
(campaigns in DIR are reused). Writes ``bench/results/identify_modes.json``; ends with one
JSON line.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import time
from pathlib import Path

import numpy as np

from identification.rig.presets import MODAL_RIG_PRESETS
from pm_joint.cli import main
from studies import modal_identification as case
from studies.seeds import HELD_OUT_SEED

RESULTS = Path(__file__).parent / "results"
SSMLEARN_NMTE_PERCENT = 3.65


def _run(argv: list[str]) -> None:
    """One ``pm-joint`` command; its printed lines are kept quiet, a failure raised."""
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(argv)
    if code not in (0, None):
        raise RuntimeError(f"pm-joint {' '.join(argv)} exited with {code}")


def _predict(model: Path, record: Path, options: list[str], out: Path) -> float:
    _run(["predict", "--model", str(model), str(record), *options, "--out", str(out)])
    return json.loads(Path(f"{out}.json").read_text())["nmte_percent"]


def _case(name: str, train: Path, held_out: list[Path], options: list[str], work: Path,
          n_train: int = 3):  # fmt: skip
    two, one = work / f"{name}_two.json", work / f"{name}_one.json"
    started = time.perf_counter()
    identify = ["identify", str(train), *options, "--records", str(n_train)]
    _run([*identify, "--modes", "2", "--out", str(two)])
    _run([*identify, "--out", str(one)])
    two_nmte = [_predict(two, r, options, work / f"{name}_two_{r.name}.csv") for r in held_out]
    one_nmte = [_predict(one, r, options, work / f"{name}_one_{r.name}.csv") for r in held_out]
    ratio = float(np.mean(two_nmte) / np.mean(one_nmte))
    print(f"{name}: two-mode NMTE {np.round(two_nmte, 2).tolist()} %, one-mode "
          f"{np.round(one_nmte, 2).tolist()} %, ratio {ratio:.3f}")  # fmt: skip
    return {
        "two_mode_nmte_percent": two_nmte,
        "one_mode_nmte_percent": one_nmte,
        "mean_two_mode_nmte_percent": float(np.mean(two_nmte)),
        "mean_one_mode_nmte_percent": float(np.mean(one_nmte)),
        "ratio": ratio,
        "meets_target": ratio <= case.RATIO_TARGET,
        "seconds": time.perf_counter() - started,
    }


def _floor(held_out: list[Path], options: list[str], work: Path, one_mode: list[float]) -> dict:
    """The rig preset's nominal truth predicted on the held-out records (module notes)."""
    nominal = MODAL_RIG_PRESETS["two-mode"].model(None).to_json(work / "rig_nominal_truth.json")
    nmte = [_predict(nominal, r, options, work / f"rig_nominal_{r.name}.csv") for r in held_out]
    floor = float(np.mean(nmte) / np.mean(one_mode))
    print(f"rig: nominal truth NMTE {np.round(nmte, 2).tolist()} %, floor ratio {floor:.3f}")
    return {"nominal_truth_nmte_percent": nmte,
            "mean_nominal_truth_nmte_percent": float(np.mean(nmte)),
            "floor_ratio": floor}  # fmt: skip


def _independent(work: Path, n_train: int, n_held_out: int, held_out_seed: int) -> dict:
    folder = work / "independent_train"
    folder.mkdir(parents=True, exist_ok=True)
    case.decay_records(range(n_train), folder)
    held = work / f"independent_held_out_{held_out_seed}"
    held.mkdir(exist_ok=True)
    records = case.decay_records(range(held_out_seed, held_out_seed + n_held_out), held)
    shapes = work / "independent_shapes.txt"
    shapes.write_text(case.MODE_SHAPES.to_text())
    options = ["--test", "free-decay", "--response", ",".join(case.SENSORS), "--quantity",
               "displacement", "--mode-shapes", str(shapes)]  # fmt: skip
    # identify reads the folder of column files as a campaign, the training decays all of it.
    return _case("independent", folder, [Path(r.path) for r in records], options, work, n_train)


def _rig(work: Path, assemblies: int, held_out_seed: int, held_out_assemblies: int) -> dict:
    campaigns = {}
    held_label = f"rig_held_out_{held_out_seed}_{held_out_assemblies}"
    for label, seed, size in (("rig_train", 0, assemblies),
                              (held_label, held_out_seed, held_out_assemblies)):  # fmt: skip
        folder = work / label
        if not (folder / "ground_truth.json").is_file():
            _run(["rig", "--preset", "two-mode", "--test", "free-decay", "--out", str(folder),
                  "--assemblies", str(size), "--seed", str(seed)])  # fmt: skip
        campaigns[label] = folder
    held_out = sorted(p for p in campaigns[held_label].glob("*_Assemb*") if p.is_file())
    options = ["--test", "free-decay"]
    figures = _case("rig", campaigns["rig_train"], held_out, options, work, assemblies)
    return {**figures, **_floor(held_out, options, work, figures["one_mode_nmte_percent"])}


def main_bench() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--work", type=Path, default=Path("bench_identify_modes"))
    parser.add_argument("--train", type=int, default=3, help="independent training decays")
    parser.add_argument("--held-out", type=int, default=5, help="independent held-out decays")
    parser.add_argument("--assemblies", type=int, default=3, help="rig training assemblies")
    parser.add_argument("--held-out-assemblies", type=int, default=3,
                        help="rig held-out assemblies (one campaign, --held-out-seed)")  # fmt: skip
    parser.add_argument("--cases", default="independent,rig")
    parser.add_argument(
        "--held-out-seed",
        type=int,
        default=HELD_OUT_SEED,
        help="first held-out seed (a fresh block, 2_000_000 …, once one was seen)",
    )
    args = parser.parse_args()
    args.work.mkdir(parents=True, exist_ok=True)
    figures: dict = {"target_ratio": case.RATIO_TARGET,
                     "anchor_ssmlearn_nmte_percent": SSMLEARN_NMTE_PERCENT,
                     "held_out_seed": args.held_out_seed,
                     "held_out_assemblies": args.held_out_assemblies}  # fmt: skip
    cases = args.cases.split(",")
    if "independent" in cases:
        figures["independent"] = _independent(
            args.work, args.train, args.held_out, args.held_out_seed
        )
    if "rig" in cases:
        figures["rig"] = _rig(
            args.work, args.assemblies, args.held_out_seed, args.held_out_assemblies
        )
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "identify_modes.json").write_text(json.dumps(figures, indent=2) + "\n")
    print(json.dumps(figures))


if __name__ == "__main__":
    main_bench()
