"""The catalogue's candidates judged: refitted, admissible, adequate, the share they
explain, and ranked.

:class:`Ranking` turns the decision's linearised gains into :class:`Candidate` records:
the significant effects (best gains first, :data:`MAX_REFITS` at most) are refitted
(:class:`~identification.criticism.refits.Refits`) and judged; the proposed ones the
data cannot separate from the best form the proposed group, fewest new parameters
first.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from functools import cached_property

import numpy as np

from identification.criticism.adequacy import admissibility, onset_only
from identification.criticism.config import (
    EXPLAINED,
    MAX_REFITS,
    PARTLY,
    SEPARATION,
    CriticismConfig,
    Verdict,
)
from identification.criticism.decision import Decision, separation
from identification.criticism.directions import mean_prediction
from identification.criticism.readings import _reading
from identification.criticism.records import Candidate
from identification.criticism.reference import explained_share
from identification.criticism.refits import Refits
from identification.criticism.words import nearby_mode_words

__all__ = ["Ranking"]


class Ranking:
    """Every candidate effect of one criticism, judged and ranked."""

    def __init__(
        self,
        decision: Decision,
        refits: Refits,
        candidate_effects: Sequence[str],
        config: CriticismConfig,
    ) -> None:
        self.decision = decision
        self.refits = refits
        self.candidate_effects = list(candidate_effects)
        self.config = config

    @cached_property
    def to_refit(self) -> list[str]:
        """Effects refitted: the significant ones (best gains first), or, when only the
        reference fires, the two best (for the share the catalogue captures)."""
        if not self.decision.significant:
            return []
        gains = self.decision.effect_gains
        order = sorted(gains, key=lambda e: -gains[e][0])
        chosen = [e for e in order if gains[e][0] > self.decision.threshold]
        return (chosen or order[:2])[:MAX_REFITS]

    def candidate(self, effect: str) -> Candidate:
        """``effect`` judged: refitted and judged when it is among :attr:`to_refit`."""
        decision, data, criterion = self.decision, self.decision.data, self.config.criterion
        gain, column = decision.effect_gains[effect]
        shape = dict(decision.problem.directions[column].shape)
        significant = gain > decision.threshold
        if effect not in self.to_refit:
            return Candidate(effect, gain, shape, significant, decision.base, criterion)
        fit = self.refits.extended(effect)
        base = self.refits.base(fit.method)
        amplitudes_m, channels = data.levels_m, data.channels
        ext = mean_prediction(data, fit.predicted)
        without = mean_prediction(data, base.predicted)
        signature = {c: ext[:, j] - without[:, j] for j, c in enumerate(channels)}
        before, after = decision.channel_chi2(base), decision.channel_chi2(fit)
        bounds = decision.calibration.channel_bounds
        # Worse beyond the noise: pushed beyond the calibrated scatter by more than χ²₁'s 1 %
        # quantile, and by more than the misfit it had (a channel already far off may move
        # while a second missing effect is still unexplained; doubling is not a trade-off).
        worse = decision.worse(before, fit)
        beyond = tuple(g for g in after if after[g] > bounds.get(g, np.inf))
        f, z = data.column("frequency_hz"), data.column("damping_ratio")
        problems = tuple(admissibility(fit.model, amplitudes_m, ext[:, f], ext[:, z]))
        if not fit.solved:
            problems = (fit.outcome_text, *problems)
        delta = decision.chi2(base) - decision.chi2(fit)
        share = explained_share(
            delta, fit.n_parameters - base.n_parameters, decision.observed.reference[0],
            decision.observed.reference_rank,
        )  # fmt: skip
        # No share where the reference gains nothing beyond noise: nothing left to capture.
        captured = 1.0 if share is None else share
        if problems or worse or not significant:
            status = "improves the fit but does not explain it"
        elif captured >= EXPLAINED and not beyond:
            status = Verdict.EXPLAINED
        elif captured >= PARTLY:
            status = Verdict.PARTLY_EXPLAINED
        else:
            status = Verdict.NOT_EXPLAINED
        # Admissible and adequate, yet showing only the onset of what identifies the effect:
        # a nearby mode fits as well, so the catalogue's physics is not a finding.
        onset = (
            onset_only(fit.model, amplitudes_m)
            if status in (Verdict.EXPLAINED, Verdict.PARTLY_EXPLAINED)
            else None
        )
        if onset:
            status = Verdict.PARTLY_EXPLAINED
        # The effect's own contribution (the rest of the refitted model kept) for the words.
        predict = self.refits.fitter.predict
        alone = predict(fit.model.without(effect), amplitudes_m, method=fit.method)
        own_points = predict(fit.model, amplitudes_m, method=fit.method) - alone
        own = own_points if np.isfinite(alone).all() else ext - without
        alternative = nearby_mode_words(onset, fit.model) if onset else ""
        return Candidate(
            effect=effect,
            gain=gain,
            shape=shape,
            significant=significant,
            base=base,
            criterion=criterion,
            fit=fit,
            delta_chi2=delta,
            delta_ic=float(
                fit.information_criterion(criterion) - base.information_criterion(criterion)
            ),
            channel_chi2={g: (before[g], after[g]) for g in after},
            problems=problems,
            worse=worse,
            beyond=beyond,
            share=share,
            status=status,
            signature=signature,
            reading=_reading(
                effect, fit.model, dict(zip(channels, own.T, strict=True)), data, problems
            )
            + (f"; OR with {alternative}" if onset else ""),
            alternative=alternative,
        )

    @cached_property
    def candidates(self) -> list[Candidate]:
        """Every candidate effect, best first: the proposed group (candidates the data cannot
        separate from the best one, fewest new parameters first), then the other refitted
        ones by their ``χ²`` gain — those that would do but that the data separate from the
        best are "not preferred" — then the rest by their linearised gain."""
        self.refits.prefetch(self.to_refit)
        tried = [self.candidate(e) for e in self.candidate_effects]
        refitted = sorted((c for c in tried if c.fit is not None), key=lambda c: -c.delta_chi2)
        proposable = [c for c in refitted if c.proposed]
        if proposable:
            group = set(self.group_of(proposable))
            first = sorted((c for c in proposable if c.effect in group),
                           key=lambda c: (c.n_new_parameters, -c.delta_chi2))  # fmt: skip
            rest = [
                dataclasses.replace(c, status="not preferred") if c.proposed else c
                for c in refitted
                if c.effect not in group
            ]
            refitted = first + rest
        others = sorted((c for c in tried if c.fit is None), key=lambda c: -c.gain)
        return refitted + others

    def group_of(self, proposed: list[Candidate]) -> list[str]:
        """The best proposed candidate and those the data cannot separate from it."""
        best = proposed[0]
        return [best.effect] + [
            c.effect for c in proposed[1:] if separation(self.decision, best, c) < SEPARATION
        ]

    def missing(self) -> list[Candidate]:
        """The effects proposed ("explained" or "partly explained"), best first."""
        if not self.decision.significant:
            return []
        return [c for c in self.candidates if c.proposed]

    @property
    def best(self) -> Candidate | None:
        """The first proposed candidate, else the refitted one with the largest share."""
        proposed = self.missing()
        if proposed:
            return proposed[0]
        refitted = [c for c in self.candidates if c.fit is not None and not c.problems]
        return max(refitted, key=lambda c: c.share or 0.0) if refitted else None

    @property
    def explained_share(self) -> float | None:
        """Share of the free-form reference's gain the best catalogue candidate captures
        (None when nothing is missing)."""
        if not self.decision.significant:
            return None
        best = self.best
        return 0.0 if best is None else best.share

    @property
    def verdict(self) -> Verdict:
        """The verdict (:class:`~identification.criticism.config.Verdict`)."""
        if not self.decision.significant:
            drift = any(d.significant for d in self.decision.drift)
            return Verdict.DRIFT if drift else Verdict.NOTHING_MISSING
        proposed = self.missing()
        if not proposed:
            return Verdict.NOT_EXPLAINED
        if proposed[0].status == Verdict.EXPLAINED:
            return Verdict.EXPLAINED
        return Verdict.PARTLY_EXPLAINED

    @property
    def provisional(self) -> Candidate | None:
        """The refitted candidate that would be proposed but for its share: significant,
        admissible, no channel worse beyond its noise, yet capturing less than
        :data:`PARTLY` of the reference's gain — what one of two missing effects looks
        like on its own (None when something is proposed or nothing qualifies)."""
        if self.missing():
            return None
        fitting = [
            c for c in self.candidates if c.fit is not None and c.status == Verdict.NOT_EXPLAINED
        ]
        return max(fitting, key=lambda c: c.delta_chi2) if fitting else None

    def alternatives(self, effect: str) -> list[str]:
        """What the swap step may put in place of ``effect`` once added: this round's
        other refitted, significant candidates (:data:`MAX_REFITS` at most), best ``χ²``
        gain first. Alone, each may be inadmissible or make a channel worse while a second
        effect is missing; the swap judges it beside that effect."""
        others = [
            c for c in self.candidates if c.effect != effect and c.fit is not None and c.significant
        ]
        return [c.effect for c in sorted(others, key=lambda c: -c.delta_chi2)]
