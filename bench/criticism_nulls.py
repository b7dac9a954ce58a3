"""Null p-values of the criticism's calibrated decision on lab-like campaigns.

Lab-rig null campaigns (:func:`studies.null_study` with ``source="rig"``: the lab presets
with one artefact each on a linear-viscous truth and nothing hidden — pure, distorted
shaker, controller ripple, imperfect lock, sensor dropouts, :data:`studies.nulls.LAB_NULL_TRUTHS`
— 3 assemblies, 8 levels, time integration under a phase-locked loop, backbones extracted
from the records), each criticised with its truth's structure, once with the systematic
floors (:data:`identification.fitting.data.NOISE_FLOOR`) and once without
(:data:`studies.nulls.NO_FLOOR`). Under the null a calibrated p-value is uniform.

Printed, for each floor setting, over all campaigns and per preset: the Kolmogorov–Smirnov
test of uniformity (two-sided), and the share of p-values ≤ α for α ∈ {0.01, 0.05, 0.1}
with its two-sided 95 % Clopper–Pearson interval; with the floors, the mean effective level
the criticisms print (``Calibration.effective_level``, at their α = 1 %) beside the
measured share ≤ 1 %. Baselines: the same campaigns with the bootstrap drawn from the
analysis' estimate of the covariance (the calibration before the bootstrap drew curves like
the measured ones).

**Outcome rule** (issue 25, fixed before the held-out run, over all campaigns, every preset
included): floors off — uniformity not rejected (KS, 1 %); floors on — uniformity not
rejected, or the printed effective level inside the measured share's two-sided 95 %
Clopper–Pearson bounds. The per-preset figures are reported beside it, not judged (about
40 campaigns each).

**Seeds.** Campaign ``k`` is seeded ``[seed, k]``; the default ``--seed`` is held-out block 4
(4_000_000, :data:`SEED`). Block 1 (1_000_000) was read before the hold fits corrected the
power balance of unsettled holds (``extraction.stored_energy_damping``, the lab-lock fix),
so the report moved; the correction was chosen on tuning seeds (block 0).
``--cache DIR`` keeps the simulated campaigns (the simulation dominates), ``--rows FILE``
appends each campaign's row and reuses rows already there, ``--part i/m`` runs the campaigns
``k ≡ i (mod m)`` only (pieces in parallel; a run without ``--part`` reads every row and
prints the figures), ``--until HH:MM`` (UTC) starts no campaign after that time and
summarises the rows done (the presets taken in turn, so a stop leaves them balanced within one).

Run: ``nice -n 10 .venv/bin/python bench/criticism_nulls.py --campaigns 200``. Writes
``bench/results/criticism_nulls.json`` and ``.txt``; ends with one JSON line.
"""

import argparse
import dataclasses
import datetime
import json
import time
from pathlib import Path

import numpy as np
from scipy import stats

from identification.criticism import calibration as cal
from identification.criticism.criticism import ALPHA, N_BOOTSTRAP, criticize
from identification.rig import RIG_PRESETS
from studies import clopper_pearson
from studies.nulls import LAB_DRIFT_TRUTHS, LAB_NULL_TRUTHS, NO_FLOOR, rig_campaign
from studies.seeds import held_out_block

LEVELS = (0.01, 0.05, 0.1)
KS_LEVEL = 0.01
RESULTS = Path(__file__).parent / "results"
FLOORS = {"floors": None, "no_floors": NO_FLOOR}
#: The held-out block of the reported run (see the module notes for why not block 1).
SEED = held_out_block(4)


def _baseline_p(crit) -> float:
    """The p-value with the bootstrap drawn from the analysis' estimate of the covariance."""
    problem = dataclasses.replace(crit.problem)
    curves = problem.curves.shape[0]
    problem.__dict__["drawn_scatter"] = (  # the draw before this change
        np.zeros((curves, problem.size)),
        problem.metric.covariance.per_curve,
    )
    calibration = cal.calibrate(
        problem, crit.observed, alpha=crit.alpha, n_bootstrap=crit.n_bootstrap, seed=crit.seed
    )
    return calibration.p_value(crit.observed.catalogue[0], crit.observed.reference[0])


def campaign_row(k: int, truth: str, seed: int, cache: Path | None, n_bootstrap: int) -> dict:
    began = time.perf_counter()
    presets = {**LAB_NULL_TRUTHS, **LAB_DRIFT_TRUTHS}
    measured = rig_campaign(presets[truth], 3, (seed, k), cache=cache)
    row = {"campaign": k, "seed": [seed, k], "truth": truth}
    for name, floor in FLOORS.items():
        crit = criticize(RIG_PRESETS[presets[truth]].model, measured, noise_floor=floor,
                         n_bootstrap=n_bootstrap)  # fmt: skip
        row[name] = {
            "p_value": crit.p_value,
            "baseline_p_value": _baseline_p(crit),
            "catalogue_gain": float(crit.observed.catalogue[0]),
            "catalogue_threshold": crit.calibration.catalogue_threshold,
            "reference_gain": float(crit.observed.reference[0]),
            "reference_threshold": crit.calibration.reference_threshold,
            "effective_level": crit.calibration.effective_level,
        }
    row["seconds"] = time.perf_counter() - began
    return row


def _shares(p: np.ndarray) -> dict:
    out = {}
    for alpha in LEVELS:
        k = int(np.sum(p <= alpha))
        low, high = clopper_pearson(k, p.size)
        out[str(alpha)] = {"count": k, "runs": int(p.size), "share": k / p.size,
                           "ci95_low": low, "ci95_high": high,
                           "alpha_inside": bool(low <= alpha <= high)}  # fmt: skip
    return out


