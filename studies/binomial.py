"""Binomial intervals of the studies' rates: the exact interval of an observed rate and the
acceptance region of a count."""

from __future__ import annotations

from scipy import stats

__all__ = ["binomial_bounds", "clopper_pearson"]


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided exact (Clopper–Pearson) interval of a binomial rate ``k / n``.

    Parameters
    ----------
    k, n
        Successes and trials.
    confidence
        Coverage of the interval.

    Returns
    -------
    tuple of float
        The interval's low and high ends.
    """
    interval = stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="exact")
    return float(interval.low), float(interval.high)


def binomial_bounds(n: int, prob: float, level: float = 0.95) -> tuple[int, int]:
    """Two-sided ``level`` acceptance region of a Binomial(n, prob) count (equal tails).

    Parameters
    ----------
    n, prob
        Trials and the success probability.
    level
        Probability of the region.

    Returns
    -------
    tuple of int
        The lowest and highest count of the region.
    """
    tail = 0.5 * (1 - level)
    return int(stats.binom.ppf(tail, n, prob)), int(stats.binom.isf(tail, n, prob))
