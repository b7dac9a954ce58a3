"""The hidden-effect study: a rig scenario (ideal or lab) through the criticism loop, from the
start a user has — the bare linear model, a SINDy-identified one, or the preset's base model
(the truth minus what is hidden) — and whether the loop finds what the rig hid.

Its outcome categories and their rules are :class:`~studies.outcomes.HiddenOutcome` (a
scenario that hides effects), :class:`~studies.outcomes.NullOutcome` (nothing hidden) and
:class:`~studies.outcomes.OutsideOutcome` (physics out of the catalogue), each judged on
the loop's end state; ``docs/studies.md`` gives them in words."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from identification.criticism.criticism import Criticism, criticize
from identification.criticism.moves import run_rounds
from identification.effects import CATALOGUE, LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.fitting.least_squares import FitResult
from identification.measurements.backbone import BackboneSet
from identification.measurements.records import Record
from identification.model import JointModel
from identification.rig import RIG_PRESETS
from identification.rig.presets import LAB_OUT_OF_CATALOGUE_SCENARIOS
from studies.campaigns import first_fit, rig_campaign
from studies.driver import is_discovery
from studies.outcomes import HiddenOutcome, NullOutcome, OutsideOutcome
from studies.rows import EndState
from studies.seeds import is_held_out

__all__ = [
    "KEY_CHANNEL",
    "START_LIBRARY",
    "StudyResult",
    "criticism_study",
    "scenario_kind",
]


#: The channel whose error a hidden effect must take down (by ≥ 80 %) in the studies, per
#: scenario that hides effects: the key channel its (first) hidden effect's module states
#: (:attr:`~identification.effects.base.HiddenScenario.key_channel`). Damping effects leave
#: the frequency at the noise level already; even effects (x², ẋ², x·ẋ) show in the second
#: harmonic of the records, which the backbone alone misses.
KEY_CHANNEL: dict[str, str] = {
    name: CATALOGUE[preset.hidden_effects[0]].hidden_scenario.key_channel
    for name, preset in RIG_PRESETS.items()
    if preset.hidden_effects and CATALOGUE[preset.hidden_effects[0]].hidden_scenario is not None
}
_STEP_RMSE = {
    "frequency_hz": "frequency_rmse_hz",
    "damping_ratio": "damping_rmse",
    "harmonics": "harmonic_rmse",
}
#: The library of a SINDy start: every monomial up to cubic in (x, ẋ), what a pysindy
#: user starts from (:data:`identification.sindy.POLYNOMIAL_LIBRARY`).
START_LIBRARY = "polynomial"


def scenario_kind(scenario: str) -> str:
    """``"null"`` (nothing to find), ``"hidden"`` (a catalogue effect hidden) or
    ``"out of catalogue"``."""
    if scenario in LAB_OUT_OF_CATALOGUE_SCENARIOS:
        return "out of catalogue"
    return "hidden" if RIG_PRESETS[scenario].hidden_effects else "null"


def _bare_linear(model: JointModel) -> JointModel:
    return JointModel(
        {e: model.coefficient(e) for e in (LINEAR_STIFFNESS, VISCOUS_DAMPING)},
        name="linear",
    )


@dataclass
class StudyResult:
    """One rig scenario run through the criticism loop from one start.

    Keeps the measured backbones, the records and the start model, so the same
    data can be criticised again another way.
    """

    scenario: str
    seed: int
    start_kind: str
    truth: JointModel
    hidden: tuple[str, ...]
    measured: BackboneSet
    records: list[Record]
    start: JointModel
    criticisms: list[Criticism] = field(default_factory=list)
    seconds: float = float("nan")

    @property
    def kind(self) -> str:
        return scenario_kind(self.scenario)

    @property
    def history(self):
        return self.criticisms[-1].history

    @property
    def added(self) -> list[str]:
        """The effects the loop added, in order (a swap's replacement after its round's),
        as each step records them (:attr:`~identification.criticism.criticism.Step.added`)."""
        return [effect for step in self.history for effect in step.added]

    @property
    def kept(self) -> list[str]:
        """The effects the last model holds beyond the start (after every swap)."""
        return [e for e in self.criticisms[-1].base.model.effects if e not in self.start]

    @property
    def first(self) -> str | None:
        """The effect ranked first by the first criticism (None: nothing proposed)."""
        proposed = self.criticisms[0].missing()
        return proposed[0].effect if proposed else None

    @property
    def verdict(self) -> str:
        """The first criticism's verdict."""
        return self.criticisms[0].verdict

    @property
    def end_state(self) -> EndState:
        """Where the loop ended: its last model, verdict and p-value."""
        return EndState.of(self.criticisms[-1])

    def _round_of(self, effect: str) -> int | None:
        """The first round whose proposed effect or group holds ``effect``."""
        for k, crit in enumerate(self.criticisms):
            proposed = crit.missing()
            if not proposed:
                return None
            group = next((g.effects for g in crit.groups if proposed[0].effect in g.effects),
                         (proposed[0].effect,))  # fmt: skip
            if effect in group:
                return k
        return None

    @property
    def in_start(self) -> bool:
        """Whether the start model already holds every hidden effect (SINDy found them)."""
        return bool(self.hidden) and all(e in self.start for e in self.hidden)

    @property
    def hit(self) -> bool | None:
        """Hidden scenarios: every hidden effect the start lacks is ranked first or in the
        first group of a round, with only effects of the truth added before; or the last
        model (after the loop's swaps and trial additions) holds every one of them and no
        effect beyond the truth's (None for other kinds)."""
        if self.kind != "hidden":
            return None
        missing = [e for e in self.hidden if e not in self.start]
        # forward-backward: the last model holds them, and only effects of the truth
        kept = self.kept
        if missing and all(e in kept for e in missing) and all(e in self.truth for e in kept):
            return True
        rounds = [self._round_of(e) for e in missing]
        if any(r is None for r in rounds):
            return False
        wrong = [e for e in self.added[: max(rounds, default=0)] if e not in self.truth]
        return not wrong

    @cached_property
    def stand_ins(self) -> dict[str, str]:
        """Hidden rows: per hidden effect the start lacks, the start's term that the first
        criticism's model-term groups pair it with — a term of the start standing in for
        it (e.g. SINDy's ẋ² for x²) — whether the start is adequate or not (empty on
        other rows, and for effects no group holds)."""
        if self.kind != "hidden" or self.in_start:
            return {}
        groups = self.criticisms[0].term_groups
        found = {}
        for effect in (e for e in self.hidden if e not in self.start):
            group = next((g for g in groups if effect in g.alternatives), None)
            if group is not None:
                found[effect] = group.term
        return found

    @cached_property
    def _reference_fit(self) -> FitResult:
        """What a hidden effect's worth is measured from: the first criticism's refitted
        start, less the terms standing in for a hidden effect (:attr:`stand_ins`, the rest
        refitted). A stand-in already takes part of the effect's error down; measured from
        a start that holds one, the effect found would be credited only with what the
        stand-in left."""
        crit = self.criticisms[0]
        model = crit.base.model
        for term in dict.fromkeys(self.stand_ins.values()):
            model = model.without(term)
        return crit.base if model == crit.base.model else crit.refits.structure(model)

    def reduction(self, channel: str) -> float | None:
        """Fractional RMSE reduction of a channel from the first criticism's refitted model
        (less its :attr:`stand_ins`, refitted) to the last one's."""
        before = getattr(self._reference_fit, _STEP_RMSE[channel])
        after = getattr(self.criticisms[-1].base, _STEP_RMSE[channel])
        return None if before is None or after is None else float(1 - after / before)

    @property
    def false_discovery(self) -> bool | None:
        """Null scenarios: the first criticism says something is missing, or the loop added
        an effect (None otherwise)."""
        if self.kind != "null":
            return None
        return is_discovery(self.verdict) or bool(self.added)

    @property
    def start_adequate(self) -> bool:
        """Hidden scenarios: the start lacks a hidden effect by name (not :attr:`in_start`),
        yet its first criticism is :attr:`~identification.criticism.criticism.Criticism.adequate`
        — nothing significant, and the refitted start's residual within the calibrated
        scatter in every channel group, the same test a proposed candidate must pass. The
        start's own terms reproduce the hidden effect on these data (e.g. SINDy's x², x³
        and ẋ² terms an exponential spring): it is not missing from this start, so the row
        is neither a hit nor a miss."""
        if self.kind != "hidden" or self.in_start:
            return False
        return self.criticisms[0].adequate

    @property
    def truth_gap(self) -> float | None:
        """Start-adequate rows: the largest gap between the rig's truth and the refitted
        start, in standard errors of the measured mean (None on other rows). Both are
        predicted at the data's amplitude levels by a multi-harmonic balance driven by the
        measured excitation; frequency and damping are taken less their gap at the lowest
        level (the drawn assemblies' offsets, not the hidden effect). The ground truth's view
        of what the start may still miss below the criticism's calibrated bounds: beyond the
        where-bound it would be a missed effect, not an adequate start."""
        if not self.start_adequate:
            return None
        crit = self.criticisms[0]
        data = crit.data
        truth = crit.predict_at(self.truth, data.levels_m, method="multi")
        start = crit.predict_at(crit.base.model, data.levels_m, method="multi")
        gap = truth - start
        for channel in ("frequency_hz", "damping_ratio"):
            j = data.column(channel)
            gap[:, j] -= gap[0, j]
        se = np.column_stack([crit.residual(c)[1] for c in data.channels])
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.abs(gap) / se
        return float(np.nanmax(z[:, data.used]))

    @property
    def term_group(self) -> dict[str, str] | None:
        """Start-adequate rows: per hidden effect the start lacks, the start's term that the
        first criticism's model-term groups
        (:attr:`~identification.criticism.criticism.Criticism.term_groups`) say it is
        consistent with; None unless every one of them is in such a group."""
        if not self.start_adequate:
            return None
        found = self.stand_ins
        lacked = [e for e in self.hidden if e not in self.start]
        return found if all(e in found for e in lacked) else None

    @cached_property
    def _linear_fit(self) -> FitResult:
        """The bare linear model refitted to the first criticism's data."""
        crit = self.criticisms[0]
        return crit.refits.structure(_bare_linear(crit.base.model))

    def _linear_rmse(self, channel: str) -> float | None:
        return getattr(self._linear_fit, _STEP_RMSE[channel])

    def term_reduction(self, channel: str) -> float | None:
        """Rows with a :attr:`term_group` of one hidden effect: fractional RMSE reduction of
        a channel from the bare linear model (refitted to these data) to the start with the
        hidden effect in place of the term it is grouped with (as the group refitted it).
        Nothing is added on such a row (the start holds a stand-in already), so the effect's
        worth is measured against the model without any nonlinearity (None otherwise)."""
        found = self.term_group
        if found is None or len(found) != 1:
            return None
        ((effect, term),) = found.items()
        groups = self.criticisms[0].term_groups
        after = getattr(next(g for g in groups if g.term == term).fits[effect], _STEP_RMSE[channel])
        before = self._linear_rmse(channel)
        return None if before is None or after is None else float(1 - after / before)

    def start_reduction(self, channel: str) -> float | None:
        """Start-adequate rows: fractional RMSE reduction of a channel from the bare linear
        model (refitted to these data) to the refitted start (None on other rows)."""
        if not self.start_adequate:
            return None
        after = getattr(self.criticisms[0].base, _STEP_RMSE[channel])
        before = self._linear_rmse(channel)
        return None if before is None or after is None else float(1 - after / before)

    @property
    def _term_stands_in(self) -> bool:
        """Start-adequate rows: a model-term group of the start holds the hidden effect
        (:attr:`term_group`) and the effect in place of that term takes the key channel's
        error down ≥ 80 % from the bare linear model's (:meth:`term_reduction`)."""
        if self.term_group is None:
            return False
        key = self.term_reduction(KEY_CHANNEL[self.scenario])
        return key is not None and key >= 0.8

    def _found(self) -> bool:
        """The hit rule of :class:`~studies.outcomes.HiddenOutcome` for a start that is not
        adequate without the effect."""
        if self.in_start:
            return all(e in self.truth for e in self.added) and not (
                self.criticisms[-1].significant
            )
        key = self.reduction(KEY_CHANNEL[self.scenario])
        return bool(self.hit) and key is not None and key >= 0.8

    @property
    def outcome(self) -> HiddenOutcome | NullOutcome | OutsideOutcome:
        """The row's category, by its kind's rule (:mod:`studies.outcomes`): a
        :class:`~studies.outcomes.HiddenOutcome` where effects are hidden, a
        :class:`~studies.outcomes.NullOutcome` where nothing is, an
        :class:`~studies.outcomes.OutsideOutcome` out of the catalogue."""
        if self.kind == "null":
            return NullOutcome.FALSE_DISCOVERY if self.false_discovery else NullOutcome.QUIET
        if self.kind == "out of catalogue":
            return self._outside_outcome()
        if self.start_adequate:
            if not self._term_stands_in:
                return HiddenOutcome.START_ADEQUATE
            return HiddenOutcome.TERM_SWAPPED if self.hit else HiddenOutcome.TERM_GROUP
        if not self._found():
            return HiddenOutcome.MISS
        final = self.criticisms[-1].base.model
        replaced = self.stand_ins and not any(t in final for t in self.stand_ins.values())
        return HiddenOutcome.TERM_SWAPPED if replaced else HiddenOutcome.HIT

    def _outside_outcome(self) -> OutsideOutcome:
        if any(c.verdict == "explained" for c in self.criticisms):
            return OutsideOutcome.EXPLAINED
        final = self.criticisms[-1].verdict
        if final == "not explained by the catalogue":
            return OutsideOutcome.NOT_EXPLAINED
        if final == "partly explained":
            return OutsideOutcome.PARTLY_EXPLAINED
        return OutsideOutcome.QUIET_AT_END

    @property
    def passed(self) -> bool | None:
        """The row's pass rule on the loop's end state (:mod:`studies.outcomes`). Null:
        quiet (nothing proposed, nothing added). Hidden: a hit
        (:attr:`~studies.outcomes.HiddenOutcome.is_hit`); a miss fails; a start adequate
        without the effect (:attr:`~studies.outcomes.HiddenOutcome.TERM_GROUP`,
        :attr:`~studies.outcomes.HiddenOutcome.START_ADEQUATE`) is not judged (None): the
        effect is not missing from that start, yet it was not found either, so the hit
        rate counts the row in its denominator and never in its numerator. Out of
        catalogue: the loop ends "not explained by the catalogue" or "partly explained",
        and no round said "explained"."""
        outcome = self.outcome
        if isinstance(outcome, NullOutcome):
            return outcome is NullOutcome.QUIET
        if isinstance(outcome, OutsideOutcome):
            return outcome.said_unexplained
        if outcome in (HiddenOutcome.TERM_GROUP, HiddenOutcome.START_ADEQUATE):
            return None
        return outcome.is_hit

    def row(self) -> dict[str, Any]:
        """Table row of the study."""
        first = self.criticisms[0]
        groups = [list(g.effects) for g in first.groups]
        return {
            "scenario": self.scenario,
            "kind": self.kind,
            "seed": self.seed,
            "start": self.start_kind,
            "start_model": self.start.equation(),
            "hidden": list(self.hidden),
            "verdict": self.verdict,
            "explained_share": first.explained_share,
            "p_value": first.p_value,
            "threshold": first.threshold,
            "ranked_first": self.first,
            "groups": groups,
            "added": self.added,
            "kept": self.kept,
            "swaps": [s.to_dict() for c in self.criticisms for s in c.swaps if s.kept],
            "in_start": self.in_start,
            "start_adequate": self.start_adequate,
            "truth_gap_se": self.truth_gap,
            "term_groups": [
                {"term": g.term, "effects": list(g.alternatives), "separation": g.separation}
                for g in first.term_groups
            ],
            "term_group": self.term_group,
            "stand_ins": self.stand_ins or None,
            "term_reduction": {c: self.term_reduction(c) for c in _STEP_RMSE}
            if self.term_group
            else None,
            "start_reduction": {c: self.start_reduction(c) for c in _STEP_RMSE}
            if self.start_adequate
            else None,
            "beyond_scatter": list(first.beyond_scatter),
            "hit": self.hit,
            "frequency_rmse_hz": [c.base.frequency_rmse_hz for c in self.criticisms],
            "damping_rmse": [c.base.damping_rmse for c in self.criticisms],
            "harmonic_rmse": [c.base.harmonic_rmse for c in self.criticisms],
            "reduction": {c: self.reduction(c) for c in _STEP_RMSE},
            "key_channel": KEY_CHANNEL.get(self.scenario),
            "drift": [d.channel for d in first.drift if d.significant],
            "passed": self.passed,
            "outcome": str(self.outcome),
            "end_state": self.end_state.to_dict(),
            "seed_kind": "held-out" if is_held_out(self.seed) else "tuning",
            "seconds": self.seconds,
        }


