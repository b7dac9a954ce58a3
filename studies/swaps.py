"""The swap study: how often the stepwise loop's swap step undoes a right addition, and how
often it corrects a wrong one, over lab-rig campaigns (by default; fast harmonic-balance
campaigns as a unit-level check)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Self

from identification.criticism.criticism import criticize
from identification.effects import (
    coulomb_friction,
    cubic_damping,
    cubic_stiffness,
    exponential,
    microslip,
    quadratic_damping,
    stribeck_friction,
    tanh_saturation,
    van_der_pol,
)
from identification.rig.presets import lab_hidden_scenario
from studies.driver import Campaign, CampaignRow, CampaignSource, run_campaigns
from studies.outcomes import SwapOutcome
from studies.rows import EndState, Row

__all__ = ["SWAP_TRUTHS", "SwapRow", "SwapTrial", "swap_study"]

#: Truths of the swap study: each catalogue effect of the lab scenarios that has a rival
#: the data may hardly tell from it (cubic hardening: tanh/exponential/microslip; the
#: damping laws among themselves; Coulomb and Stribeck friction), on the lab base model.
SWAP_TRUTHS: tuple[str, ...] = tuple(
    module.EFFECT.name
    for module in (
        cubic_stiffness,
        tanh_saturation,
        exponential,
        microslip,
        quadratic_damping,
        cubic_damping,
        van_der_pol,
        coulomb_friction,
        stribeck_friction,
    )
)


@dataclass(frozen=True)
class SwapTrial(Row):
    """One trial of the swap step: an effect in place of the one added (None: its removal),
    the ``χ²`` it gains, whether the step kept it, and why it is inadmissible ("" if not)."""

    add: str | None
    delta_chi2: float
    kept: bool
    why: str

    @classmethod
    def of(cls, trial: Any) -> Self:
        """The row of a :class:`~identification.criticism.records.SwapTrial` (a record of
        :attr:`~identification.criticism.criticism.Criticism.swaps`, or its stored dict)."""
        if isinstance(trial, Mapping):
            return cls(trial["add"], trial["delta_chi2"], trial["kept"], trial["why"])
        return cls(trial.add, trial.delta_chi2, trial.kept, trial.why)

    @property
    def decision(self) -> str:
        """The step's outcome when it keeps this trial: "replaced by <effect>" or "removed"."""
        return f"replaced by {self.add}" if self.add else "removed"


@dataclass(frozen=True, kw_only=True)
class SwapRow(CampaignRow):
    """One swap-study campaign (:func:`swap_study`); its ``truth`` is the effect ``B``.

    Attributes
    ----------
    wrong_first
        The side of the study: a rival of ``B`` added (power) or ``B`` itself.
    proposed_first
        The effect round 1 proposed first (None: nothing).
    groups
        Round 1's ambiguity groups.
    add_worse
        The channels flagged worse when round 1 refitted ``B`` (None: not refitted).
    added
        The effect added before the swap step (None: no decision on this campaign).
    added_was_proposed
        Round 1 proposed it.
    alternatives
        The replacements the swap step tried.
    trials
        The swap step's trials.
    best_replacement_gain
        The largest ``χ²`` gain of a replacement.
    decision
        "kept", "replaced by <effect>" or "removed".
    false_swap
        ``B`` added and a change kept (None on the power side).
    corrected
        The power side: ``B`` put in place of the rival (None on the other side).
    swap_veto
        The swap's trial of ``B`` was flagged worse in a channel (None: no such trial).
    end_state
        The model after the swap step, refitted, with its criticism's verdict and p-value
        (round 1's when nothing was added; None on a row written before it existed).
    """

    wrong_first: bool
    proposed_first: str | None
    groups: tuple[tuple[str, ...], ...] | None = None
    add_worse: tuple[str, ...] | None = None
    added: str | None = None
    added_was_proposed: bool = False
    alternatives: tuple[str, ...] | None = None
    trials: tuple[SwapTrial, ...] | None = None
    best_replacement_gain: float | None = None
    decision: str | None = None
    false_swap: bool | None = None
    corrected: bool | None = None
    swap_veto: bool | None = None
    end_state: EndState | None = None

    @property
    def outcome(self) -> SwapOutcome:
        """The decision's category (:class:`~studies.outcomes.SwapOutcome`)."""
        if self.decision is None:
            return SwapOutcome.NO_DECISION
        if self.decision.startswith("replaced"):
            return SwapOutcome.REPLACED
        return SwapOutcome(self.decision)

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Self:
        """A row as :meth:`to_dict` wrote it (keys a row of an earlier version lacks take
        their defaults; keys it does not know are left out)."""
        names = set(cls.__dataclass_fields__)
        fields = {v: k for k, v in cls._JSON_KEYS.items()}
        values = {fields.get(k, k): v for k, v in data.items()}
        values = {k: v for k, v in values.items() if k in names}
        for key in ("conditions", "add_worse", "alternatives"):
            if values.get(key) is not None:
                values[key] = tuple(values[key])
        if values.get("groups") is not None:
            values["groups"] = tuple(tuple(g) for g in values["groups"])
        if values.get("trials") is not None:
            values["trials"] = tuple(SwapTrial.of(t) for t in values["trials"])
        if values.get("end_state") is not None:
            values["end_state"] = EndState.from_dict(values["end_state"])
        return cls(**values)


