"""The criticism's rule with and without a level-by-level gate: power on a small trend over
many levels, and the rate on null campaigns.

Campaigns are drawn here from the closed form of a linear joint's backbone (constant
frequency and damping ratio) with per-point scatter, 8 curves at 20 levels over one octave
(1–2 mm), systematic floors off (the bootstrap alone calibrates), the whole catalogue
tried. The alternative adds a cubic stiffness's frequency shift (∝ a²) whose ``χ²`` beyond
what a linear stiffness absorbs is ``--gain`` in expectation (about one standard error at
each level for a gain of 20). Each campaign is criticised once; the rule is read two ways:

* **calibrated** (the rule): the catalogue or the free-form test fires
  (``Criticism.significant``);
* **gated** (the rule before #25): the same and ``where()`` finds a level beyond its bound.

Outcome rules fixed before the run: a campaign is a finding when the rule fires; "small"
when it fires and ``where()`` is empty; the verdict is never "nothing missing" where the
rule fires. Seeds from ``--seed`` (held out: 1 000 000 up, ``COMMON`` convention).

Run: ``nice .venv/bin/python bench/criticism_rule.py --campaigns 20``. Prints one line per
campaign, then one JSON line, and writes ``bench/results/criticism_rule.json``.
"""

import argparse
import json
import os
import time

import numpy as np

from identification.criticism.config import Verdict
from identification.criticism.criticism import criticize
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from studies import clopper_pearson

HELD_OUT_SEED = 1_000_000
W0 = 2 * np.pi * 101.0
LINEAR = JointModel({"linear_stiffness": W0**2, "viscous_damping": 2 * 0.003 * W0})
LEVELS_M = 1e-3 * np.geomspace(1.0, 2.0, 20)
FREQUENCY_SD_HZ, DAMPING_SD, N_CURVES = 0.003, 3e-5, 8
NO_FLOOR = {"frequency_hz": 1e-6, "damping_ratio": 1e-9, "harmonics": 1e-7}


def campaign(gain: float, seed: int) -> BackboneSet:
    """8 curves of the linear joint, scattered, with the trend of ``χ²`` ``gain``."""
    rng = np.random.default_rng(seed)
    a2 = LEVELS_M**2
    se = FREQUENCY_SD_HZ / np.sqrt(N_CURVES)
    bias = np.sqrt(gain) * se * a2 / np.linalg.norm(a2 - a2.mean())
    return BackboneSet(
        [
            Backbone(
                LEVELS_M,
                101.0 + bias + FREQUENCY_SD_HZ * rng.standard_normal(LEVELS_M.size),
                0.003 + DAMPING_SD * rng.standard_normal(LEVELS_M.size),
                label=f"c{i}",
            )
            for i in range(N_CURVES)
        ]
    )


def _count(name: str, k: int, n: int) -> dict:
    low, high = clopper_pearson(k, n)
    print(f"{name}: {k} of {n} (95 % interval {low:.3f}–{high:.3f})")
    return {"k": k, "n": n, "rate": k / n, "interval95": [low, high]}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--campaigns", type=int, default=20)
    parser.add_argument("--gain", type=float, default=20.0)
    parser.add_argument("--seed", type=int, default=HELD_OUT_SEED)
    parser.add_argument("--n-bootstrap", type=int, default=1000)
    args = parser.parse_args()
    start = time.perf_counter()
    figures: dict = {"seeds": [args.seed, args.seed + 2 * args.campaigns - 1]}
    for gain in (0.0, args.gain):
        rows = []
        for i in range(args.campaigns):
            seed = args.seed + i + (args.campaigns if gain else 0)
            crit = criticize(LINEAR, campaign(gain, seed), noise_floor=NO_FLOOR,
                             n_bootstrap=args.n_bootstrap, seed=seed)  # fmt: skip
            row = {
                "seed": seed, "calibrated": crit.significant,
                "gated": crit.significant and bool(crit.where()), "small": crit.small,
                "verdict": str(crit.verdict), "p_value": crit.p_value,
                "catalogue_gain": float(crit.observed.catalogue[0]),
                "threshold": crit.threshold,
            }  # fmt: skip
            print(json.dumps(row))
            rows.append(row)
        quiet = [r["verdict"] in (Verdict.NOTHING_MISSING, Verdict.DRIFT) for r in rows]
        key = "null" if gain == 0 else f"gain_{gain:g}"
        figures[key] = {
            "calibrated": _count(
                f"{key} calibrated", sum(r["calibrated"] for r in rows), len(rows)
            ),
            "gated": _count(f"{key} gated", sum(r["gated"] for r in rows), len(rows)),
            "small": sum(r["small"] for r in rows),
            "quiet_where_fired": sum(
                q and r["calibrated"] for q, r in zip(quiet, rows, strict=True)
            ),
            "median_p": float(np.median([r["p_value"] for r in rows])),
        }
    figures["seconds"] = time.perf_counter() - start
    os.makedirs("bench/results", exist_ok=True)
    with open("bench/results/criticism_rule.json", "w") as handle:
        json.dump(figures, handle, indent=2)
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
