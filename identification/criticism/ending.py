"""The loop's end: why the stepwise loop stopped, what each added effect explains, and the
shape of what is left.

:func:`~identification.criticism.moves.run_rounds` stops adding (:class:`Stop`) when the
calibrated test no longer fires, when it fires but no admissible catalogue candidate
captures enough of the free-form reference's gain to be proposed (the rest is not shaped
like any candidate), when the next candidate explains less than :data:`STOP_SHARE` of the
gain that is left (the reference's gain on the current model), when the next model would
be inadmissible (:func:`~identification.criticism.adequacy.admissibility`: the loop keeps
the last admissible one), or when it has added the effects it was allowed. Its answer is
one :class:`LoopEnd`: each added effect with the share of the gain left that it explained
when it was added, the stop and its reason, the final verdict and p-value, and the free-form
reference's residual describing functions at the final model (:class:`Rest`).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import TYPE_CHECKING, Any

import numpy as np

from identification.criticism.adequacy import fitted_problems
from identification.criticism.config import STOP_SHARE, Verdict

if TYPE_CHECKING:
    from identification.criticism.criticism import Criticism

__all__ = ["STOP_SHARE", "Added", "LoopEnd", "Rest", "Stop", "loop_end", "problems_of"]


class Stop(StrEnum):
    """Why the loop stopped adding."""

    NOTHING_MISSING = "nothing missing"
    NOT_SHAPED = "not shaped like any candidate"
    BELOW_SHARE = "next candidate below the share"
    INADMISSIBLE = "next model inadmissible"
    ROUNDS = "rounds used"


@dataclass(frozen=True)
class Added:
    """An effect the final model holds beyond the start, and what it explained.

    Attributes
    ----------
    effect
        Catalogue name.
    share
        Share of the free-form reference's gain on the model it was added to (less its
        degrees of freedom) that its refit captured, as :attr:`Candidate.share`; None where
        that gain was within the noise. A swap step's replacement carries the share of the
        effect it replaced (it fits better in its place by more than ``SEPARATION``).
    delta_chi2
        ``χ²`` its addition gained (None for a replacement or a model-term swap).
    how
        ``"added"``, ``"in place of <effect>"`` (swap step) or ``"in place of the model's
        <term>"`` (model-term swap).
    """

    effect: str
    share: float | None
    delta_chi2: float | None
    how: str

    @property
    def text(self) -> str:
        share = "n/a" if self.share is None else f"{100 * self.share:.0f} %"
        return f"{self.effect} ({self.how}; {share} of the gain left when added)"

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.effect,
            "share": self.share,
            "delta_chi2": self.delta_chi2,
            "how": self.how,
            "text": self.text,
        }


@dataclass(frozen=True)
class Rest:
    """The shape of what the final model leaves: the free-form reference's correction of
    it, as equivalent stiffness and damping against amplitude (mass-normalised,
    :meth:`~identification.criticism.reference.FreeForm.describing`).

    Attributes
    ----------
    amplitude_mm
        The levels.
    stiffness, damping
        ``k_eq`` (1/s²) and ``c_eq`` (1/s) of the reference less the final model's.
    stiffness_share, damping_share
        The same over the final model's own ``k_eq`` and ``c_eq``.
    gain, degrees_of_freedom
        The reference's ``χ²`` gain over the final model and its degrees of freedom.
    fires
        Whether that gain is beyond its calibrated threshold.
    """

    amplitude_mm: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    stiffness_share: np.ndarray
    damping_share: np.ndarray
    gain: float
    degrees_of_freedom: int
    fires: bool

    @classmethod
    def of(cls, crit: Criticism) -> Rest:
        """The rest at ``crit``'s refitted model."""
        ref = crit.reference
        k_base, c_base = ref.describing(ref.base_frequency_hz, ref.base_damping_ratio)
        k_ref, c_ref = ref.describing(ref.frequency_hz, ref.damping_ratio)
        return cls(
            1e3 * ref.levels_m, k_ref - k_base, c_ref - c_base, k_ref / k_base - 1,
            c_ref / c_base - 1, ref.gain, ref.degrees_of_freedom, crit.fires["reference"],
        )  # fmt: skip

    @property
    def text(self) -> str:
        if not (np.isfinite(self.stiffness_share).any() and np.isfinite(self.damping_share).any()):
            return "no describing functions (the final model has no solution at the levels)"
        i = int(np.nanargmax(np.abs(self.stiffness_share)))
        j = int(np.nanargmax(np.abs(self.damping_share)))
        mm = self.amplitude_mm
        return (
            f"k_eq {100 * self.stiffness_share[i]:+.2g} % at {mm[i]:.2g} mm, c_eq "
            f"{100 * self.damping_share[j]:+.2g} % at {mm[j]:.2g} mm (largest departures over "
            f"{mm[0]:.2g}–{mm[-1]:.2g} mm); free-form Δχ² {self.gain:.3g} with "
            f"{self.degrees_of_freedom} dof, {'beyond' if self.fires else 'within'} its threshold"
        )

    def to_dict(self) -> dict[str, Any]:
        return {
            "amplitude_mm": self.amplitude_mm.tolist(),
            "k_eq": self.stiffness.tolist(),
            "c_eq": self.damping.tolist(),
            "k_eq_share": self.stiffness_share.tolist(),
            "c_eq_share": self.damping_share.tolist(),
            "gain": self.gain,
            "degrees_of_freedom": self.degrees_of_freedom,
            "fires": self.fires,
            "text": self.text,
        }