def swap_study(
    campaigns: int,
    *,
    wrong_first: bool = False,
    truths: Sequence[str] = SWAP_TRUTHS,
    curve_counts: Sequence[int] = (1, 3, 5, 10),
    seed: int = 0,
    progress: Callable[[SwapRow], None] | None = None,
    source: CampaignSource = CampaignSource.LAB_RIG,
    **options: Any,
) -> list[SwapRow]:
    """The swap step's decisions (:meth:`~identification.criticism.criticism.Criticism.swap`)
    over ``campaigns`` campaigns (truths and curve counts in turn, drawn by
    :func:`~studies.driver.run_campaigns` from ``source``: the lab rig by default).

    Each campaign's truth is the lab base model plus one effect ``B`` (the preset
    ``lab-hidden-<B>``). Round 1 criticises the truth without ``B``; its significant
    refitted runners-up are the alternatives the swap may put in place of the effect
    added (:meth:`~identification.criticism.criticism.Criticism.alternatives`, as
    :func:`~identification.criticism.criticism.run_rounds` passes them).

    * ``wrong_first=False`` (the false-swap rate): ``B`` itself is added, so the model
      judged has the truth's structure; any change the swap keeps (a replacement or a
      removal of ``B``) is a false swap.
    * ``wrong_first=True`` (the power): round 1's best proposed candidate other than ``B``
      (what the loop could have added), else its best refitted significant one, is added
      instead; the swap corrects it when it puts ``B`` in its place.
      Campaigns where round 1 has no such candidate have no decision (``added`` None).

    The swap judges the effect added as it judges one an earlier round added (``last``
    names no effect here): the decision is the same, made one round earlier. Each row also
    says whether round 1 proposed ``B`` first, round 1's ambiguity groups, and the false
    vetoes of the truth: the channels :data:`~identification.criticism.criticism.WORSE`
    flags when ``B`` is refitted in round 1 (``add_worse``, None when ``B`` was not
    refitted), and, with ``wrong_first``, in the swap's trial of ``B`` (``swap_veto``).

    Parameters
    ----------
    campaigns
        Number of campaigns.
    wrong_first
        Add a rival of ``B`` first (the power) instead of ``B`` (the false-swap rate).
    truths
        The effects ``B``, in turn.
    curve_counts
        Assemblies per campaign, in turn.
    seed
        Seed of the study.
    progress
        Called with each row as it is done.
    source
        Where the campaigns come from (:class:`~studies.driver.CampaignSource`): the lab
        rig; the harmonic balance only as a fast unit-level check.
    **options
        Passed to :func:`identification.criticism.criticism.criticize`.

    Returns
    -------
    list of SwapRow
        A row per campaign.
    """

    def judge(campaign: Campaign) -> SwapRow:
        effect = campaign.truth_name
        first = criticize(campaign.truth.without(effect), campaign.measured, **options)
        proposed = [c.effect for c in first.missing()]
        refitted = {c.effect: c for c in first.candidates if c.fit is not None}
        added = effect
        if wrong_first:
            # what the loop could have added (proposed), else any significant runner-up
            rivals = [e for e in proposed if e != effect] or first.alternatives(effect)
            added = rivals[0] if rivals else None
        row = SwapRow.of(
            campaign,
            wrong_first=wrong_first,
            proposed_first=proposed[0] if proposed else None,
            groups=tuple(tuple(g.effects) for g in first.groups),
            add_worse=tuple(refitted[effect].worse) if effect in refitted else None,
            added=added,
            added_was_proposed=added in proposed,
        )
        if added is None:
            return dataclasses.replace(row, end_state=EndState.of(first))
        alternatives = first.alternatives(added)
        swapped = first.add(added).swap({added: alternatives}, last="")
        trials = tuple(SwapTrial.of(t) for t in swapped.swaps)
        change = next((t for t in trials if t.kept), None)
        truth_trial = [t for t in trials if t.add == effect]
        return dataclasses.replace(
            row,
            alternatives=tuple(alternatives),
            trials=trials,
            best_replacement_gain=max(
                (t.delta_chi2 for t in trials if t.add is not None), default=None
            ),
            decision="kept" if change is None else change.decision,
            false_swap=None if wrong_first else change is not None,
            corrected=(change is not None and change.add == effect) if wrong_first else None,
            swap_veto=("worse" in truth_trial[0].why) if truth_trial else None,
            end_state=EndState.of(swapped),
        )

    return run_campaigns(
        campaigns, truths, curve_counts, seed, lab_hidden_scenario, judge, progress, source
    )
