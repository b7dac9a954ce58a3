"""The stepwise moves of the criticism loop, each one object with one method.

- :class:`Add`: the model with a catalogue effect added and everything refitted;
- :class:`Swap`: the backward/swap step over the effects earlier rounds added;
- :class:`SwapTerm`: the swap step for the model's own terms (a model-term group's
  favoured stand-in in the term's place).

``move.apply(crit)`` returns the criticism of the changed model (its history and rounds
continue ``crit``'s), or for a swap that changes nothing ``crit`` carrying the trials.
:func:`run_rounds` is the forward-backward stepwise loop built from them.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

from identification.criticism.config import SEPARATION
from identification.criticism.records import SwapTrial
from identification.effects import get_effect
from identification.fitting.least_squares import FitResult

if TYPE_CHECKING:
    from identification.criticism.criticism import Criticism

__all__ = ["Add", "Swap", "SwapTerm", "run_rounds"]

#: The rule a replacement is kept by (the swap step's and the model-term swap's).
REPLACE_IF = f"gain > {SEPARATION:.4g}, admissible, no channel worse"


@dataclass(frozen=True)
class Add:
    """Add ``effect`` (``shape``: start values of its fit, e.g. ``k_t=…``) and refit."""

    effect: str
    shape: Mapping[str, float] = field(default_factory=dict)

    def apply(self, crit: Criticism) -> Criticism:
        """The criticism of ``crit``'s model with the effect added and everything refitted.

        Raises
        ------
        ValueError
            If the effect is not in the catalogue or already in the model.
        """
        effect = self.effect
        get_effect(effect)
        if effect in crit.model:
            raise ValueError(
                f"effect {effect!r} is already in the model ({', '.join(crit.model.effects)})"
            )
        fit = crit.refits.extended(effect, **self.shape)
        return crit.successor(
            fit, [c for c in crit.candidate_effects if c != effect], crit.rounds, f"+ {effect}",
            added=(effect,),
        )  # fmt: skip


@dataclass(frozen=True)
class Swap:
    """The backward/swap step of forward-backward stepwise selection.

    For each effect added in an earlier round (a key of ``alternatives`` still in the
    model, not ``last``, the one this round added): refit the model without it, and
    with it replaced by each of its ``alternatives``. Judged by the same statistic as
    the add step, the criticism's ``χ²`` in its metric: the effect is removed when
    removing it costs less than the calibrated threshold (added back, it would not be
    significant); it is replaced when a replacement gains more than :data:`SEPARATION`
    (the data tell the two apart), is admissible and makes no channel worse beyond its
    noise. The best replacement wins over a removal; one change per round.
    """

    alternatives: Mapping[str, Sequence[str]]
    last: str

    def apply(self, crit: Criticism) -> Criticism:
        """Every trial is recorded in ``swaps`` of the criticism returned: a copy of
        ``crit`` when nothing changed (``crit``'s own are left as they were), else the
        criticism of the changed model."""
        decision, base = crit.decision, crit.base
        model = base.model
        chi2 = decision.chi2(base)
        before = decision.channel_chi2(base)
        trials: list[SwapTrial] = []
        fits: list[FitResult] = []
        for earlier in [e for e in self.alternatives if e in model and e != self.last]:
            without = crit.refits.structure(model.without(earlier))
            cost = decision.chi2(without) - chi2
            trials.append(
                SwapTrial(earlier, None, -cost, keep_if=f"cost < {decision.threshold:.4g}")
            )
            fits.append(without)
            for other in self.alternatives[earlier]:
                if other in model:
                    continue
                fit = crit.refits.structure(model.without(earlier).with_effect(other, 0.0))
                why = "; ".join(decision.objections(fit, before))
                trials.append(SwapTrial(earlier, other, chi2 - decision.chi2(fit), False, why,
                                        REPLACE_IF))  # fmt: skip
                fits.append(fit)
        replacements = [
            i for i, t in enumerate(trials)
            if t.add is not None and not t.why and t.delta_chi2 > SEPARATION
        ]  # fmt: skip
        removals = [
            i for i, t in enumerate(trials) if t.add is None and -t.delta_chi2 < decision.threshold
        ]
        if replacements:
            chosen = max(replacements, key=lambda i: trials[i].delta_chi2)
        elif removals:
            chosen = max(removals, key=lambda i: trials[i].delta_chi2)
        else:
            # The same model, carrying the trials: a shallow copy shares the refits and the
            # calibration already computed, and leaves this criticism's swaps as they were.
            unchanged = copy.copy(crit)
            unchanged.swaps = trials
            return unchanged
        trials[chosen] = change = replace(trials[chosen], kept=True)
        candidates = [c for c in crit.candidate_effects if c != change.add]
        step = crit.history[-1]
        return crit.successor(
            fits[chosen],
            [*candidates, change.remove],
            crit.previous_rounds,
            f"{step.action}; swap {change.words}",
            trials,
            crit.history[:-1],  # the swapped model takes this round's step
            added=(*step.added, *([change.add] if change.add else [])),
            removed=(*step.removed, change.remove),
        )


@dataclass(frozen=True)
class SwapTerm:
    """The swap step for the model's own terms: the term replaced by the catalogue effect
    its model-term group says the data prefer (:attr:`TermGroup.favoured`: it fits better
    by more than :data:`SEPARATION`, is admissible and makes no channel worse beyond its
    noise — the rule :class:`Swap` keeps a replacement by); the largest gain when several
    qualify.

    A start the user brought (e.g. SINDy's ẋ² where the structure holds x², terms the
    backbones hardly tell apart) is corrected the way an added effect is; how often a
    stand-in is favoured over a true term is measured by ``bench/criticism_terms.py``.
    """

    def apply(self, crit: Criticism) -> Criticism | None:
        """The criticism with the term swapped, every group's trials recorded in its
        ``swaps``; None when no group favours a stand-in."""
        term_groups = crit.term_groups
        favoured = [(g, e) for g in term_groups for e in g.favoured]
        if not favoured:
            return None
        group, effect = min(favoured, key=lambda pair: pair[0].separation[pair[1]])
        trials = [
            SwapTrial(g.term, e, -g.separation[e], (g, e) == (group, effect), "", REPLACE_IF)
            for g in term_groups
            for e in g.alternatives
        ]
        candidates = [c for c in crit.candidate_effects if c != effect]
        return crit.successor(
            group.fits[effect],
            [*candidates, group.term],
            crit.rounds,
            f"swap − {group.term} + {effect}",
            trials,
            added=(effect,),
            removed=(group.term,),
        )


def run_rounds(crit: Criticism, rounds: int) -> list[Criticism]:
    """Forward-backward stepwise selection from ``crit``: up to ``rounds`` effects added.

    Each round adds the effect proposed first (:meth:`Criticism.missing`, :class:`Add`),
    then runs the swap step (:class:`Swap`) over the effects added in earlier rounds.
    When nothing is proposed, a term of the model that the data prefer a catalogue effect
    in place of (:class:`SwapTerm`, e.g. a SINDy start's ẋ² for x²) is replaced first, as
    a round of its own that adds no effect (at most ``rounds`` such swaps). When nothing
    is proposed but a provisional candidate exists (two effects missing: neither explains
    enough alone), it is added on trial and kept only when the next round's verdict is
    "explained" (an effect that, beside it, explains the data: two additions); otherwise
    the loop stops.

    Returns
    -------
    list of Criticism
        The criticism of each model the loop kept, ``crit`` first; the last one's
        ``rounds`` hold every round's report, with its swaps.
    """
    chain = [crit]
    alternatives: dict[str, list[str]] = {}
    added = term_swaps = 0
    while added < rounds:
        crit = chain[-1]
        proposed = crit.missing()
        if not proposed:
            swapped = SwapTerm().apply(crit) if term_swaps < rounds else None
            if swapped is not None:
                chain.append(swapped)
                term_swaps += 1
                continue
            trial = crit.provisional
            if trial is None or added + 2 > rounds:
                break
            tried = Add(trial.effect).apply(crit)
            # kept only when the pair explains the data: out-of-catalogue physics, which
            # catalogue terms partly mimic one after another, is not fitted term by term
            if tried.verdict != "explained":
                break
            alternatives[trial.effect] = crit.alternatives(trial.effect)
            chain.append(tried)
            added += 1
            continue
        effect = proposed[0].effect
        alternatives[effect] = crit.alternatives(effect)
        chain.append(Swap(alternatives, effect).apply(Add(effect).apply(crit)))
        added += 1
    return chain
