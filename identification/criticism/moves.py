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

from identification.criticism.adequacy import fitted_problems
from identification.criticism.config import SEPARATION, STOP_SHARE
from identification.criticism.ending import Added, Stop, loop_end, problems_of
from identification.criticism.records import SwapTrial
from identification.effects import get_effect
from identification.fitting.least_squares import FitResult

if TYPE_CHECKING:
    from identification.criticism.criticism import Criticism

__all__ = ["Add", "Swap", "SwapTerm", "run_rounds"]

#: The rule a replacement is kept by (the swap step's and the model-term swap's).
REPLACE_IF = f"gain > {SEPARATION:.4g}, admissible, no channel worse"
#: The rule a removal is kept by (the calibrated threshold filled in).
REMOVE_IF = "cost < {threshold:.4g}, admissible"


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

    ``stand_ins``: terms of the model that a model-term group of the criticism before this
    round's addition paired with the effect added (a SINDy start's ẋ² for x²). The data
    could not do without them before; with the effect in, each is tried for removal by the
    same rule as an earlier effect (no replacement: the effect just added is it), so a
    stand-in the effect makes redundant does not stay beside it.
    """

    alternatives: Mapping[str, Sequence[str]]
    last: str
    stand_ins: Sequence[str] = ()

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
        earlier_effects = [e for e in self.alternatives if e in model and e != self.last]
        stand_ins = [t for t in self.stand_ins if t in model and t not in earlier_effects]
        for earlier in [*earlier_effects, *stand_ins]:
            without = crit.refits.structure(model.without(earlier))
            cost = decision.chi2(without) - chi2
            why = "; ".join(fitted_problems(crit.data, without))
            trials.append(SwapTrial(earlier, None, -cost, False, why, REMOVE_IF.format(
                threshold=decision.threshold)))  # fmt: skip
            fits.append(without)
            for other in self.alternatives.get(earlier, ()):
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
            i for i, t in enumerate(trials)
            if t.add is None and not t.why and -t.delta_chi2 < decision.threshold
        ]  # fmt: skip
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


def run_rounds(crit: Criticism, rounds: int, min_share: float = STOP_SHARE) -> list[Criticism]:
    """Forward-backward stepwise selection from ``crit``: up to ``rounds`` effects added,
    and a loop that stops.

    A term of the model that the data prefer a catalogue effect in place of
    (:class:`SwapTerm`, e.g. a SINDy start's ẋ² for x²) is replaced when nothing is
    proposed, or unless the first proposal's addition gains more ``χ²`` than the swap by
    :data:`SEPARATION` (within it the moves cannot be told apart, and the swap adds no
    parameter): a round of its own that adds no effect (at most ``rounds`` such swaps).
    Otherwise a round adds the effect proposed first (:meth:`Criticism.missing`,
    :class:`Add`), then runs the swap step (:class:`Swap`) over the effects added in
    earlier rounds and the model's terms that a model-term group paired with the effect
    just added (its stand-ins: tried for removal, so that an effect found beside a term
    that stood in for it does not leave the term behind). The loop stops
    (:class:`~identification.criticism.ending.Stop`) when the calibrated test does not
    fire; when it fires and nothing is proposed (no admissible candidate captures enough of
    the free-form reference's gain: the rest is not shaped like any candidate); when the
    first proposed candidate captures less than ``min_share`` of the reference's gain on
    the current model (the gain left); when the next model (the addition with its swap,
    or a model-term swap) is inadmissible, keeping the last admissible one; or after
    ``rounds`` additions. Nothing is ever added on trial: each effect the final model
    holds explained at least ``min_share`` of what was left when it came in.

    Returns
    -------
    list of Criticism
        The criticism of each model the loop kept, ``crit`` first; the last one's
        ``rounds`` hold every round's report, with its swaps, and its ``loop_end`` the
        final answer (:class:`~identification.criticism.ending.LoopEnd`; the last one is
        a shallow copy of the criticism it ends on, so a criticism handed in is left as
        it was).
    """
    chain = [crit]
    alternatives: dict[str, list[str]] = {}
    added: list[Added] = []
    n_added = term_swaps = 0
    while True:
        crit = chain[-1]
        proposed = crit.missing()
        # The better move first: a term the data prefer a catalogue effect in place of
        # (beyond SEPARATION) is replaced when nothing is proposed, or unless the first
        # proposal's addition gains more than the swap by SEPARATION (within it the data
        # cannot tell the two moves apart, and the swap adds no parameter). Added beside a
        # stand-in, an effect is judged against it: a SINDy start's ẋ² beside which x²,
        # linearised, looks small while another spring's shape is proposed.
        swapped = SwapTerm().apply(crit) if term_swaps < rounds else None
        if swapped is not None and proposed:
            swap_gain = next(t.delta_chi2 for t in swapped.swaps if t.kept)
            if (proposed[0].delta_chi2 or 0.0) - swap_gain > SEPARATION:
                swapped = None
        refused = problems_of(swapped) if swapped is not None else ()
        if swapped is not None and not refused:
            step = swapped.history[-1]
            how = f"in place of the model's {', '.join(step.removed)}"
            added += [Added(e, None, None, how) for e in step.added]
            chain.append(swapped)
            term_swaps += 1
            continue
        if not proposed:
            if not crit.significant:
                stop, why = Stop.NOTHING_MISSING, "the calibrated test does not fire"
            else:
                stop = Stop.NOT_SHAPED
                why = (
                    "no admissible catalogue candidate captures enough of the free-form gain "
                    f"to be proposed (the best: {_percent(crit.explained_share)})"
                )
            if refused:
                why += f"; the model-term swap was refused: {'; '.join(refused)}"
            break
        best = proposed[0]
        if best.share is not None and best.share < min_share:
            stop = Stop.BELOW_SHARE
            why = (
                f"the next candidate, {best.effect}, captures {_percent(best.share)} of the "
                f"gain left, below {_percent(min_share)}"
            )
            break
        if n_added >= rounds:
            stop = Stop.ROUNDS
            why = (
                f"{rounds} effect{'s' if rounds != 1 else ''} added; next proposed: "
                f"{best.effect} ({_percent(best.share)} of the gain left)"
            )
            break
        effect = best.effect
        alternatives[effect] = crit.alternatives(effect)
        stand_ins = tuple(g.term for g in crit.term_groups if effect in g.alternatives)
        following = Swap(alternatives, effect, stand_ins).apply(Add(effect).apply(crit))
        refused = problems_of(following)
        if refused:
            stop = Stop.INADMISSIBLE
            why = f"adding {effect} ends on an inadmissible model: {'; '.join(refused)}"
            break
        added.append(Added(effect, best.share, best.delta_chi2, "added"))
        step = following.history[-1]
        for effect_in, effect_out in zip(step.added[1:], step.removed, strict=False):
            share = next((a.share for a in reversed(added) if a.effect == effect_out), None)
            added.append(Added(effect_in, share, None, f"in place of {effect_out}"))
        chain.append(following)
        n_added += 1
    last = copy.copy(chain[-1])
    last.loop_end = loop_end(chain, added, stop, why, min_share)
    chain[-1] = last
    return chain


def _percent(share: float | None) -> str:
    return "all" if share is None else f"{100 * share:.0f} %"
