"""The oracle test: is one named catalogue effect there?

The criticism's catalogue test searches every candidate column (every effect over its
shape grid) for the largest ``χ²`` gain; a user who already suspects one effect can test
that effect alone. :func:`oracle` is that test: the same linearised score statistic
(:func:`~identification.criticism.calibration.statistics`) restricted to the named
effect's own columns (its shape grid included, the largest gain over it taken), with no
free-form reference, calibrated by the same parametric bootstrap
(:func:`~identification.criticism.calibration.calibrate`, same ``alpha``, bootstrap size
and seed) under the same refitted base model. The search and the oracle then differ only
in what they search over; the oracle's threshold is the lower, and the gap between the
two is the price of not knowing which effect to test (see ``docs/criticism.md``, power).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from identification.criticism import calibration as cal
from identification.criticism.decision import Decision

__all__ = ["OracleTest", "oracle", "restricted"]


@dataclass(frozen=True)
class OracleTest:
    """The oracle's test of one effect against one campaign.

    Attributes
    ----------
    effect
        The effect tested.
    gain
        The largest ``χ²`` gain over the effect's columns (linearised at the refitted base).
    threshold
        Its calibrated threshold: a null campaign exceeds it with probability ``alpha``.
    p_value
        Bootstrap p-value of ``gain``.
    alpha, n_bootstrap, seed
        The calibration's level, bootstrap campaigns and seed (the search's own).
    columns
        Columns of the effect (its shape grid).
    """

    effect: str
    gain: float
    threshold: float
    p_value: float
    alpha: float
    n_bootstrap: int
    seed: int
    columns: int

    @property
    def detects(self) -> bool:
        """Whether the effect is detected at level ``alpha``."""
        return self.gain > self.threshold


def restricted(problem: cal.Problem, effect: str) -> cal.Problem:
    """``problem`` with only ``effect``'s candidate columns and no free-form reference."""
    columns = [i for i, d in enumerate(problem.directions) if d.effect == effect]
    if not columns:
        raise ValueError(
            f"{effect!r} is not a candidate of this criticism (the model holds it, or it is "
            f"not in the catalogue); candidates: {', '.join(problem.effects())}"
        )
    return dataclasses.replace(
        problem,
        candidates=problem.candidates[:, columns],
        directions=[problem.directions[i] for i in columns],
        reference=problem.reference[:, :0],
        reference_channels=[],
    )


def oracle(decision: Decision, effect: str) -> OracleTest:
    """Test ``effect`` alone against the campaign of ``decision`` (a criticism's
    :attr:`~identification.criticism.criticism.Criticism.decision`).

    Parameters
    ----------
    decision
        The criticism's statistics: its refitted base model, metric and settings.
    effect
        A catalogue effect the criticised model lacks.

    Returns
    -------
    OracleTest
        Gain, calibrated threshold and p-value of the effect's own columns.
    """
    problem = restricted(decision.problem, effect)
    observed = cal.statistics(problem, problem.residual[None], problem.metric.covariance.mean[None])
    config = decision.config
    calibration = cal.calibrate(
        problem, observed, alpha=config.alpha, n_bootstrap=config.n_bootstrap, seed=config.seed
    )
    gain = float(observed.catalogue[0])
    null = calibration.null_catalogue
    return OracleTest(
        effect=effect,
        gain=gain,
        threshold=calibration.catalogue_threshold,
        p_value=float((1 + np.sum(null >= gain)) / (null.size + 1)),
        alpha=config.alpha,
        n_bootstrap=config.n_bootstrap,
        seed=config.seed,
        columns=len(problem.directions),
    )
