"""Calibration of the density's family choice for few curves (``pm_joint.distributions.
family_choice``): the margin Δ(n) by which another family's AICc must beat the normal's.

Each sample of ``n`` values is fitted with the candidates that compete at ``n``
(``family_choice.competitors`` of ``UNBOUNDED_CANDIDATES``: the two-parameter families up
to thirty samples, every candidate beyond), ranked by AICc with the library's
``fit_best``; the gap is ``AICc(norm) − min AICc(other)``.

* ``--stage tune`` (tuning seeds, from 0): standard-normal samples at every n = 4…30; the
  gap's 95 % quantile at each is the table ``family_choice.MARGIN_BY_N`` (printed as
  code). Writes ``bench/results/family_choice_tuning.json``.
* ``--stage report`` (held-out seeds, block ``--block``, after the table is fixed): per
  n = 4…30 and beyond (:data:`BEYOND_N`), how often the rule and plain AICc among the
  same candidates (the choice without the margin, the baseline) choose a non-normal
  family on normal samples (the false-choice rate), and at :data:`POWER_N` how often they
  choose the right-skewed family (gumbel_r) on right-skewed populations: Gumbel
  (skewness 1.14) and lognormal with σ = 0.3 (skewness 0.95), the power. Beyond thirty
  samples, on how many normal samples the t decides the rule's choice. Writes
  ``bench/results/family_choice.json``.

Outcome rule, fixed before the held-out run: the table is calibrated when at every
n = 4…30 the two-sided Clopper–Pearson interval of the false-choice rate, at the level
1 − 0.05/27 (Bonferroni over the 27 sizes: 95 % for them together), contains 5 %.

Run: ``nice -n 10 .venv/bin/python bench/family_choice.py --stage tune --samples 6000``,
then ``--stage report --block 2 --normal 2000 --beyond 600 --skewed 400``. Ends with one JSON line.
"""

import argparse
import json
import os
import time
from multiprocessing import Pool

import numpy as np

from pm_joint.distributions import family_choice
from pm_joint.distributions.families import UNBOUNDED_CANDIDATES, fit_best
from pm_joint.distributions.family_choice import (
    FALSE_CHOICE_RATE,
    TWO_PARAMETER_UP_TO,
    chosen_fit,
    competitors,
    normal_gap_aicc,
)
from studies import clopper_pearson
from studies.seeds import SeedRange, held_out_seeds

TABLE_N = tuple(range(4, TWO_PARAMETER_UP_TO + 1))
BEYOND_N = (50,)
POWER_N = (5, 8, 10, 15, 20, 30, 50)
#: Family-wise level of the outcome rule's intervals (Bonferroni over the table's sizes).
FAMILY_LEVEL = 0.95
#: name → draw n values from rng
POPULATIONS = {
    "normal": lambda rng, n: rng.standard_normal(n),
    "gumbel": lambda rng, n: rng.gumbel(size=n),
    "lognormal_0.3": lambda rng, n: rng.lognormal(0.0, 0.3, size=n),
}
SKEWED_FAMILY = "gumbel_r"


def _ranked(task: tuple[str, int, int]) -> list:
    """One sample of ``task``'s population, its competitors' fits ranked by AICc."""
    population, n, seed = task
    rng = np.random.default_rng([seed, n, list(POPULATIONS).index(population)])
    x = POPULATIONS[population](rng, n)
    return fit_best(x, competitors(UNBOUNDED_CANDIDATES, n), "aicc")


def _gap(task: tuple[str, int, int]) -> float:
    """The gap on one sample (tuning: no rule read)."""
    return normal_gap_aicc(_ranked(task))


def _one(task: tuple[str, int, int]) -> dict:
    population, n, seed = task
    ranked = _ranked(task)
    row = {"population": population, "n": n, "seed": seed, "gap": normal_gap_aicc(ranked),
           "aicc_family": ranked[0].family,
           "rule_family": chosen_fit(ranked, n).family}  # fmt: skip
    if n > TWO_PARAMETER_UP_TO:  # whether the t decides where it competes
        without_t = [f for f in ranked if f.family != "t"]
        row["rule_family_without_t"] = chosen_fit(without_t, n).family
    return row


def _run(tasks: list, workers: int, work=_one) -> list:
    with Pool(workers) as pool:
        return list(pool.imap(work, tasks, chunksize=16))


def _rate(k: int, n: int, level: float = 0.95) -> dict:
    low, high = clopper_pearson(k, n, level)
    return {"k": k, "n": n, "rate": k / n, "interval": [low, high], "level": level}


