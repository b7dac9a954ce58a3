"""Which family a marginal of few samples gets: the normal, unless another is clearly better.

Ranked by AICc alone, the candidate families of a handful of samples are chosen by
likelihood only: every two-parameter family pays the same penalty, and on five values
drawn from a normal a skewed Gumbel fits best more often than the normal does. A skewed
marginal then moves the density's mode away from its median, and a posterior scored by
that density with it.

The rule (:func:`chosen_fit`): the normal is the default; the AICc-best other candidate
replaces it only when it beats the normal's AICc by more than a margin Δ(n)
(:func:`normal_margin_aicc`), set so that on ``n`` samples drawn from a normal a
non-normal family is chosen for at most :data:`FALSE_CHOICE_RATE` of the marginals.

Calibration (``bench/family_choice.py``): the gap ``AICc(norm) − min AICc(other)`` of
every candidate in :data:`~pm_joint.distributions.families.UNBOUNDED_CANDIDATES` does
not depend on the normal's mean and spread (every candidate is a location-scale family,
fitted by maximum likelihood), so its distribution under the normal depends on ``n``
alone. The bench draws standard-normal samples on tuning seeds at n = 4…30, takes the
gap's 95 % quantile at each, and Δ(n) is a saturating curve fitted to those quantiles
(:func:`normal_margin_aicc`), which holds its plateau beyond thirty. The false-choice
rate (normal samples that get another family) and the power (skewed samples
that get a skewed family of the right side) are then measured, beside plain AICc, on
held-out seeds: ``bench/results/family_choice.json``.

For a subset of the unbounded candidates the same margin keeps the rate at or below
5 % (the best of fewer alternatives beats the normal less often); for other candidate
sets (bounded families) it is not calibrated. With three samples or fewer AICc is
undefined for every family, and the normal is taken.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from pm_joint.distributions.families import (
    UNBOUNDED_CANDIDATES,
    DistributionFit,
    fit_best,
)

__all__ = [
    "FALSE_CHOICE_RATE",
    "MARGIN_PLATEAU",
    "MARGIN_RISE",
    "MARGIN_SCALE_N",
    "choose_family",
    "chosen_fit",
    "normal_gap_aicc",
    "normal_margin_aicc",
]

#: The share of normal samples for which the rule may choose another family.
FALSE_CHOICE_RATE = 0.05

#: Δ(n) = MARGIN_PLATEAU − MARGIN_RISE · exp(−n / MARGIN_SCALE_N): least squares through
#: the gap's ``1 − FALSE_CHOICE_RATE`` quantiles on standard-normal samples at n = 4…30
#: (tuning seeds, ``bench/family_choice.py --stage tune``; the quantiles are in
#: ``bench/results/family_choice_tuning.json``).
MARGIN_PLATEAU = 3.63
MARGIN_RISE = 5.51
MARGIN_SCALE_N = 3.82


def normal_margin_aicc(n_samples: float) -> float:
    """Δ(n): how much lower than the normal's another family's AICc must be to replace it.

    Parameters
    ----------
    n_samples
        Number of samples the families are fitted to.

    Returns
    -------
    float
        ``MARGIN_PLATEAU − MARGIN_RISE · exp(−n / MARGIN_SCALE_N)``; infinite below four
        samples (AICc is undefined for two parameters there).
    """
    if n_samples < 4:
        return float("inf")
    return float(MARGIN_PLATEAU - MARGIN_RISE * np.exp(-n_samples / MARGIN_SCALE_N))


def normal_gap_aicc(ranked: Sequence[DistributionFit]) -> float:
    """``AICc(norm) − min AICc(other candidates)``: how far the best other family beats the normal.

    Parameters
    ----------
    ranked
        Fits of the candidates (any order), the normal among them.

    Returns
    -------
    float
        Positive where another family's AICc is lower; ``-inf`` where no other family
        has a finite AICc.
    """
    normal = _normal(ranked)
    others = [f.aicc for f in ranked if f.family != "norm" and np.isfinite(f.aicc)]
    if not others or not np.isfinite(normal.aicc):
        return float("-inf")
    return float(normal.aicc - min(others))


def chosen_fit(ranked: Sequence[DistributionFit], n_samples: int) -> DistributionFit:
    """The rule: the normal, unless the best other family beats it by more than Δ(n).

    Parameters
    ----------
    ranked
        Fits of the candidates ranked by AICc, best first (:func:`fit_best` with
        ``"aicc"``), the normal among them.
    n_samples
        Number of samples they were fitted to.

    Returns
    -------
    DistributionFit
        The chosen fit.
    """
    if normal_gap_aicc(ranked) > normal_margin_aicc(n_samples):
        return ranked[0]
    return _normal(ranked)


def choose_family(
    samples: ArrayLike,
    candidates: tuple[str, ...] = UNBOUNDED_CANDIDATES,
    *,
    prefer_normal: bool = True,
) -> DistributionFit:
    """The fitted family of one marginal.

    Parameters
    ----------
    samples, candidates
        As for :func:`~pm_joint.distributions.families.fit_best`.
    prefer_normal
        Apply :func:`chosen_fit` (when ``"norm"`` is a candidate); ``False``: the
        AICc-best candidate, the choice before the rule.

    Returns
    -------
    DistributionFit
        The chosen fit; its ``family`` says which.
    """
    ranked = fit_best(samples, candidates, "aicc")
    if not prefer_normal or "norm" not in candidates:
        return ranked[0]
    return chosen_fit(ranked, int(np.size(samples)))


def _normal(ranked: Sequence[DistributionFit]) -> DistributionFit:
    for fit in ranked:
        if fit.family == "norm":
            return fit
    raise ValueError(f"no normal fit among {[f.family for f in ranked]}")
