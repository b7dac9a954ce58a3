"""The loop's end on lab-rig campaigns: where the stepwise loop stops, on what, and why.

``--tune`` runs the loop with no share threshold and records every step (the share of the
gain left each addition captured, the verdict, p-value and admissibility of each model
kept), then replays the loop at each threshold of a grid: a loop with threshold T is the
same loop cut at its first addition below T. On tuning seeds (``0 … 999_999``) the threshold
is chosen by the rule written in docs/criticism.md ("The loop's end") before the run; on
held-out seeds the rows are read at the chosen threshold only after it was fixed.

Without ``--tune`` (held-out seeds only) it runs the loop as the library does
(:data:`~identification.criticism.config.STOP_SHARE`) and reports per row the final model,
the final verdict and p-value, whether the final model is admissible, the smallest share a
final term explained when it was added, and the stop.

    nice -n 10 python bench/criticism_loop.py --tune --seeds 1 --scenarios lab-iwan,...
    nice -n 10 python bench/criticism_loop.py --tune --first-seed 2000000 --seeds 1 ...

Scenarios ``independent-<joint>`` (``independent-iwan``, ``-clearance``, ``-contact``,
``-power-law-damping``) take their campaigns from the independent simulator
(:data:`independent.campaigns.OUT_OF_CATALOGUE_JOINTS`: its own harmonic balance and forces,
3 assemblies at its 10 default levels, its default scatter and hold noise), started from
the linear pair fitted to the backbones' frequency and damping, as the lab rows are.

Ends with one JSON line; writes ``bench/results/criticism_loop[_independent][_tune]
[_heldout].json``, or ``ROWS.summary.json`` beside a ``--rows`` file.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from identification.criticism.config import LINEAR_PAIR, STOP_SHARE
from identification.criticism.criticism import Criticism, criticize
from identification.criticism.ending import problems_of
from identification.criticism.moves import run_rounds
from identification.rig.presets import (
    LAB_HIDDEN_SCENARIOS,
    LAB_OUT_OF_CATALOGUE_SCENARIOS,
    RIG_PRESETS,
)
from independent.campaigns import OUT_OF_CATALOGUE_JOINTS
from studies.campaigns import independent_out_of_catalogue
from studies.hidden_effects import criticism_study

#: Thresholds the tuning replays (a proposed candidate captures at least PARTLY = 0.5).
GRID = (0.5, 0.6, 0.7, 0.8, 0.9)
#: First held-out seed (studies/seeds.py's HELD_OUT_SEED, defined here until it is on main).
HELD_OUT_SEED = 1_000_000
RESULTS = Path(__file__).parent / "results"


#: Scenario names of the independent simulator's out-of-catalogue joints.
INDEPENDENT = {f"independent-{name}": name for name in OUT_OF_CATALOGUE_JOINTS}


def _start(scenario: str, seed: int) -> Criticism:
    """The first criticism of ``scenario``'s campaign at ``seed``, from the linear start."""
    if scenario not in INDEPENDENT:
        return criticism_study(scenario, seed, start="linear", rounds=0).criticisms[0]
    measured, start = independent_out_of_catalogue(INDEPENDENT[scenario], seed)
    return criticize(start, measured)


def run(scenario: str, seed: int, rounds: int, min_share: float) -> dict:
    """One campaign through the loop from the linear start: every kept model's state."""
    began = time.perf_counter()
    chain = run_rounds(_start(scenario, seed), rounds, min_share=min_share)
    steps = []
    for k, crit in enumerate(chain):
        action = crit.history[-1].action
        share = None
        if k and action.startswith("+ "):
            best = chain[k - 1].missing()[0]
            share = 1.0 if best.share is None else best.share
        steps.append(
            {
                "action": action,
                "effects": list(crit.base.model.effects),
                "equation": crit.base.model.equation(),
                "share_in": share,
                "verdict": str(crit.verdict),
                "p_value": float(crit.p_value),
                "fires": dict(crit.fires),
                "problems": list(problems_of(crit)),
            }
        )
    end = chain[-1].loop_end
    outside = scenario in LAB_OUT_OF_CATALOGUE_SCENARIOS or scenario in INDEPENDENT
    # an independent joint's catalogue part is the linear pair
    preset = RIG_PRESETS.get(scenario)
    return {
        "scenario": scenario,
        "seed": seed,
        "kind": "out of catalogue" if outside else "hidden",
        "truth": list(preset.model.effects) if preset else list(LINEAR_PAIR),
        "hidden": list(preset.hidden_effects) if preset else [],
        "steps": steps,
        "loop_end": end.to_dict(),
        "seconds": time.perf_counter() - began,
    }


