"""The campaign driver the null, swap and term-group studies share: campaigns drawn in turn
over truths and curve counts, one typed row each, timed, handed to a progress callback.

A study gives the driver its truths (named by what the rig's preset is called), a judge
that turns one :class:`Campaign` into a row, and gets the rows back in campaign order.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Self

from identification.criticism.config import Verdict
from identification.measurements.backbone import BackboneSet
from identification.model import JointModel
from identification.rig import RIG_PRESETS
from studies.campaigns import draw_lab_campaign
from studies.rows import Row

__all__ = [
    "QUIET_VERDICTS",
    "Campaign",
    "CampaignRow",
    "is_discovery",
    "run_campaigns",
]

#: Verdicts that propose nothing: anything else, on a campaign whose truth has the
#: criticised structure, is a false discovery.
QUIET_VERDICTS = (Verdict.NOTHING_MISSING, Verdict.DRIFT)


def is_discovery(verdict: str) -> bool:
    """Whether a criticism's verdict proposes something (not one of :data:`QUIET_VERDICTS`)."""
    return verdict not in QUIET_VERDICTS


@dataclass(frozen=True)
class Campaign:
    """One campaign of a study: its truth and the lab campaign drawn for it.

    Attributes
    ----------
    index
        The campaign's place in the study (it seeds the campaign's draw).
    truth_name
        The truth as the study names it (a key of its truths).
    truth
        The rig preset's model.
    n_curves
        Assemblies measured.
    n_levels
        Levels per branch.
    conditions
        The lab conditions present (:data:`~studies.campaigns.NULL_CONDITIONS`).
    measured
        The simulated campaign.
    """

    index: int
    truth_name: str
    truth: JointModel
    n_curves: int
    n_levels: int
    conditions: tuple[str, ...]
    measured: BackboneSet


@dataclass(frozen=True, kw_only=True)
class CampaignRow(Row):
    """The fields every campaign row starts with; each study's row adds its own.

    ``seconds`` is the campaign's time from its simulation to its row, set by
    :func:`run_campaigns`.
    """

    campaign: int
    truth: str
    n_curves: int
    n_levels: int
    conditions: tuple[str, ...]
    seconds: float = float("nan")

    _JSON_KEYS: ClassVar[Mapping[str, str]] = {"n_levels": "levels"}

    @classmethod
    def of(cls, campaign: Campaign, **fields: Any) -> Self:
        """The row of ``campaign`` with a study's own ``fields``."""
        return cls(
            campaign=campaign.index,
            truth=campaign.truth_name,
            n_curves=campaign.n_curves,
            n_levels=campaign.n_levels,
            conditions=campaign.conditions,
            **fields,
        )


def run_campaigns[R: CampaignRow](
    campaigns: int,
    truths: Sequence[str],
    curve_counts: Sequence[int],
    seed: int,
    preset: Callable[[str], str],
    judge: Callable[[Campaign], R],
    progress: Callable[[R], None] | None = None,
) -> list[R]:
    """Draw ``campaigns`` lab campaigns and judge each.

    Truths are taken in turn, curve counts in turn per round of truths; each campaign
    draws its lab conditions and its levels from its own seed
    (:func:`~studies.campaigns.draw_lab_campaign`), so a run of any length mixes clean
    and artefact-laden campaigns over every truth and curve count.

    Parameters
    ----------
    campaigns
        Number of campaigns.
    truths
        The study's truths, by its names.
    curve_counts
        Assemblies per campaign, in turn.
    seed
        Seed of the study.
    preset
        The rig preset (:data:`~identification.rig.RIG_PRESETS`) of a truth's name.
    judge
        The study's judgement of one campaign: its row (``seconds`` is set here).
    progress
        Called with each row as it is done.

    Returns
    -------
    list
        The rows, in campaign order.
    """
    rows = []
    for k in range(campaigns):
        name = truths[k % len(truths)]
        n_curves = curve_counts[(k // len(truths)) % len(curve_counts)]
        truth = RIG_PRESETS[preset(name)].model
        began = time.perf_counter()
        conditions, n_levels, measured = draw_lab_campaign(truth, n_curves, seed, k)
        campaign = Campaign(k, name, truth, n_curves, n_levels, conditions, measured)
        row = dataclasses.replace(judge(campaign), seconds=time.perf_counter() - began)
        rows.append(row)
        if progress is not None:
            progress(row)
    return rows