@dataclass(frozen=True)
class LoopEnd:
    """The loop's final answer (:func:`~identification.criticism.moves.run_rounds`).

    Attributes
    ----------
    equation
        The final model.
    added
        The effects it holds beyond the start, in the order they came in.
    stop, why
        Why the loop stopped, and in words (with the refused model's problems when the
        next one was inadmissible).
    verdict, verdict_text, p_value
        The final criticism's verdict and calibrated p-value.
    problems
        What makes the final model inadmissible (empty: admissible; non-empty only when
        the start already was and no move made it admissible).
    rest
        The shape of what is left.
    min_share
        The share threshold the loop ran with.
    """

    equation: str
    added: tuple[Added, ...]
    stop: Stop
    why: str
    verdict: Verdict
    verdict_text: str
    p_value: float
    problems: tuple[str, ...]
    rest: Rest
    min_share: float

    @property
    def admissible(self) -> bool:
        return not self.problems

    @property
    def smallest_share(self) -> float | None:
        """The smallest share an added effect explained when added (None: none known)."""
        shares = [a.share for a in self.added if a.share is not None]
        return min(shares) if shares else None

    def lines(self) -> list[str]:
        """One line per item, as the summary prints them."""
        out = [f"loop end: {self.stop} ({self.why})", f"loop end: final model {self.equation}"]
        out += [f"loop end: added {a.text}" for a in self.added] or ["loop end: nothing added"]
        out.append(f"loop end: verdict {self.verdict_text} (p = {self.p_value:.2g})")
        out.append(
            "loop end: admissible"
            if self.admissible
            else f"loop end: NOT admissible: {'; '.join(self.problems)}"
        )
        out.append(f"loop end: rest {self.rest.text}")
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "equation": self.equation,
            "added": [a.to_dict() for a in self.added],
            "stop": str(self.stop),
            "why": self.why,
            "verdict": str(self.verdict),
            "verdict_text": self.verdict_text,
            "p_value": self.p_value,
            "admissible": self.admissible,
            "problems": list(self.problems),
            "smallest_share": self.smallest_share,
            "min_share": self.min_share,
            "rest": self.rest.to_dict(),
        }


def problems_of(crit: Criticism) -> tuple[str, ...]:
    """What makes ``crit``'s refitted model inadmissible as physics (empty: admissible)."""
    return tuple(fitted_problems(crit.data, crit.base))


def loop_end(
    chain: list[Criticism], added: list[Added], stop: Stop, why: str, min_share: float
) -> LoopEnd:
    """The final answer of a loop that kept ``chain`` (its start first) and added
    ``added`` (those the final model still holds are kept, in order)."""
    last = chain[-1]
    model = last.base.model
    start = chain[0].model
    # the last time each effect the final model holds beyond the start came in
    last_in = {a.effect: a for a in added if a.effect in model and a.effect not in start}
    held = [a for a in added if last_in.get(a.effect) is a]
    return LoopEnd(
        model.equation(), tuple(held), stop, why, Verdict(last.verdict), last.verdict_text,
        float(last.p_value), problems_of(last), Rest.of(last), min_share,
    )  # fmt: skip
