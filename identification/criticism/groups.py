"""Groups: what the data cannot tell apart, and what measurement would.

Two kinds (:class:`Groups`): **ambiguity groups** of proposed candidates whose fitted
signatures the data cannot separate (:func:`separation` below :data:`SEPARATION`; a
ranking inside a group is not a finding), and **model-term groups**: a term of the
criticised model that catalogue effects it lacks reproduce in its place on these data
(refitted there, :class:`~identification.criticism.records.Trial`) — a "cannot tell"
statement, never a proposal. Each comes with what would separate its members
(:meth:`Groups.what_separates`).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
from scipy.linalg import solve_triangular

from identification.criticism.adequacy import NEARBY_MODE
from identification.criticism.config import (
    LINEAR_PAIR,
    MAX_TERM_REFITS,
    SEPARATION,
    TERM_OVERLAP,
)
from identification.criticism.decision import Decision, separation
from identification.criticism.readings import CHANNEL_LABELS
from identification.criticism.records import Group, TermGroup, Trial
from identification.criticism.refits import Refits
from identification.criticism.words import separates_nearby_mode
from identification.fitting.data import BACKBONE_CHANNELS, HARMONIC_ORDERS
from identification.fitting.least_squares import FitResult, default_free
from identification.model import JointModel

if TYPE_CHECKING:
    from identification.criticism.candidates import Ranking

__all__ = ["Groups"]


class Groups:
    """The ambiguity groups and the model-term groups of one criticism."""

    def __init__(self, decision: Decision, refits: Refits, ranking: Ranking) -> None:
        self.decision = decision
        self.refits = refits
        self.ranking = ranking

    # ------------------------------------------------------- ambiguity groups
    @cached_property
    def groups(self) -> list[Group]:
        """Groups of proposed candidates the data cannot separate (each of two or more)."""
        decision = self.decision
        remaining = self.ranking.missing()
        out = []
        while remaining:
            best = max(remaining, key=lambda c: c.delta_chi2)
            members = [best] + [c for c in remaining if c is not best
                                and separation(decision, best, c) < SEPARATION]  # fmt: skip
            if len(members) > 1:
                out.append(
                    Group(
                        tuple(c.effect for c in members),
                        {c.effect: separation(decision, best, c) for c in members[1:]},
                        self.what_separates([(c.effect, c.fit.model) for c in members]),
                    )
                )
            remaining = [c for c in remaining if c not in members]
        for c in self.ranking.missing():
            if c.alternative:
                out.append(Group((c.effect, NEARBY_MODE), {}, separates_nearby_mode(c.fit.model)))
        return out

    def what_separates(self, members: Sequence[tuple[str, JointModel]]) -> str:
        """What measurement would separate the group (each member a name and its fitted
        model, the first against each other), from where the fitted models' predictions
        differ most relative to today's standard errors: a wider amplitude range, the
        harmonics (their size or phase, or the records' harmonics where the backbones carry
        none), or more accurate damping or frequency."""
        first, *rest = members
        return "; ".join(dict.fromkeys(self._separating(first, other) for other in rest))

    def _separating(self, first: tuple[str, JointModel], other: tuple[str, JointModel]) -> str:
        data = self.decision.data
        a_lo, a_hi = data.levels_m[0], data.levels_m[-1]
        outside = np.concatenate([np.geomspace(a_lo / 4, a_lo, 4)[:-1],
                                  np.geomspace(a_hi, 3 * a_hi, 4)[1:]])  # fmt: skip
        channels = BACKBONE_CHANNELS + tuple(
            f"harmonic{h}_{p}" for h in HARMONIC_ORDERS for p in ("cos", "sin")
        )
        se = np.full((data.levels_m.size, len(channels)), data.noise_floor["harmonics"])
        for j, channel in enumerate(channels):
            if channel in data.channels and data.used[data.column(channel)]:
                se[:, j] = self.decision.standard_error[:, data.column(channel)]

        def predict(member: tuple[str, JointModel], amplitudes: np.ndarray) -> np.ndarray:
            return self.refits.fitter.predict(member[1], amplitudes, channels, method="multi")

        inside = np.abs(predict(first, data.levels_m) - predict(other, data.levels_m)) / se
        edges = np.vstack([np.repeat(se[:1], 3, axis=0), np.repeat(se[-1:], 3, axis=0)])
        beyond = np.abs(predict(first, outside) - predict(other, outside))[:, :2] / edges[:, :2]
        names = f"{first[0]} and {other[0]}"
        options = []
        if np.isfinite(beyond).any():
            i, j = np.unravel_index(np.nanargmax(beyond), beyond.shape)
            options.append((
                beyond[i, j] / 3,  # a test beyond today's range costs more: ask for more
                f"a wider amplitude range ({names} differ by {beyond[i, j]:.2g} standard "
                f"errors in {CHANNEL_LABELS[channels[j]][0]} at {1e3 * outside[i]:.2g} mm)",
            ))  # fmt: skip
        for j, (name, accuracy) in enumerate((("frequency", "frequency accuracy"),
                                              ("damping", "damping accuracy"))):  # fmt: skip
            options.append((
                np.nanmax(inside[:, j]),
                f"{accuracy} ({names} differ by at most {np.nanmax(inside[:, j]):.2g} standard "
                f"errors of today's mean {name})",
            ))  # fmt: skip
        harmonic = np.nanmax(inside[:, 2:], axis=0)
        j = int(np.argmax(harmonic))
        order, part = channels[2 + j][len("harmonic")], channels[2 + j].rsplit("_", 1)[1]
        what = (
            f"the {order}{'nd' if order == '2' else 'rd'} harmonic's "
            f"{'phase' if part == 'sin' else 'size'}, measured against a clean reference"
            if data.has_harmonics
            else "the 2nd and 3rd harmonics of the records (extract the backbones from them)"
        )
        options.append(
            (harmonic[j], f"{what} ({names} differ there by {harmonic[j]:.2g} standard errors)")
        )
        score, text = max(options, key=lambda o: o[0])
        if score < 0.5:
            return (
                f"nothing near this test: {names} coincide over and around its amplitudes "
                f"(at most {score:.1g} standard errors apart in any channel)"
            )
        return text

    # ------------------------------------------------------- model-term groups
    @cached_property
    def term_base(self) -> FitResult:
        """What the model-term trials compare with: the refitted base model, or with a
        posterior (whose median is judged as given) the model's structure refitted, as the
        stand-ins are."""
        base = self.decision.base
        return base if not self.refits.posterior else self.refits.structure(base.model)

    @cached_property
    def term_trials(self) -> list[Trial]:
        """The trials behind :attr:`term_groups`, one per model term and catalogue effect
        refitted in its place (:class:`~identification.criticism.records.Trial`). Terms the
        data do not need get no trial (one record with ``effect`` None says what removing
        them cost)."""
        decision = self.decision
        base = self.term_base
        model = base.model
        rivals = {t: self.term_rivals(t) for t in model.effects if t not in LINEAR_PAIR}
        rivals = {t: r for t, r in rivals.items() if r and model.coefficient(t) != 0}
        if not rivals:
            return []
        chi2 = decision.chi2(base)
        removed = self.refits.structures([model.without(t) for t in rivals])
        cost = {t: decision.chi2(fit) - chi2 for t, fit in zip(rivals, removed, strict=True)}
        needed = [t for t in rivals if cost[t] >= decision.threshold]
        pairs = [(t, effect) for t in needed for effect in rivals[t]]
        fits = self.refits.structures([model.without(t).with_effect(e, 0.0) for t, e in pairs])
        before = decision.channel_chi2(base)
        trials = [Trial(t, None, cost[t]) for t in rivals if t not in needed]
        for (term, effect), fit in zip(pairs, fits, strict=True):
            why = "; ".join(decision.objections(fit, before))
            gain = chi2 - decision.chi2(fit)
            standing = not why and gain > -SEPARATION
            trials.append(Trial(term, effect, cost[term], gain, why, standing, fit))
        return trials

    @cached_property
    def term_groups(self) -> list[TermGroup]:
        """The model's own terms that catalogue effects it lacks reproduce on these data.

        For each term beyond the linear pair (:data:`LINEAR_PAIR`) that the data need —
        removing it and refitting the rest costs at least the calibrated threshold, the
        gain that would make it significant were it missing (the swap step's rule for
        keeping an effect) — the catalogue effects whose linearised signature overlaps the
        term's (:meth:`term_rivals`) are refitted in its place (:attr:`term_trials`).
        Those that fit no worse than :data:`SEPARATION` below the model (the data cannot
        tell the term from them, or prefer them: :attr:`TermGroup.favoured`), are
        admissible and make no channel worse beyond its noise
        (:meth:`Decision.objections`) form a group with the term, with what would separate
        them. Each stand-in replaces the one term: where several of the model's terms
        together reproduce an effect, each is tried alone (e.g. SINDy's x³ and ẋ² for an
        exponential spring: either one's replacement by it fits as well).

        A group is a "cannot tell" statement, never a proposal: the verdict and the
        proposed effects do not depend on it. With a posterior the comparison is with the
        model's structure refitted, as the stand-ins are.
        """
        model = self.term_base.model
        out = []
        for term in dict.fromkeys(t.term for t in self.term_trials):
            standing = [t for t in self.term_trials if t.term == term and t.standing]
            if not standing:
                continue
            fits = {t.effect: t.fit for t in standing}
            members = [(f"the model's {term}", model)] + [(e, f.model) for e, f in fits.items()]
            out.append(
                TermGroup(
                    term, model.coefficient(term), standing[0].needed, (term, *fits),
                    {t.effect: -t.delta_chi2 for t in standing},
                    self.what_separates(members), fits,
                )
            )  # fmt: skip
        return out

    def term_rivals(self, term: str) -> list[str]:
        """Catalogue effects the model lacks whose linearised signature may stand in for
        ``term``'s: both off the model's other parameters (whitened, as the statistics see
        them), the squared cosine between the term's coefficient column and the effect's
        best shape column at least :data:`TERM_OVERLAP`; :data:`MAX_TERM_REFITS` at most,
        best first (none when the term's coefficient is not a free parameter)."""
        decision = self.decision
        problem = decision.problem
        free = list(decision.base.free) or default_free(decision.base.model)
        if term not in free or not problem.candidates.shape[1]:
            return []
        factor = decision.observed.frame["factor"]
        white = solve_triangular(factor, np.hstack([problem.base, problem.candidates]), lower=True)
        own, columns = white[:, : len(free)], white[:, len(free) :]
        others = own[:, [i for i, n in enumerate(free) if n.split(".")[0] != term]]

        def off(x: np.ndarray) -> np.ndarray:
            return x - others @ np.linalg.lstsq(others, x, rcond=None)[0]

        signature, columns = off(own[:, free.index(term)]), off(columns)
        norms = np.sum(columns**2, axis=0) * (signature @ signature)
        with np.errstate(divide="ignore", invalid="ignore"):
            overlap = np.where(norms > 0, (signature @ columns) ** 2 / norms, 0.0)
        best: dict[str, float] = {}
        for direction, value in zip(problem.directions, overlap, strict=True):
            best[direction.effect] = max(best.get(direction.effect, 0.0), float(value))
        ranked = sorted((e for e in best if best[e] >= TERM_OVERLAP), key=lambda e: -best[e])
        return ranked[:MAX_TERM_REFITS]
