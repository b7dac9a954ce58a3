"""The arch through the criticism loop: a start holding a stand-in for the truth's term.

The truth is the lab preset ``lab-hidden-quadratic-stiffness``'s model (linear, viscous,
x² and x³); the start holds ẋ² in x²'s place, its coefficients fitted to the campaign (as
SINDy's polynomial start does on the rig). Campaigns: ``studies.simulated_campaign``, 3
assemblies, 8 levels (the harmonic balance, a unit-level check like
``tests/test_criticism_terms.py``'s fixture, of which this is the seed sweep). Per seed:
round 1's calibrated decision (p-value, catalogue and reference gains against their
thresholds), what it proposes first, the ẋ² group's separations, and the loop's end (3
rounds): its final model, verdict and x² coefficient, and the changes it kept.

Outcome rule, fixed before the held-out rows ran: a row is **right** when the loop ends on
the truth's structure (x² in, ẋ² out, nothing else added) with x² within 30 % of the
truth's coefficient. Seeds below ``HELD_OUT_SEED`` are tuning seeds.

Run: ``.venv/bin/python bench/criticism_arch.py --first-seed 3000000 --campaigns 6``.
Prints one JSON row per seed, then one JSON summary line; writes
``bench/results/criticism_arch_<first seed>.json``.
"""

import argparse
import json
import os
import time

from identification.criticism.criticism import criticize
from identification.criticism.moves import run_rounds
from identification.effects import quadratic_stiffness, velocity_squared
from identification.fitting.least_squares import fit_backbones
from identification.rig import RIG_PRESETS
from studies import HELD_OUT_SEED, simulated_campaign

X2, V2 = quadratic_stiffness.EFFECT.name, velocity_squared.EFFECT.name
RESULTS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "results")


def arch_row(seed: int) -> dict:
    """One campaign of the arch: round 1's decision and the loop's end."""
    began = time.perf_counter()
    truth = RIG_PRESETS["lab-hidden-quadratic-stiffness"].model
    measured = simulated_campaign(truth, 3, seed=seed, levels=8)
    start = fit_backbones(truth.without(X2).with_effect(V2, 0.0), measured).model
    crit = criticize(start, measured)
    decision, calibration = crit.decision, crit.calibration
    chain = run_rounds(crit, 3)
    last = chain[-1].base.model
    right = set(last.effects) == set(truth.effects) and (
        abs(last.coefficient(X2) / truth.coefficient(X2) - 1) <= 0.3
    )
    return {
        "seed": seed,
        "seed_kind": "held-out" if seed >= HELD_OUT_SEED else "tuning",
        "p_value": crit.p_value,
        "fires": bool(crit.significant),
        "catalogue": [float(decision.observed.catalogue[0]), calibration.catalogue_threshold],
        "reference": [float(decision.observed.reference[0]), calibration.reference_threshold],
        "verdict": str(crit.verdict),
        "first": [c.effect for c in crit.missing()][:1],
        "group": {g.term: g.separation for g in crit.term_groups if g.term == V2},
        "final": list(last.effects),
        "final_verdict": str(chain[-1].verdict),
        "final_x2": last.coefficient(X2) if X2 in last else None,
        "kept": [t.to_dict() for c in chain for t in c.swaps if t.kept],
        "right": right,
        "seconds": time.perf_counter() - began,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--first-seed", type=int, default=HELD_OUT_SEED)
    parser.add_argument("--campaigns", type=int, default=6)
    args = parser.parse_args()
    rows = []
    for seed in range(args.first_seed, args.first_seed + args.campaigns):
        rows.append(arch_row(seed))
        print(json.dumps(rows[-1]), flush=True)
    summary = {
        "benchmark": "criticism_arch",
        "first_seed": args.first_seed,
        "campaigns": len(rows),
        "round1_fires": sum(r["fires"] for r in rows),
        "first_is_x2": sum(r["first"] == [X2] for r in rows),
        "right": sum(r["right"] for r in rows),
        "target": "every row right",
    }
    os.makedirs(RESULTS, exist_ok=True)
    with open(os.path.join(RESULTS, f"criticism_arch_{args.first_seed}.json"), "w") as out:
        json.dump({**summary, "rows": rows}, out, indent=1)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
