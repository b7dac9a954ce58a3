"""Calibration of the density's family choice for few curves (``pm_joint.distributions.
family_choice``): the margin Δ(n) by which another family's AICc must beat the normal's.

Each sample of ``n`` values is fitted with every family of ``UNBOUNDED_CANDIDATES`` (the
library's ``fit_best``, ranked by AICc); the gap is ``AICc(norm) − min AICc(other)``.

* ``--stage tune`` (tuning seeds, from 0): standard-normal samples at each ``n`` of
  ``TUNE_N``; the gap's 95 % quantile at each, and the saturating curve
  ``plateau − rise · exp(−n / scale)`` fitted to them by least squares, whose rounded
  constants are written into ``family_choice.MARGIN_*``. Writes
  ``bench/results/family_choice_tuning.json``. ``--stage fit`` refits the curve to the
  quantiles stored there (no sampling).
* ``--stage report`` (held-out seeds, from 1 000 000, after the table is fixed): per
  ``n`` of ``REPORT_N`` (inside the calibrated range 4…30 and one beyond it),
  how often the rule and plain AICc (the choice before the rule, the baseline) choose a
  non-normal family on normal samples (the false-choice rate, with its two-sided 95 %
  Clopper–Pearson interval), and how often they choose a right-skewed family (gumbel_r)
  on right-skewed populations: Gumbel (skewness 1.14) and lognormal with σ = 0.3
  (skewness 0.95), the power; and on how many normal samples the t family decides the
  rule's choice (the fast test leaves the t out). Writes ``bench/results/family_choice.json``.

Outcome rule fixed before the held-out run: the rule is calibrated when no false-choice
interval inside 4…30 lies wholly above 5 %.

Run: ``nice -n 10 .venv/bin/python bench/family_choice.py --stage tune --samples 800``,
then ``--stage report --normal 600 --skewed 150``. Ends with one JSON line.
"""

import argparse
import json
import os
import time
from multiprocessing import Pool

import numpy as np
from scipy.optimize import curve_fit

from pm_joint.distributions import family_choice
from pm_joint.distributions.families import UNBOUNDED_CANDIDATES, fit_best
from pm_joint.distributions.family_choice import FALSE_CHOICE_RATE, chosen_fit, normal_gap_aicc
from studies import clopper_pearson
from studies.seeds import SeedRange, held_out_seeds

TUNE_N = (4, 5, 6, 7, 8, 10, 12, 15, 20, 25, 30)
REPORT_N = (4, 5, 6, 8, 9, 10, 12, 15, 20, 30, 50)
TUNING_JSON = "bench/results/family_choice_tuning.json"
#: name → (draw n values from rng, the family that names its skew)
POPULATIONS = {
    "normal": lambda rng, n: rng.standard_normal(n),
    "gumbel": lambda rng, n: rng.gumbel(size=n),
    "lognormal_0.3": lambda rng, n: rng.lognormal(0.0, 0.3, size=n),
}
SKEWED_FAMILY = "gumbel_r"


def _one(task: tuple[str, int, int]) -> dict:
    population, n, seed = task
    rng = np.random.default_rng([seed, n, list(POPULATIONS).index(population)])
    x = POPULATIONS[population](rng, n)
    ranked = fit_best(x, UNBOUNDED_CANDIDATES, "aicc")
    row = {"population": population, "n": n, "seed": seed, "gap": normal_gap_aicc(ranked),
           "aicc_family": ranked[0].family}  # fmt: skip
    row["rule_family"] = chosen_fit(ranked, n).family
    # Whether the t decides: the rule's choice without it (the fast test leaves it out).
    without_t = [f for f in ranked if f.family != "t"]
    row["rule_family_without_t"] = chosen_fit(without_t, n).family
    return row


def _run(tasks: list, workers: int) -> list[dict]:
    with Pool(workers) as pool:
        return list(pool.imap_unordered(_one, tasks, chunksize=4))


def _rate(k: int, n: int) -> dict:
    low, high = clopper_pearson(k, n)
    return {"k": k, "n": n, "rate": k / n, "interval95": [low, high]}


def tune(samples: int, workers: int) -> dict:
    seeds = SeedRange(0, samples)
    rows = _run([("normal", n, s) for n in TUNE_N for s in seeds], workers)
    quantiles = {}
    for n in TUNE_N:
        gaps = np.array([r["gap"] for r in rows if r["n"] == n])
        quantiles[n] = round(float(np.quantile(gaps, 1 - FALSE_CHOICE_RATE)), 2)
        plain = int(np.sum(gaps > 0))
        print(f"n={n}: gap 95 % quantile {quantiles[n]:.2f}, plain AICc non-normal "
              f"{plain}/{gaps.size}")  # fmt: skip
    figures = {"stage": "tune", "seeds": seeds.to_dict(), "samples_per_n": samples,
               "quantile": 1 - FALSE_CHOICE_RATE, "quantiles": list(quantiles.items())}  # fmt: skip
    return figures | fit(figures["quantiles"])


