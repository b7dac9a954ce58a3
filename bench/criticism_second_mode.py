"""Criticism that names a missing mode: two-mode data against one-mode data (#27 item 6).

Runs :func:`studies.second_mode.second_mode_campaign` over cases and seeds (the outcome rule
and the cases are in :mod:`studies.second_mode`, fixed before any reported run), one
process, appending each row to a JSON-lines file as it finishes (a run stopped by
``--stop-at`` keeps what it did), then counts per case with two-sided 95 % Clopper–Pearson
intervals against #27's acceptance (≥ 27 of 30 per two-mode case, ≤ 1 of 30 on one-mode data),
beside how many were named at a located frequency and at a wrong one.

    nice -n 10 python bench/criticism_second_mode.py --first-seed 0 --seeds 1   # tuning
    nice -n 10 python bench/criticism_second_mode.py --cases "two-mode near 1:1,independent \\
        near 1:1,two-mode 1:2,independent 1:2,lab-second-mode" --first-seed 8000000 --seeds 30 \\
        --rows bench/results/criticism_missing_mode_rows_block8.jsonl --stop-at 01:40  # held out
    python bench/criticism_second_mode.py --rows FILE --summary                # count only

Ends with one JSON line; writes ``bench/results/criticism_missing_mode[_tuning].json``.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
from pathlib import Path

from studies.binomial import clopper_pearson
from studies.second_mode import CASES, TWO_MODE_CASES, SecondModeRow, count, second_mode_campaign
from studies.seeds import HELD_OUT_SEED

RESULTS = Path(__file__).parent / "results"
TARGET = "two-mode cases: >= 27 of 30 named within 5 %; one-mode data: <= 1 of 30 named"


def _past(stop_at: str | None) -> bool:
    if not stop_at:
        return False
    hour, minute = (int(x) for x in stop_at.split(":"))
    now = dt.datetime.now(dt.UTC)
    return (now.hour, now.minute) >= (hour, minute)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default=",".join(CASES))
    parser.add_argument("--first-seed", type=int, default=HELD_OUT_SEED)
    parser.add_argument("--seeds", type=int, default=1)
    parser.add_argument("--rows", type=Path, default=None,
                        help="JSON-lines rows file (summary: FILE.summary.json)")  # fmt: skip
    parser.add_argument("--stop-at", default=None, help="UTC HH:MM after which no row starts")
    parser.add_argument("--summary", action="store_true", help="count the rows file only")
    args = parser.parse_args()
    held_out = args.first_seed >= HELD_OUT_SEED
    name = "criticism_missing_mode" + ("" if held_out else "_tuning")
    rows_path = args.rows or RESULTS / f"{name}_rows.jsonl"
    if not args.summary:
        cases = [c for c in args.cases.split(",") if c]
        # seeds outermost: a run stopped early has every case at the seeds it reached
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            for case in cases:
                if _past(args.stop_at):
                    break
                row = second_mode_campaign(case, seed)
                with rows_path.open("a") as out:
                    out.write(json.dumps(row.to_dict()) + "\n")
                print(f"{case} {seed}: {row.verdict}; {row.named_hz:.4g} Hz "
                      f"(truth {row.truth_hz:.4g}); passed {row.passed}", flush=True)  # fmt: skip
    rows = [SecondModeRow(**json.loads(line)) for line in rows_path.read_text().splitlines()]
    counts = count(rows)
    for c in counts:
        what = "named within 5 %" if c.two_modes else "failed (named wrongly)"
        print(f"{c.case}: {c.passed if c.two_modes else c.n - c.passed} of {c.n} {what}; named "
              f"{c.named}, located {c.located}, at a wrong frequency {c.wrong} "
              f"(95 % CP {100 * c.low:.1f}–{100 * c.high:.1f} %), seeds {c.seeds}")  # fmt: skip
    one_mode = [r for r in rows if not r.two_modes]
    falsely = sum(not r.passed for r in one_mode)
    summary = {
        "benchmark": "criticism_missing_mode",
        "target": TARGET,
        "rows": str(rows_path),
        "two_mode_cases": list(TWO_MODE_CASES),
        "counts": [c.to_dict() for c in counts],
        "one_mode_failed": falsely,
        "one_mode_n": len(one_mode),
        "one_mode_cp95": list(clopper_pearson(falsely, len(one_mode))) if one_mode else None,
    }
    # A rows file of one's own gets its summary beside it, not the study's (which a
    # partial run would overwrite).
    own = args.rows is not None
    where = rows_path.with_suffix(".summary.json") if own else RESULTS / f"{name}.json"
    where.write_text(json.dumps(summary, indent=2) + "\n")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
