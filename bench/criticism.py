"""Benchmark and acceptance study of model criticism.

Default: time from test records to a ranking of missing effects. A 5-record
campaign of the ``trc-like`` rig (10 levels of 2.5 s at 10 kHz; microslip and
cubic hardening hidden from a linear-viscous base model) is written to a
temporary folder first (not timed). Timed: reading the records, extracting
the backbones (with their harmonics), fitting the user's base model, criticising
it with the backbones' harmonics and ranking every catalogue effect. Target: ≤ 60 s.

``--study``: the hidden-effect study. For every rig scenario and seed, the
preset's base model is fitted, criticised with the harmonics, and the effect
ranked first added until nothing significant is missing; the table gives the
effect ranked first, what was added, the RMSE before → after of frequency,
damping and harmonics, and ΔBIC. Acceptance: the hidden effect ranked first
and its key channel's RMSE down by ≥ 80 %, nothing proposed in the control,
both effects of ``hidden-two`` found in two rounds.

Run: ``.venv/bin/python bench/criticism.py`` or
``.venv/bin/python bench/criticism.py --study --seeds 5``.
Prints a table, then one JSON line.
"""

import argparse
import json
import shutil
import tempfile
import time
from pathlib import Path

from identification.criticism.criticism import criticize
from identification.fitting.least_squares import fit_backbones
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Campaign
from identification.rig import HIDDEN_EFFECT_SCENARIOS, RIG_PRESETS, Rig
from pm_joint.studies import KEY_CHANNEL, hidden_effect_study

TARGET_S = 60.0
SCENARIOS = HIDDEN_EFFECT_SCENARIOS


def bench(records: int, levels: int, hold_s: float) -> dict:
    folder = Path(tempfile.mkdtemp(prefix="pm-joint-bench-criticism-"))
    try:
        rig = Rig.preset("trc-like", levels=levels, hold_s=hold_s)
        rig.write_campaign(folder, assemblies=records, seed=0)  # not timed
        times = {}
        start = time.perf_counter()
        loaded = list(Campaign(folder))
        times["read_s"] = time.perf_counter() - start
        mark = time.perf_counter()
        measured = extract_backbones(loaded)
        times["extract_s"] = time.perf_counter() - mark
        mark = time.perf_counter()
        # the user's first fit: frequency and damping of the backbones alone
        base = fit_backbones(RIG_PRESETS["trc-like"].base_model, measured.without_harmonics())
        times["base_fit_s"] = time.perf_counter() - mark
        mark = time.perf_counter()
        crit = criticize(base.model, measured)
        ranking = crit.missing()
        times["criticize_s"] = time.perf_counter() - mark
        times["total_s"] = time.perf_counter() - start
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    print(f"{'stage':<14}{'seconds':>10}")
    for key, value in times.items():
        print(f"{key[:-2]:<14}{value:>10.2f}")
    print(f"ranked: {[c.effect for c in ranking[:3]]} of {len(crit.candidates)} candidates")
    return {
        "benchmark": "criticism_records_to_ranking",
        "records": records,
        "levels": levels,
        "hold_s": hold_s,
        "candidates": len(crit.candidates),
        "ranked_first": ranking[0].effect if ranking else None,
        **{k: round(v, 3) for k, v in times.items()},
        "target_total_s": TARGET_S,
        "meets_target": times["total_s"] <= TARGET_S,
    }


def _pair(values, factor=1.0, digits=3) -> str:
    first, last = values[0], values[-1]
    if first is None:
        return "—"
    return f"{factor * first:.{digits}g} → {factor * last:.{digits}g}"


def study(seeds: int, assemblies: int, levels: int) -> dict:
    header = (
        f"{'scenario':<25}{'seed':>5}  {'ranked first':<22}{'added':<34}"
        f"{'freq RMSE Hz':<19}{'damping RMSE %':<21}{'harm. RMSE %':<21}{'ΔBIC':<20}"
        f"{'key −%':>7}  ok"
    )
    print(header)
    rows = []
    for scenario in SCENARIOS:
        for seed in range(seeds):
            start = time.perf_counter()
            result = hidden_effect_study(scenario, seed, assemblies=assemblies, levels=levels)
            row = result.row() | {"seconds": round(time.perf_counter() - start, 1)}
            rows.append(row)
            key = KEY_CHANNEL.get(scenario)
            key_text = f"{100 * row['reduction'][key]:.1f}" if key else "—"
            print(
                f"{scenario:<25}{seed:>5}  {row['ranked_first'] or 'nothing':<22}"
                f"{', '.join(row['added']) or '—':<34}"
                f"{_pair(row['frequency_rmse_hz']):<18} "
                f"{_pair(row['damping_rmse'], 100):<20} "
                f"{_pair(row['harmonic_rmse'], 100):<20} "
                f"{', '.join(f'{d:.0f}' for d in row['delta_ic']) or '—':<20}"
                f"{key_text:>7}  {'yes' if row['passed'] else 'NO'}",
                flush=True,
            )
    passed = sum(r["passed"] for r in rows)
    print(f"passed {passed} of {len(rows)}")
    return {
        "benchmark": "criticism_hidden_effect_study",
        "seeds": seeds,
        "assemblies": assemblies,
        "levels": levels,
        "passed": passed,
        "runs": len(rows),
        "target": "hidden effect ranked first, key-channel RMSE reduction >= 80 %, "
        "nothing proposed in hidden-none, both effects of hidden-two in two rounds",
        "rows": rows,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--study", action="store_true", help="run the hidden-effect study")
    parser.add_argument("--seeds", type=int, default=5, help="seeds per scenario (study)")
    parser.add_argument("--assemblies", type=int, default=3, help="assemblies per run (study)")
    parser.add_argument("--records", type=int, default=5, help="records in the bench campaign")
    parser.add_argument("--levels", type=int, help="levels per record (8 study, 10 bench)")
    args = parser.parse_args()
    if args.study:
        figures = study(args.seeds, args.assemblies, args.levels or 8)
    else:
        figures = bench(args.records, args.levels or 10, hold_s=2.5)
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
