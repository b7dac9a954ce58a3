"""Calibration of the criticism's model-term groups: how often a term of the model is
grouped with a catalogue effect the data can tell it from.

A model-term group (:attr:`identification.criticism.criticism.Criticism.term_groups`)
says that a term the data need could be a catalogue effect the model lacks: that effect,
refitted in the term's place, fits no worse than
:data:`~identification.criticism.criticism.SEPARATION` below the model, is admissible and
makes no channel worse beyond its noise. :func:`studies.term_group_study` runs it
over lab-rig campaigns (the presets ``lab-hidden-<effect>`` with their mild lab
artefacts, records simulated and backbones extracted; 1/3/5/10 assemblies, 5–8 levels;
``--source "harmonic balance"``: the null study's fast harmonic-balance campaigns, the
criticism's own model class, a unit-level check only) of eleven truths, each the lab base
model plus one effect with near-collinear catalogue rivals, criticised with the truth's
own structure.

Every trial (a term of the truth, a stand-in the prescreen picked) gets its separation at
the design, ``λ``: the stand-in refitted to the noise-free truth in the campaign's own
metric (the noncentrality of the trial's ``Δχ²``). A trial with ``λ`` ≥ SEPARATION is one
the data can tell apart (in expectation the stand-in fits worse by more than the bound);
grouping it is a **false flag**. Printed with two-sided 95 % Clopper–Pearson intervals, by
``λ`` band, beside what a one-degree-of-freedom noncentral ``χ²`` of that ``λ`` predicts
for the ``Δχ²`` rule alone (before admissibility and the channel veto); the groups flagged
where ``λ`` < SEPARATION (the statement is then right); the group sizes; and the verdicts
of the campaigns (each a null campaign for its truth's structure: groups do not alter
them, nothing may be proposed).

Each trial's category is :class:`studies.TermTrialOutcome` (fixed in ``docs/studies.md``).
The study seed is held out by default (:mod:`studies.seeds`); the JSON line names it and
the source.

Run: ``.venv/bin/python bench/criticism_terms.py --campaigns 44``. Prints the trials,
the rates, then one JSON line.
"""

import argparse
import json
import os
import time
from collections import Counter

import numpy as np
from criticism import (
    _rate,  # bench/criticism.py, beside this script
    campaign_arguments,
)
from scipy.stats import ncx2

from identification.criticism.criticism import SEPARATION
from studies import (
    TERM_TRUTHS,
    CampaignSource,
    SeedRange,
    TermGroupRow,
    TermTrial,
    TermTrialOutcome,
    rows_table,
    term_group_study,
)

COLUMNS = ("campaign", "truth", "n_curves", "term", "effect", "delta_chi2", "lambda", "standing",
           "why")  # fmt: skip
#: Bands of the design's separation λ (in units of SEPARATION) the false flags are given in.
BANDS = ((1, 2), (2, 4), (4, np.inf))


def _trials(rows: list[TermGroupRow]) -> list[tuple[TermGroupRow, TermTrial]]:
    """Every stand-in trial of every campaign, beside its campaign's row."""
    return [(r, t) for r in rows for t in r.trials if t.effect is not None]


def _table(trials: list[tuple[TermGroupRow, TermTrial]]) -> str:
    """The trials as a table, each with its campaign's fields."""
    rows = [
        {"campaign": r.campaign, "truth": r.truth, "n_curves": r.n_curves, **t.to_dict()}
        for r, t in trials
    ]
    return rows_table(rows, COLUMNS)


