"""Calibration of the criticism's swap step: how often it undoes a right addition, how
often it corrects a wrong one.

The swap step of the forward-backward loop
(:meth:`identification.criticism.criticism.Criticism.swap`) replaces an effect added
earlier when a replacement gains more than :data:`~identification.criticism.criticism.
SEPARATION` in ``χ²`` (admissible, no channel worse beyond its noise:
:data:`~identification.criticism.criticism.WORSE`), and removes it when removing it
costs less than the calibrated threshold. :func:`studies.swap_study` runs it
over lab-rig campaigns (the presets ``lab-hidden-<effect>`` with their mild lab
artefacts, records simulated and backbones extracted; 1/3/5/10 assemblies, 5–8 levels;
``--source "harmonic balance"``: the fast harmonic-balance campaigns of the null study,
the criticism's own model class, a unit-level check only) of nine truths, each the lab
base model plus one effect with a near-collinear rival in the catalogue:

* **false swaps**: the effect added is the truth's; any change kept is wrong. Target
  ≤ 5 % per decision (the false-discovery target), judged on the upper end of the
  two-sided 95 % Clopper–Pearson interval. Split into replacements (SEPARATION's
  decision) and removals (the threshold's), and given for the campaigns where round 1
  proposed the truth first (the addition the loop would have made).
* **false vetoes**: the truth's refit flagged "worse" in a channel — in round 1 (the add
  step, every campaign where the truth is refitted) and in the swap's trial of the truth
  (the power campaigns).
* **true swaps** (power): round 1's best proposed rival (else its best significant
  runner-up) is added instead of the truth; the swap corrects it when it puts the truth
  in its place; and whether round 1 flagged the two as one ambiguity group.
* the distribution of the best replacement's gain when the truth's structure is judged:
  the quantity SEPARATION bounds.

Each row records the end state (the model after the swap step, its verdict and
p-value). The study seed is held out by default (:mod:`studies.seeds`; the power side
runs on the next seed); the JSON line names the seeds and the source.

Run: ``.venv/bin/python bench/criticism_swap.py --campaigns 200`` (``--no-floors``:
systematic floors all but off; ``--side``: one side only; ``--from-rows``: analyse stored
rows). Prints the rows, the rates, the margin swept over the same trials (each trial's
gain and vetoes do not depend on it), then one JSON line.
"""

import argparse
import json
import os
import time
from collections import Counter

import numpy as np
from criticism import (
    NO_FLOOR,  # bench/criticism.py, beside this script
    campaign_arguments,
)
from criticism import _rate as _interval

from identification.criticism.criticism import SEPARATION, WORSE
from studies import (
    SWAP_TRUTHS,
    CampaignSource,
    SeedRange,
    SwapRow,
    rows_table,
    swap_study,
)

TARGET_RATE = 0.05
COLUMNS = (
    "campaign", "truth", "n_curves", "levels", "conditions", "proposed_first", "added",
    "best_replacement_gain", "decision", "add_worse", "swap_veto", "seconds",
)  # fmt: skip


def _rate(name: str, k: int, n: int) -> dict:
    """The count printed with its Clopper–Pearson interval (bench/criticism.py's), and the rate."""
    return _interval(name, k, n) | {"rate": k / n if n else None}


def _run(campaigns: int, seed: int, wrong_first: bool, source: str, options: dict) -> list[SwapRow]:
    def progress(row: SwapRow) -> None:
        print(rows_table([row], COLUMNS).splitlines()[-1], flush=True)

    rows = swap_study(campaigns, wrong_first=wrong_first, seed=seed, progress=progress,
                      source=CampaignSource(source), **options)  # fmt: skip
    print(rows_table(rows, COLUMNS))
    return rows


#: Margins (χ² gains) at which the sweep re-decides the stored replacement trials.
SWEEP_MARGINS = (0.0, 0.25, 0.5, 1.0, 2.0, 4.0, SEPARATION)


def _replacement(row: SwapRow, margin: float) -> str | None:
    """The replacement the swap step keeps at ``margin``: the best admissible trial, no
    channel worse, gaining more (each trial's gain and vetoes do not depend on it)."""
    ok = [t for t in row.trials if t.add and not t.why and t.delta_chi2 > margin]
    return max(ok, key=lambda t: t.delta_chi2).add if ok else None