def tune(samples: int, workers: int) -> dict:
    seeds = SeedRange(0, samples)
    gaps_by_n = np.reshape(
        _run([("normal", n, s) for n in TABLE_N for s in seeds], workers, _gap), (len(TABLE_N), -1)
    )
    table = []
    for n, gaps in zip(TABLE_N, gaps_by_n, strict=True):
        table.append(round(float(np.quantile(gaps, 1 - FALSE_CHOICE_RATE)), 3))
        print(f"n={n}: gap {1 - FALSE_CHOICE_RATE:.0%} quantile {table[-1]:.3f}, plain AICc "
              f"non-normal {int(np.sum(gaps > 0))}/{gaps.size}")  # fmt: skip
    print(f"MARGIN_BY_N: tuple[float, ...] = {tuple(table)}")
    return {"stage": "tune", "seeds": seeds.to_dict(), "samples_per_n": samples,
            "quantile": 1 - FALSE_CHOICE_RATE, "n": list(TABLE_N),
            "margin_by_n": table}  # fmt: skip


def report(normal: int, beyond: int, skewed: int, workers: int, block: int) -> dict:
    seed_range = held_out_seeds(max(normal, beyond, skewed), block=block)
    seeds = list(seed_range)
    tasks = [("normal", n, s) for n in TABLE_N for s in seeds[:normal]]
    tasks += [("normal", n, s) for n in BEYOND_N for s in seeds[:beyond]]
    tasks += [(p, n, s) for p in list(POPULATIONS)[1:] for n in POWER_N
              for s in seeds[:skewed]]  # fmt: skip
    rows = _run(tasks, workers)
    level = 1 - (1 - FAMILY_LEVEL) / len(TABLE_N)
    figures: dict = {"stage": "report", "seeds": seed_range.to_dict(),
                     "margin": {n: family_choice.normal_margin_aicc(n) for n in TABLE_N + BEYOND_N},
                     "false_choice": {}, "power": {p: {} for p in list(POPULATIONS)[1:]},
                     "outcome_rule": f"every n = 4…{TWO_PARAMETER_UP_TO}: the rate's "
                     f"two-sided interval at {level:.4f} contains {FALSE_CHOICE_RATE}"}  # fmt: skip
    for n in TABLE_N + BEYOND_N:
        mine = [r for r in rows if r["n"] == n and r["population"] == "normal"]
        rule = _rate(sum(r["rule_family"] != "norm" for r in mine), len(mine), level)
        plain = _rate(sum(r["aicc_family"] != "norm" for r in mine), len(mine))
        entry = {"where": "table" if n in TABLE_N else "beyond", "rule": rule, "plain_aicc": plain}
        if n > TWO_PARAMETER_UP_TO:
            entry["t_decides"] = sum(r["rule_family"] != r["rule_family_without_t"] for r in mine)
        figures["false_choice"][n] = entry
        print(f"normal n={n}: rule {rule['rate']:.4f} [{rule['interval'][0]:.4f}, "
              f"{rule['interval'][1]:.4f}], plain AICc {plain['rate']:.3f}")  # fmt: skip
    for p in figures["power"]:
        for n in POWER_N:
            mine = [r for r in rows if r["n"] == n and r["population"] == p]
            rule = _rate(sum(r["rule_family"] == SKEWED_FAMILY for r in mine), len(mine))
            plain = _rate(sum(r["aicc_family"] == SKEWED_FAMILY for r in mine), len(mine))
            figures["power"][p][n] = {"rule": rule, "plain_aicc": plain}
            print(f"{p} n={n}: rule chooses {SKEWED_FAMILY} {rule['rate']:.3f}, "
                  f"plain AICc {plain['rate']:.3f}")  # fmt: skip
    table = [
        e["rule"]["interval"] for e in figures["false_choice"].values() if e["where"] == "table"
    ]
    figures["calibrated"] = all(low <= FALSE_CHOICE_RATE <= high for low, high in table)
    return figures


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--stage", choices=("tune", "report"), required=True)
    parser.add_argument("--samples", type=int, default=6000, help="tune: samples per n")
    parser.add_argument("--normal", type=int, default=2000, help="report: normal samples per n")
    parser.add_argument(
        "--beyond",
        type=int,
        default=600,
        help="report: normal samples per n beyond the table (the t competes: slow)",
    )
    parser.add_argument("--skewed", type=int, default=400, help="report: per skewed population")
    parser.add_argument("--block", type=int, default=2, help="report: held-out block")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    start = time.perf_counter()
    if args.stage == "tune":
        figures, name = tune(args.samples, args.workers), "family_choice_tuning"
    else:
        figures = report(args.normal, args.beyond, args.skewed, args.workers, args.block)
        name = "family_choice"
    figures["seconds"] = time.perf_counter() - start
    os.makedirs("bench/results", exist_ok=True)
    with open(f"bench/results/{name}.json", "w") as handle:
        json.dump(figures, handle, indent=2)
    print(json.dumps(figures))


if __name__ == "__main__":
    main()