def _figures(p: np.ndarray) -> dict:
    ks = stats.kstest(p, "uniform")
    return {"ks_statistic": float(ks.statistic), "ks_p": float(ks.pvalue),
            "uniform_not_rejected": bool(ks.pvalue > KS_LEVEL),
            "median_p": float(np.median(p)), "below": _shares(p)}  # fmt: skip


def _share_text(below: dict) -> str:
    return ", ".join(
        f"≤ {a}: {v['count']}/{v['runs']} ({100 * v['ci95_low']:.1f}–{100 * v['ci95_high']:.1f} %)"
        for a, v in below.items()
    )


def summarise(rows: list[dict]) -> tuple[dict, list[str]]:
    """Figures and baselines of the rows, with their text lines."""
    last = max(r["campaign"] for r in rows)
    lines = [f"{len(rows)} lab-rig null campaigns (seed {rows[0]['seed'][0]}, "
             f"k ≤ {last}); p-values of the calibrated decision"]  # fmt: skip
    figures, baselines = {}, {}
    for name in FLOORS:
        p = np.array([r[name]["p_value"] for r in rows])
        b = np.array([r[name]["baseline_p_value"] for r in rows])
        figures[name], baselines[name] = _figures(p), _figures(b)
        figures[name]["by_truth"] = {
            t: _figures(np.array([r[name]["p_value"] for r in rows if r["truth"] == t]))
            for t in dict.fromkeys(r["truth"] for r in rows)
        }
        for prefix, f in (("", figures[name]), ("baseline ", baselines[name])):
            lines.append(f"{prefix}{name}: KS p {f['ks_p']:.3g}, median p {f['median_p']:.2f}; "
                         + _share_text(f["below"]))  # fmt: skip
        for t, f in figures[name]["by_truth"].items():
            lines.append(f"  {name} {t}: KS p {f['ks_p']:.3g}, median {f['median_p']:.2f}; "
                         + _share_text(f["below"]))  # fmt: skip
    printed = float(np.mean([r["floors"]["effective_level"] for r in rows]))
    at_alpha = figures["floors"]["below"][str(ALPHA)]
    figures["floors"]["printed_effective_level"] = printed
    figures["floors"]["printed_inside_measured"] = bool(
        at_alpha["ci95_low"] <= printed <= at_alpha["ci95_high"]
    )
    lines.append(
        f"floors: effective level printed (mean over campaigns, α = {ALPHA:g}) "
        f"{100 * printed:.2g} %, measured {at_alpha['count']}/{at_alpha['runs']} "
        f"({100 * at_alpha['ci95_low']:.1f}–{100 * at_alpha['ci95_high']:.1f} %)"
    )
    return {"figures": figures, "baselines": baselines}, lines


def _past(until: str) -> bool:
    """Whether the UTC clock is past ``HH:MM`` today."""
    now = datetime.datetime.now(datetime.UTC)
    hours, minutes = (int(x) for x in until.split(":"))
    return (now.hour, now.minute) >= (hours, minutes)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaigns", type=int, default=200)
    parser.add_argument("--seed", type=int, default=SEED)
    parser.add_argument("--truths", default=",".join(LAB_NULL_TRUTHS),
                        help="keys of LAB_NULL_TRUTHS / LAB_DRIFT_TRUTHS, in turn")  # fmt: skip
    parser.add_argument("--n-bootstrap", type=int, default=N_BOOTSTRAP)
    parser.add_argument("--cache", type=Path, help="folder keeping the simulated campaigns")
    parser.add_argument("--rows", type=Path, help="JSON-lines file of rows (appended, reused)")
    parser.add_argument("--part", help="i/m: run only the campaigns k ≡ i (mod m)")
    parser.add_argument("--until", help="HH:MM (UTC): start no campaign after it")
    parser.add_argument("--out", type=Path, default=RESULTS / "criticism_nulls.json")
    args = parser.parse_args()
    truths = args.truths.split(",")
    done = {}
    if args.rows is not None and args.rows.exists():
        for line in args.rows.read_text().splitlines():
            row = json.loads(line)
            if row["seed"][0] == args.seed:
                done[row["campaign"]] = row
    part, parts = (int(x) for x in args.part.split("/")) if args.part else (0, 1)
    began = time.perf_counter()
    for k in range(part, args.campaigns, parts):
        if k in done:
            continue
        if args.until is not None and _past(args.until):
            break
        row = campaign_row(k, truths[k % len(truths)], args.seed, args.cache, args.n_bootstrap)
        done[k] = row
        print(json.dumps(row), flush=True)
        if args.rows is not None:
            with args.rows.open("a") as out:
                out.write(json.dumps(row) + "\n")
    if args.part:
        return
    rows = [done[k] for k in sorted(done) if k < args.campaigns]
    result, lines = summarise(rows)
    text = "\n".join(lines)
    print(text)
    summary = {
        "benchmark": "criticism_null_p_values",
        "campaigns": len(rows),
        "seed": args.seed,
        "truths": truths,
        "assemblies": 3,
        "levels": 8,
        "alpha": ALPHA,
        "n_bootstrap": args.n_bootstrap,
        **result,
        "targets": {
            "ks_level": KS_LEVEL,
            "rule": "uniformity not rejected (KS, 1 %), or the printed effective level "
            "within the measured share's two-sided 95 % Clopper-Pearson bounds",
        },
        "meets_target": {
            "no_floors": result["figures"]["no_floors"]["uniform_not_rejected"],
            "floors": result["figures"]["floors"]["uniform_not_rejected"]
            or result["figures"]["floors"]["printed_inside_measured"],
        },
        "seconds": round(time.perf_counter() - began, 1),
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(summary, indent=1) + "\n")
    args.out.with_suffix(".txt").write_text(text + "\n")
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