def _sweep(right: list[SwapRow], wrong: list[SwapRow]) -> dict:
    """False replacements and true swaps had the margin been each of :data:`SWEEP_MARGINS`
    (removals are the calibrated threshold's and unchanged)."""
    print("\nthe margin swept over the same trials (false replacements | true swaps)")
    out = {}
    for margin in SWEEP_MARGINS:
        false = sum(_replacement(r, margin) is not None for r in right)
        true = sum(_replacement(r, margin) == r.truth for r in wrong)
        out[f"{margin:g}"] = {"false_replacements": false, "true_swaps": true}
        print(f"  {margin:>5g}: {false} of {len(right)} | {true} of {len(wrong)}")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaigns", type=int, default=200, help="campaigns per side")
    campaign_arguments(parser)
    parser.add_argument("--rows", type=str, help="write every row here (JSON lines)")
    parser.add_argument("--from-rows", type=str,
                        help="analyse the rows of an earlier run (with --no-floors for a "
                        "floors-off run's)")  # fmt: skip
    parser.add_argument("--side", choices=("both", "false", "power"), default="both",
                        help="run only the false-swap or the power campaigns")  # fmt: skip
    parser.add_argument("--no-floors", action="store_true",
                        help="systematic floors all but off: the margins against the "
                        "estimated covariance alone")  # fmt: skip
    args = parser.parse_args()
    options = {"noise_floor": NO_FLOOR} if args.no_floors else {}
    began = time.perf_counter()
    if args.from_rows:
        with open(args.from_rows) as stored:
            rows = [SwapRow.from_dict(json.loads(line)) for line in stored if line.strip()]
        right = [r for r in rows if not r.wrong_first]
        wrong = [r for r in rows if r.wrong_first]
    else:
        right = (
            _run(args.campaigns, args.seed, False, args.source, options)
            if args.side != "power"
            else []
        )
        wrong = (
            _run(args.campaigns, args.seed + 1, True, args.source, options)
            if args.side != "false"
            else []
        )
    total_s = time.perf_counter() - began
    if args.rows:
        with open(args.rows, "w") as out:
            for row in right + wrong:
                out.write(json.dumps(row.to_dict(), default=str) + "\n")

    print("\nfalse swaps (the truth's effect added; any change kept is wrong)")
    decided = [r for r in right if r.added is not None]
    first = [r for r in decided if r.proposed_first == r.truth]
    figures = {
        "false_swaps": _rate("  any change", sum(r.false_swap for r in decided), len(decided)),
        "false_replacements": _rate(
            "  replaced by another effect (SEPARATION)",
            sum(r.decision.startswith("replaced") for r in decided), len(decided),
        ),
        "false_removals": _rate(
            "  removed (calibrated threshold)",
            sum(r.decision == "removed" for r in decided), len(decided),
        ),
        "false_swaps_when_proposed_first": _rate(
            "  any change, campaigns where round 1 proposed the truth first",
            sum(r.false_swap for r in first), len(first),
        ),
    }  # fmt: skip
    by_truth = {}
    for truth in SWAP_TRUTHS:
        some = [r for r in decided if r.truth == truth]
        by_truth[truth] = _rate(f"    {truth}", sum(r.false_swap for r in some), len(some))
    by_count = {}
    for n in sorted({r.n_curves for r in decided}):
        some = [r for r in decided if r.n_curves == n]
        by_count[n] = _rate(f"    {n} curves", sum(r.false_swap for r in some), len(some))
    gains = np.array([r.best_replacement_gain for r in decided
                      if r.best_replacement_gain is not None])  # fmt: skip
    figures["best_replacement_gain_chi2"] = (
        {
            "campaigns": int(gains.size),
            "q50": float(np.quantile(gains, 0.5)),
            "q95": float(np.quantile(gains, 0.95)),
            "q99": float(np.quantile(gains, 0.99)),
            "max": float(gains.max()),
            "above_separation": int(np.sum(gains > SEPARATION)),
        }
        if gains.size
        else None
    )
    print(
        f"  best replacement gain under the truth's structure: {
            figures['best_replacement_gain_chi2']
        } (SEPARATION = {SEPARATION})"
    )

    print("\nfalse vetoes (the truth's refit flagged 'worse' beyond its noise)")
    refitted = [r for r in right + wrong if r.add_worse is not None]
    figures["add_step_false_vetoes"] = _rate(
        "  add step (round 1, truth refitted)", sum(bool(r.add_worse) for r in refitted),
        len(refitted),
    )  # fmt: skip
    tried = [r for r in wrong if r.swap_veto is not None]
    figures["swap_step_false_vetoes"] = _rate(
        "  swap step (trial of the truth in place of a wrong first addition)",
        sum(r.swap_veto for r in tried), len(tried),
    )  # fmt: skip

    print("\ntrue swaps (round 1's runner-up added instead of the truth)")
    wrong_decided = [r for r in wrong if r.added is not None]
    figures["true_swaps"] = _rate(
        "  truth put in place of the wrong effect", sum(r.corrected for r in wrong_decided),
        len(wrong_decided),
    )  # fmt: skip
    offered = [r for r in wrong_decided if r.truth in r.alternatives]
    figures["true_swaps_truth_offered"] = _rate(
        "  the same, campaigns where the truth is among the alternatives",
        sum(r.corrected for r in offered), len(offered),
    )  # fmt: skip
    separated = [r for r in offered if any(t.add == r.truth and t.delta_chi2 > SEPARATION
                                          for t in r.trials)]  # fmt: skip
    figures["true_swaps_truth_separated"] = _rate(
        f"  the same, campaigns where the truth gains more than SEPARATION = {SEPARATION}",
        sum(r.corrected for r in separated), len(separated),
    )  # fmt: skip
    proposable = [r for r in wrong_decided if r.added_was_proposed]
    figures["true_swaps_added_was_proposed"] = _rate(
        "  the same, campaigns where round 1 proposed the wrong effect (the loop's mistake)",
        sum(r.corrected for r in proposable), len(proposable),
    )  # fmt: skip
    grouped = [r for r in wrong_decided if not r.corrected and r.groups is not None]
    figures["uncorrected_truth_grouped_with_added"] = _rate(
        "  of those not corrected, round 1 flagged the truth and the effect added as one group",
        sum(any({r.truth, r.added} <= set(g) for g in r.groups) for r in grouped),
        len(grouped),
    )  # fmt: skip
    mistakes = [r for r in grouped if r.added_was_proposed]
    figures["uncorrected_mistakes_grouped_with_truth"] = _rate(
        "  of the loop's mistakes not corrected, flagged as one group with the truth",
        sum(any({r.truth, r.added} <= set(g) for g in r.groups) for r in mistakes),
        len(mistakes),
    )  # fmt: skip
    power_by_pair = Counter((r.truth, r.added, r.decision) for r in wrong_decided)
    for (truth, added, decision), n in sorted(power_by_pair.items()):
        print(f"    truth {truth}, added {added}: {decision} × {n}")
    figures["margin_sweep_chi2"] = _sweep(decided, wrong_decided)
    if not args.from_rows:
        print(f"{len(right) + len(wrong)} campaigns in {total_s:.0f} s; load {os.getloadavg()}")
    print(json.dumps({
        "benchmark": "criticism_swap_calibration",
        "campaigns_per_side": max(len(right), len(wrong)),
        "seed": args.seed,
        "seeds": SeedRange(args.seed, 2).to_dict(),
        "source": (right + wrong)[0].source if right + wrong else None,
        "from_rows": args.from_rows,
        "systematic_floors": not args.no_floors,
        "truths": list(SWAP_TRUTHS),
        "separation_chi2": SEPARATION,
        "worse_chi2": WORSE,
        **figures,
        "false_swaps_by_truth": by_truth,
        "false_swaps_by_curve_count": by_count,
        "target_false_swap_rate_max": TARGET_RATE,
        "meets_target": figures["false_swaps"]["ci95_high"] <= TARGET_RATE,
        "total_s": None if args.from_rows else round(total_s, 1),
        "load_average": os.getloadavg(),
    }, default=str))  # fmt: skip


if __name__ == "__main__":
    main()