def _law(n, plateau, rise, scale):
    return plateau - rise * np.exp(-n / scale)


def fit(quantiles: list) -> dict:
    """The saturating curve through the quantiles (least squares), rounded as the code holds it."""
    n, q = np.array(quantiles, dtype=float).T
    constants, _ = curve_fit(_law, n, q, p0=(q.max(), q.max(), 4.0))
    plateau, rise, scale = (round(float(c), 2) for c in constants)
    residuals = q - _law(n, plateau, rise, scale)
    print(f"MARGIN_PLATEAU = {plateau}\nMARGIN_RISE = {rise}\nMARGIN_SCALE_N = {scale}")
    return {"law": {"plateau": plateau, "rise": rise, "scale_n": scale},
            "rms_residual": float(np.sqrt(np.mean(residuals**2)))}  # fmt: skip


def report(normal: int, skewed: int, workers: int, block: int) -> dict:
    law = (family_choice.MARGIN_PLATEAU, family_choice.MARGIN_RISE,
           family_choice.MARGIN_SCALE_N)  # fmt: skip
    seeds = held_out_seeds(max(normal, skewed), block=block)
    tasks = [("normal", n, s) for n in REPORT_N for s in list(seeds)[:normal]]
    tasks += [(p, n, s) for p in list(POPULATIONS)[1:] for n in REPORT_N
              for s in list(seeds)[:skewed]]  # fmt: skip
    rows = _run(tasks, workers)
    figures: dict = {"stage": "report", "seeds": seeds.to_dict(),
                     "law": dict(zip(("plateau", "rise", "scale_n"), law, strict=True)),
                     "margin": {n: family_choice.normal_margin_aicc(n) for n in REPORT_N},
                     "false_choice": {},
                     "power": {p: {} for p in list(POPULATIONS)[1:]}}  # fmt: skip
    for n in REPORT_N:
        mine = [r for r in rows if r["n"] == n and r["population"] == "normal"]
        rule = _rate(sum(r["rule_family"] != "norm" for r in mine), len(mine))
        plain = _rate(sum(r["aicc_family"] != "norm" for r in mine), len(mine))
        where = "calibrated" if n <= max(TUNE_N) else "beyond"
        t_decides = sum(r["rule_family"] != r["rule_family_without_t"] for r in mine)
        figures["false_choice"][n] = {"where": where, "rule": rule, "plain_aicc": plain,
                                      "t_decides": t_decides}  # fmt: skip
        print(f"normal n={n} ({where}): rule {rule['rate']:.3f} "
              f"[{rule['interval95'][0]:.3f}, {rule['interval95'][1]:.3f}], "
              f"plain AICc {plain['rate']:.3f}")  # fmt: skip
        for p in figures["power"]:
            mine = [r for r in rows if r["n"] == n and r["population"] == p]
            rule = _rate(sum(r["rule_family"] == SKEWED_FAMILY for r in mine), len(mine))
            plain = _rate(sum(r["aicc_family"] == SKEWED_FAMILY for r in mine), len(mine))
            figures["power"][p][n] = {"rule": rule, "plain_aicc": plain}
            print(f"{p} n={n}: rule chooses {SKEWED_FAMILY} {rule['rate']:.3f}, "
                  f"plain AICc {plain['rate']:.3f}")  # fmt: skip
    figures["calibrated"] = all(
        e["rule"]["interval95"][0] <= FALSE_CHOICE_RATE
        for e in figures["false_choice"].values() if e["where"] == "calibrated"
    )  # fmt: skip
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stage", choices=("tune", "fit", "report"), required=True)
    parser.add_argument("--samples", type=int, default=800, help="tune: samples per n")
    parser.add_argument("--normal", type=int, default=800, help="report: normal samples per n")
    parser.add_argument("--skewed", type=int, default=200, help="report: per skewed population")
    parser.add_argument("--block", type=int, default=1, help="report: held-out block")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    start = time.perf_counter()
    if args.stage == "tune":
        figures, name = tune(args.samples, args.workers), "family_choice_tuning"
    elif args.stage == "fit":
        with open(TUNING_JSON) as handle:
            figures = json.load(handle)
        figures |= fit(figures["quantiles"])
        name = "family_choice_tuning"
    else:
        figures = report(args.normal, args.skewed, args.workers, args.block)
        name = "family_choice"
    if args.stage != "fit":  # the fit keeps the sampling's time
        figures["seconds"] = time.perf_counter() - start
    os.makedirs("bench/results", exist_ok=True)
    with open(f"bench/results/{name}.json", "w") as handle:
        json.dump(figures, handle, indent=2)
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