def _start_model(
    start: str, scenario: str, records: Sequence[Record], measured: BackboneSet
) -> JointModel:
    preset = RIG_PRESETS[scenario]
    if start == "base":
        model = preset.base_model
    elif start == "linear":
        model = _bare_linear(preset.base_model)
    elif start == "sindy":
        from identification.sindy import POLYNOMIAL_LIBRARY, identify

        return identify(list(records)[:3], POLYNOMIAL_LIBRARY).model
    else:
        raise ValueError(f"start must be 'base', 'linear' or 'sindy', got {start!r}")
    return first_fit(model, measured)


def criticism_study(
    scenario: str,
    seed: int = 0,
    *,
    start: str = "base",
    assemblies: int = 3,
    levels: int = 8,
    hold_s: float = 2.5,
    rounds: int = 3,
    **options: Any,
) -> StudyResult:
    """Run a rig scenario through the loop: criticise the start model, add, repeat.

    The rig (:func:`~studies.campaigns.rig_campaign`, ideal or lab) draws ``assemblies``
    assemblies and their noise as :meth:`~identification.rig.Rig.write_campaign` does
    (seeds ``[seed, a]`` and ``[seed, a, 1]``) but keeps the records in memory. The
    start is fitted to the backbones alone (frequency and damping, as a user's first fit
    is; SINDy's own coefficients for ``"sindy"``); the criticism uses the harmonics the
    backbones carry too. The loop is forward-backward stepwise
    (:func:`~identification.criticism.criticism.run_rounds`): each round adds the effect
    proposed first and may swap out an effect an earlier round added, until nothing is
    proposed or ``rounds`` effects were added.

    Parameters
    ----------
    scenario
        A rig preset (:data:`~identification.rig.RIG_PRESETS`).
    seed
        Seed of the assemblies and their noise (:mod:`studies.seeds`: a reported figure
        comes from held-out seeds, ``≥ HELD_OUT_SEED``).
    start
        ``"base"``: the preset's base model, the truth minus what is hidden;
        ``"linear"``: the bare linear-viscous model; ``"sindy"``: SINDy on the first three
        records with the polynomial library (:data:`START_LIBRARY`).
    assemblies
        Records of the campaign.
    levels
        Number of excitation levels per record.
    hold_s
        Seconds of each hold.
    rounds
        Most effects the loop adds.
    **options
        Passed to :func:`identification.criticism.criticism.criticize`.

    Returns
    -------
    StudyResult
        The scenario's run, its criticisms one per round.
    """
    began = time.perf_counter()
    records, measured = rig_campaign(scenario, assemblies, (seed,), levels=levels, hold_s=hold_s)
    preset = RIG_PRESETS[scenario]
    model = _start_model(start, scenario, records, measured)
    result = StudyResult(
        scenario, seed, start, preset.model, preset.hidden_effects, measured, records, model
    )
    result.criticisms = run_rounds(criticize(model, measured, **options), rounds)
    result.seconds = time.perf_counter() - began
    return result