def replay(row: dict, threshold: float) -> dict:
    """The row's loop at ``threshold``: cut at its first addition below it."""
    steps = row["steps"]
    k = next(
        (i for i, s in enumerate(steps) if s["share_in"] is not None and s["share_in"] < threshold),
        len(steps),
    )
    final = steps[k - 1]
    shares = [s["share_in"] for s in steps[1:k] if s["share_in"] is not None]
    truth, effects = set(row["truth"]), set(final["effects"])
    extra = sorted(effects - truth)
    outcome = "exact" if effects == truth else "extra" if truth <= effects else "short"
    return {
        "added": [e for e in final["effects"] if e not in LINEAR_PAIR],
        "beyond_truth": extra,
        "verdict": final["verdict"],
        "p_value": final["p_value"],
        "admissible": not final["problems"],
        "smallest_share": min(shares) if shares else None,
        "outcome": outcome,
        "consistent": _consistent(final),
    }


def _consistent(step: dict) -> bool:
    """A step's verdict agrees with its calibrated test: where the test fires, never
    "nothing missing" (or "drift")."""
    fires = step["fires"]["catalogue"] or step["fires"]["reference"]
    return not (fires and step["verdict"] in ("nothing missing", "drift"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tune", action="store_true", help="no threshold; replay the grid")
    parser.add_argument("--scenarios", help="comma-separated (default: lab hidden + out of cat.)")
    parser.add_argument("--seeds", type=int, default=1, help="seeds per scenario")
    parser.add_argument("--first-seed", type=int, default=0, help="first seed")
    parser.add_argument("--rounds", type=int, default=3, help="most effects added")
    parser.add_argument(
        "--rows", type=Path, help="append rows here (JSON lines), reuse them; FILE.summary.json"
    )
    args = parser.parse_args()
    if not args.tune and args.first_seed < HELD_OUT_SEED:
        parser.error(f"a reported figure comes from held-out seeds (≥ {HELD_OUT_SEED})")
    scenarios = (
        args.scenarios.split(",")
        if args.scenarios
        else [*LAB_HIDDEN_SCENARIOS, *LAB_OUT_OF_CATALOGUE_SCENARIOS]
    )
    done = {}
    if args.rows and args.rows.exists():
        for line in args.rows.read_text().splitlines():
            r = json.loads(line)
            done[(r["scenario"], r["seed"])] = r
    rows = []
    min_share = 0.0 if args.tune else STOP_SHARE
    for scenario in scenarios:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            row = done.get((scenario, seed)) or run(scenario, seed, args.rounds, min_share)
            if args.rows and (scenario, seed) not in done:
                with args.rows.open("a") as out:
                    out.write(json.dumps(row) + "\n")
            rows.append(row)
            end = row["loop_end"]
            print(
                f"{scenario:34s} {seed:8d}  {end['stop']:30s} {end['verdict']:32s} "
                f"p={end['p_value']:.3g} admissible={end['admissible']} smallest share="
                f"{end['smallest_share']} | {end['equation']}",
                flush=True,
            )
    out = {"benchmark": "criticism_loop", "tune": args.tune, "rows": rows}
    if args.tune:
        out["grid"] = {}
        for t in GRID:
            replays = [(r, replay(r, t)) for r in rows]
            for r, p in replays:
                r.setdefault("replays", {})[t] = p
            hidden = [p for r, p in replays if r["kind"] == "hidden"]
            outside = [p for r, p in replays if r["kind"] != "hidden"]
            out["grid"][t] = figures = {
                "hidden_exact": sum(p["outcome"] == "exact" for p in hidden),
                "hidden_extra": sum(p["outcome"] == "extra" for p in hidden),
                "hidden_short": sum(p["outcome"] == "short" for p in hidden),
                "hidden_rows": len(hidden),
                "outside_stacked": sum(len(p["beyond_truth"]) >= 2 for p in outside),
                "outside_rows": len(outside),
                "inadmissible": sum(not p["admissible"] for _, p in replays),
                "inconsistent": sum(not p["consistent"] for _, p in replays),
            }
            print(f"threshold {t}: {figures}")
    else:
        ends = [r["loop_end"] for r in rows]
        out |= {
            "seeds": [args.first_seed, args.first_seed + args.seeds - 1],
            "min_share": STOP_SHARE,
            "admissible": sum(e["admissible"] for e in ends),
            "consistent": sum(_consistent(r["steps"][-1]) for r in rows),
            "below_share": sum(
                e["smallest_share"] is not None and e["smallest_share"] < STOP_SHARE for e in ends
            ),
            "runs": len(ends),
        }
    independent = all(s in INDEPENDENT for s in scenarios)
    name = "criticism_loop" + ("_independent" if independent else "")
    name += "_tune" if args.tune else ""
    name += "_heldout" if args.first_seed >= HELD_OUT_SEED else ""
    # A rows file of one's own gets its summary beside it (a block's run would otherwise
    # overwrite another block's).
    where = args.rows.with_suffix(".summary.json") if args.rows else RESULTS / f"{name}.json"
    where.write_text(json.dumps(out, indent=1, default=str))
    print(json.dumps({k: v for k, v in out.items() if k != "rows"}, default=str))


if __name__ == "__main__":
    main()
