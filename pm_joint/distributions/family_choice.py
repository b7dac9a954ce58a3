"""Which family a marginal of few samples gets: the normal, unless another is clearly better.

Ranked by AICc alone, the candidate families of a handful of samples are chosen by
likelihood only: every two-parameter family pays the same penalty, and on five values
drawn from a normal a skewed Gumbel fits best more often than the normal does. A skewed
marginal then moves the density's mode away from its median, and a posterior scored by
that density with it.

The rule (:func:`chosen_fit`): the normal is the default; the AICc-best other candidate
replaces it only when it beats the normal's AICc by more than a margin Δ(n)
(:func:`normal_margin_aicc`), set so that on ``n`` samples drawn from a normal a
non-normal family is chosen for :data:`FALSE_CHOICE_RATE` of the marginals. Up to
:data:`TWO_PARAMETER_UP_TO` samples only the candidates of two parameters (location and
scale) compete with the normal: a third parameter, the t's degrees of freedom, cannot be
told from the normal's tails in so few samples, and on normal samples it only adds false
choices (where the t competes its fit can only widen the gap; ``t_decides`` in
``bench/results/family_choice.json`` counts those choices at fifty samples).

Calibration (``bench/family_choice.py``): the gap ``AICc(norm) − min AICc(other)`` of
the two-parameter candidates does not depend on the normal's mean and spread (each is a
location-scale family, fitted by maximum likelihood), so its distribution under the
normal depends on ``n`` alone. The bench draws standard-normal samples on tuning seeds
at every n = 4…30 and :data:`MARGIN_BY_N` is the gap's ``1 − FALSE_CHOICE_RATE``
quantile at each (a table, not a curve: a first smooth law, fitted to noisier quantiles,
failed its held-out check at two sizes; ``docs/updating.md``). Beyond thirty samples every candidate
competes with the margin at thirty. The false-choice rate (normal samples that get
another family) and the power (skewed samples that get a skewed family of the right
side) are measured, beside plain AICc, on held-out seeds:
``bench/results/family_choice.json``.

For a subset of the candidates the same margin keeps the rate at or below
:data:`FALSE_CHOICE_RATE` (the best of fewer alternatives beats the normal less often);
for other candidate sets (bounded families) it is not calibrated. With three samples or
fewer AICc is undefined for every family, and the normal is taken.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from pm_joint.distributions.families import (
    UNBOUNDED_CANDIDATES,
    DistributionFit,
    fit_best,
)

__all__ = [
    "FALSE_CHOICE_RATE",
    "MARGIN_BY_N",
    "TWO_PARAMETER_UP_TO",
    "choose_family",
    "chosen_fit",
    "competitors",
    "normal_gap_aicc",
    "normal_margin_aicc",
]

#: The share of normal samples for which the rule chooses another family.
FALSE_CHOICE_RATE = 0.05

#: Up to this many samples only two-parameter candidates compete with the normal.
TWO_PARAMETER_UP_TO = 30

#: Δ(n) for n = 4, 5, …, :data:`TWO_PARAMETER_UP_TO`: the gap's ``1 − FALSE_CHOICE_RATE``
#: quantile on standard-normal samples against the two-parameter candidates of
#: :data:`~pm_joint.distributions.families.UNBOUNDED_CANDIDATES` (tuning seeds,
#: ``bench/family_choice.py --stage tune``, which prints this table and writes it with the
#: sample counts to ``bench/results/family_choice_tuning.json``).
MARGIN_BY_N: tuple[float, ...] = (
    1.74, 2.137, 2.393, 2.56, 2.768, 2.9, 3.135, 3.309, 3.207, 3.329, 3.441, 3.465, 3.77, 3.714,
    3.661, 3.639, 3.77, 3.934, 3.943, 3.835, 3.793, 3.786, 3.828, 3.889, 3.888, 3.973, 3.783,
)  # fmt: skip


def normal_margin_aicc(n_samples: int) -> float:
    """Δ(n): how much lower than the normal's another family's AICc must be to replace it.

    Parameters
    ----------
    n_samples
        Number of samples the families are fitted to.

    Returns
    -------
    float
        :data:`MARGIN_BY_N` at ``n``, its last entry beyond :data:`TWO_PARAMETER_UP_TO`;
        infinite below four samples (AICc is undefined for two parameters there).
    """
    if n_samples < 4:
        return float("inf")
    return float(MARGIN_BY_N[min(int(n_samples), TWO_PARAMETER_UP_TO) - 4])


def competitors(candidates: Sequence[str], n_samples: int) -> tuple[str, ...]:
    """The candidates that compete with the normal on ``n_samples`` samples.

    Parameters
    ----------
    candidates
        scipy.stats family names.
    n_samples
        Number of samples.

    Returns
    -------
    tuple of str
        Up to :data:`TWO_PARAMETER_UP_TO` samples the location-scale families alone (no
        shape parameter); beyond, every candidate.
    """
    if n_samples > TWO_PARAMETER_UP_TO:
        return tuple(candidates)
    return tuple(c for c in candidates if getattr(stats, c).numargs == 0)


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
        Apply :func:`chosen_fit` among the :func:`competitors` (when ``"norm"`` is a
        candidate); ``False``: the AICc-best candidate, the choice before the rule.

    Returns
    -------
    DistributionFit
        The chosen fit; its ``family`` says which.
    """
    if not prefer_normal or "norm" not in candidates:
        return fit_best(samples, candidates, "aicc")[0]
    n_samples = int(np.size(samples))
    return chosen_fit(fit_best(samples, competitors(candidates, n_samples), "aicc"), n_samples)


def _normal(ranked: Sequence[DistributionFit]) -> DistributionFit:
    for fit in ranked:
        if fit.family == "norm":
            return fit
    raise ValueError(f"no normal fit among {[f.family for f in ranked]}")
