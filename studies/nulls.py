"""The null study: the false-discovery rate of the calibrated decision over many fast null
campaigns, each criticised with its truth's own structure (anything found is a false
discovery)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from identification.criticism.criticism import criticize
from identification.effects.coulomb_friction import EFFECT as COULOMB_FRICTION
from identification.effects.quadratic_stiffness import EFFECT as QUADRATIC_STIFFNESS
from identification.rig.presets import lab_hidden_scenario
from studies.driver import Campaign, CampaignRow, is_discovery, run_campaigns

__all__ = ["NULL_TRUTHS", "NullRow", "null_study"]

#: Truths of the null campaigns (the criticised model has each truth's structure): the
#: study's name → the rig preset.
NULL_TRUTHS: dict[str, str] = {
    "linear": "lab-pure",
    "hardening": "lab-all-hardening",
    "friction": lab_hidden_scenario(COULOMB_FRICTION.name),
    "arch": lab_hidden_scenario(QUADRATIC_STIFFNESS.name),
    "joint": "trc-like",
}


@dataclass(frozen=True, kw_only=True)
class NullRow(CampaignRow):
    """One null campaign criticised with its truth's structure.

    Attributes
    ----------
    verdict, p_value
        The criticism's verdict and p-value.
    catalogue_gain, catalogue_threshold
        The best catalogue candidate's gain and its calibrated threshold.
    reference_gain, reference_threshold, reference_dof
        The reference test's gain, calibrated threshold and degrees of freedom.
    false_discovery
        The verdict proposes something (:func:`~studies.driver.is_discovery`).
    proposed
        The effects proposed, ranked.
    """

    verdict: str
    p_value: float
    catalogue_gain: float
    catalogue_threshold: float
    reference_gain: float
    reference_threshold: float
    reference_dof: int
    false_discovery: bool
    proposed: tuple[str, ...]


def null_study(
    campaigns: int,
    *,
    truths: Sequence[str] = tuple(NULL_TRUTHS),
    curve_counts: Sequence[int] = (1, 3, 5, 10),
    seed: int = 0,
    progress: Callable[[NullRow], None] | None = None,
    **options: Any,
) -> list[NullRow]:
    """``campaigns`` null campaigns, each criticised with its truth's structure.

    Truths and curve counts are taken in turn, and each campaign draws its lab
    conditions (:data:`~studies.campaigns.NULL_CONDITIONS`, each present with probability
    ½, and 5, 6 or 8 levels per branch) from its own seed
    (:func:`~studies.driver.run_campaigns`).

    Parameters
    ----------
    campaigns
        Number of campaigns.
    truths
        Keys of :data:`NULL_TRUTHS`.
    curve_counts
        Assemblies per campaign, in turn.
    seed
        Seed of the study.
    progress
        Called with each row as it is done.
    **options
        Passed to :func:`identification.criticism.criticism.criticize`.

    Returns
    -------
    list of NullRow
        A row per campaign with the verdict and whether it is a false discovery.
    """

    def judge(campaign: Campaign) -> NullRow:
        crit = criticize(campaign.truth, campaign.measured, **options)
        return NullRow.of(
            campaign,
            verdict=crit.verdict,
            p_value=crit.p_value,
            catalogue_gain=float(crit.observed.catalogue[0]),
            catalogue_threshold=crit.calibration.catalogue_threshold,
            reference_gain=float(crit.observed.reference[0]),
            reference_threshold=crit.calibration.reference_threshold,
            reference_dof=crit.observed.reference_rank,
            false_discovery=is_discovery(crit.verdict),
            proposed=tuple(c.effect for c in crit.missing()),
        )

    return run_campaigns(
        campaigns, truths, curve_counts, seed, NULL_TRUTHS.__getitem__, judge, progress
    )