def _predicted(trials: list[TermTrial]) -> float:
    """Mean probability that the ``Δχ²`` rule alone groups a trial of separation λ: a
    noncentral χ²₁(λ) below SEPARATION."""
    if not trials:
        return 0.0
    return float(np.mean([ncx2.cdf(SEPARATION, 1, t.design_lambda) for t in trials]))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaigns", type=int, default=44, help="campaigns")
    campaign_arguments(parser)
    parser.add_argument("--rows", type=str, help="write every row here (JSON lines)")
    args = parser.parse_args()
    began = time.perf_counter()

    def progress(row: TermGroupRow) -> None:
        trials = _trials([row])
        groups = [list(g) for g in row.term_groups]
        line = f"campaign {row.campaign} {row.truth} ({row.n_curves} curves): "
        line += f"{row.verdict}, {len(trials)} trials, groups {groups}, "
        print(line + f"{row.seconds:.1f} s", flush=True)

    rows = term_group_study(
        args.campaigns, seed=args.seed, progress=progress, source=CampaignSource(args.source)
    )
    total_s = time.perf_counter() - began
    if args.rows:
        with open(args.rows, "w") as out:
            for row in rows:
                out.write(json.dumps(row.to_dict(), default=str) + "\n")
    print(_table(_trials(rows)))
    trials = [t for _, t in _trials(rows)]
    separable = [t for t in trials if t.design_lambda >= SEPARATION]
    close = [t for t in trials if t.design_lambda < SEPARATION]
    outcomes = Counter(str(t.outcome) for t in trials)
    print(f"\n{len(trials)} stand-in trials in {len(rows)} campaigns; separation at the design "
          f"λ ≥ {SEPARATION} (the data can tell them apart) in {len(separable)}")  # fmt: skip
    flagged = outcomes[TermTrialOutcome.FALSE_FLAG]
    figures = {
        "false_flags": _rate(
            "false flags: grouped although λ ≥ SEPARATION", flagged, len(separable)
        )
        | {"predicted_by_delta_chi2_rule": _predicted(separable)},
        "by_band": {},
    }
    for low, high in BANDS:
        some = [t for t in separable if low * SEPARATION <= t.design_lambda < high * SEPARATION]
        count = sum(t.standing for t in some)
        band = _rate(f"  λ in [{low}, {high})·SEPARATION", count, len(some))
        figures["by_band"][f"{low}-{high}x SEPARATION"] = band | {
            "predicted_by_delta_chi2_rule": _predicted(some)
        }
        print(f"    Δχ² rule alone (noncentral χ²₁): {100 * _predicted(some):.1f} %")
    right = "grouped where λ < SEPARATION (the data cannot tell them apart: the statement is right)"
    figures["grouped_when_close"] = _rate(right, outcomes[TermTrialOutcome.RIGHT_GROUP], len(close))
    vetoed_close = sum(bool(t.why) for t in close)
    print(f"  of those not grouped: {vetoed_close} inadmissible or a channel worse")
    # The term swap's false replacements (Criticism.swap_term): a stand-in the data prefer to
    # a true term — admissible, no channel worse, better by more than SEPARATION.
    preferred = sum(not t.why and t.delta_chi2 > SEPARATION for t in trials)
    figures["preferred_over_true_term"] = _rate(
        "stand-ins preferred to a true term (the term swap would replace it)",
        preferred,
        len(trials),
    )
    proposed = sum(r.false_discovery for r in rows)
    null = "campaigns with something proposed (each a null campaign for its truth's structure)"
    figures["null_verdicts"] = _rate(null, proposed, len(rows))
    sizes = Counter(len(g) for r in rows for g in r.term_groups)
    print(f"model-term group sizes (the term and its stand-ins): {dict(sorted(sizes.items()))}")
    max_truth = max(abs(r.lambda_truth) for r in rows)
    print(f"the truth's structure on its noise-free twin: χ² ≤ {max_truth:.2g}")
    print(f"{len(rows)} campaigns in {total_s:.0f} s, load {os.getloadavg()}")
    print(json.dumps({
        "benchmark": "criticism_term_groups",
        "campaigns": len(rows),
        "seed": args.seed,
        "seeds": SeedRange(args.seed, 1).to_dict(),
        "source": args.source,
        "trial_outcomes": dict(outcomes),
        "truths": list(TERM_TRUTHS),
        "separation": SEPARATION,
        "trials": len(trials),
        "separable_trials": len(separable),
        **figures,
        "group_sizes": dict(sorted(sizes.items())),
        "max_truth_chi2_on_twin": max_truth,
        "total_s": round(total_s, 1),
        "load": os.getloadavg(),
    }, default=str))  # fmt: skip


if __name__ == "__main__":
    main()
