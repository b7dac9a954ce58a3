"""The criticism's records: where a model fails, a candidate effect and its judgement,
groups the data cannot separate, the trials of the model's own terms and of the swap
step, and one step of the loop. Each prints as a short summary; the arrays sit behind
its attributes."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from identification.criticism.config import SEPARATION, Verdict
from identification.criticism.readings import CHANNEL_LABELS
from identification.effects import get_effect
from identification.fitting.least_squares import FitResult

__all__ = [
    "Candidate",
    "FailureRange",
    "Group",
    "Step",
    "SwapTrial",
    "TermGroup",
    "Trial",
    "ranking_entry",
    "rmse_pairs",
]


@dataclass(frozen=True)
class FailureRange:
    """An amplitude range where the model misses the measurement beyond the calibrated bound.

    ``max_residual`` is measured minus predicted at the worst level, in the
    channel's SI unit (Hz, damping ratio, fraction of the fundamental for the
    harmonics, where it is the magnitude of the complex miss); ``max_z`` its
    standardised size (the bound is the criticism's ``where`` threshold).
    """

    channel: str
    from_mm: float
    to_mm: float
    max_residual: float
    direction: str
    max_z: float = float("nan")

    @property
    def text(self) -> str:
        name, unit, factor = CHANNEL_LABELS[self.channel]
        size = f"{abs(self.max_residual) * factor:.2g} {unit}"
        span = (
            f"at {self.from_mm:.2g} mm"
            if self.from_mm == self.to_mm
            else f"between {self.from_mm:.2g} and {self.to_mm:.2g} mm"
        )
        if self.channel.startswith("harmonic"):
            return f"the {name} of the response is {self.direction} by up to {size} {span}"
        return f"{name} is {self.direction} by up to {size} {span}"

    def __str__(self) -> str:
        return self.text

    def __repr__(self) -> str:
        return f"<FailureRange: {self.text} ({self.max_z:.3g} standard errors)>"

    def to_dict(self) -> dict[str, Any]:
        return {
            "channel": self.channel,
            "from_mm": self.from_mm,
            "to_mm": self.to_mm,
            "max_residual": self.max_residual,
            "max_z": self.max_z,
            "direction": self.direction,
            "text": self.text,
        }


@dataclass(frozen=True)
class Candidate:
    """A catalogue effect tried against the data.

    Attributes
    ----------
    effect
        Catalogue name.
    gain
        The decision statistic of this effect: the linearised ``χ²`` gain of its best
        column (over its shape grid) at the refitted base model.
    shape
        Shape values of that column.
    significant
        ``gain`` above the calibrated catalogue threshold.
    fit, base
        The nonlinear refit with the effect (None where it was not refitted) and the
        refitted base model (same harmonic-balance method).
    delta_chi2
        ``χ²(base) − χ²(fit)`` in the likelihood's metric (None without a refit).
    delta_ic, criterion
        The fits' information-criterion change (descriptive only; decisions are calibrated).
    channel_chi2
        Post-fit ``χ²`` per channel group, before and after: ``{group: (before, after)}``.
    problems
        What makes the fit inadmissible as physics (empty: admissible).
    worse
        Channel groups the effect makes worse beyond their noise.
    beyond
        Channel groups whose residual stays beyond the calibrated scatter after adding it
        (empty: adequate).
    share
        Share of the free-form reference's gain it captures.
    status
        ``"explained"``, ``"partly explained"`` (the proposed group), ``"not preferred"``
        (it would do, but the data prefer the proposed group), ``"improves the fit but
        does not explain it"`` (inadmissible, a channel worse, or not significant on its
        own), ``"not explained by the catalogue"`` (too small a share) or
        ``"not significant"``.
    signature
        Per channel at the levels: the mean prediction with the effect minus without it.
    reading
        What it does in this test and what it is consistent with (:mod:`.readings`).
    alternative
        Why physics outside the catalogue fits as well, in words (empty: nothing said):
        a slip element whose onset alone is in the test
        (:func:`~identification.criticism.adequacy.onset_only`) is never "explained".
    """

    effect: str
    gain: float
    shape: dict[str, float]
    significant: bool
    base: FitResult
    criterion: str
    fit: FitResult | None = None
    delta_chi2: float | None = None
    delta_ic: float | None = None
    channel_chi2: dict[str, tuple[float, float]] = field(default_factory=dict)
    problems: tuple[str, ...] = ()
    worse: tuple[str, ...] = ()
    beyond: tuple[str, ...] | None = None
    share: float | None = None
    status: str = "not significant"
    signature: dict[str, np.ndarray] = field(default_factory=dict)
    reading: str = ""
    alternative: str = ""

    @property
    def proposed(self) -> bool:
        return self.status in (Verdict.EXPLAINED, Verdict.PARTLY_EXPLAINED)

    def __repr__(self) -> str:
        """One line of numbers, then the reading: ``<Candidate microslip: explained,
        ΔBIC −41, Δχ² 52, 93 % of the free-form gain>``."""
        if self.fit is None:
            return (
                f"<Candidate {self.effect}: {self.status}, linearised Δχ² {self.gain:.3g} "
                "(not refitted)>"
            )
        share = "" if self.share is None else f", {100 * self.share:.0f} % of the free-form gain"
        text = (
            f"<Candidate {self.effect}: {self.status}, Δ{self.criterion.upper()} "
            f"{self.delta_ic:+.3g}, Δχ² {self.delta_chi2:.3g}{share}"
        )
        return text + (f"\n  {self.reading}>" if self.reading else ">")

    __str__ = __repr__

    @property
    def adequate(self) -> bool | None:
        """Residual within the calibrated scatter in every channel group after adding it."""
        return None if self.beyond is None else not self.beyond

    @property
    def n_new_parameters(self) -> int:
        return 0 if self.fit is None else self.fit.n_parameters - self.base.n_parameters

    @property
    def error_reduction(self) -> dict[str, float]:
        """Fractional RMSE reduction per channel against the refitted base model."""
        if self.fit is None:
            return {}
        return {
            key: float(1.0 - after / before) if before > 0 else 0.0
            for key, before, after in rmse_pairs(self.base, self.fit)
        }

    def to_dict(self) -> dict[str, Any]:
        out = {
            "effect": self.effect,
            "status": str(self.status),
            "gain": self.gain,
            "shape": self.shape,
            "significant": self.significant,
            "proposed": self.proposed,
        }
        if self.fit is None:
            return out
        pairs = list(rmse_pairs(self.base, self.fit))
        return out | {
            "delta_chi2": self.delta_chi2,
            "explained_share": self.share,
            "adequate": self.adequate,
            "beyond_scatter": list(self.beyond or ()),
            "admissible": not self.problems,
            "problems": list(self.problems),
            "worse": list(self.worse),
            "channel_chi2": {k: list(v) for k, v in self.channel_chi2.items()},
            "error_reduction": self.error_reduction,
            "delta_information_criterion": self.delta_ic,
            "criterion": self.criterion,
            "reading": self.reading,
            "alternative": self.alternative,
            "rmse_before": {k: b for k, b, _ in pairs},
            "rmse_after": {k: a for k, _, a in pairs},
            "parameters": self.fit.model.parameters,
            "equation": self.fit.model.equation(),
            "signature": {k: v.tolist() for k, v in self.signature.items()},
        }


def rmse_pairs(before: FitResult, after: FitResult):
    for key, attribute in (("frequency_hz", "frequency_rmse_hz"), ("damping_ratio", "damping_rmse"),
                           ("harmonics", "harmonic_rmse")):  # fmt: skip
        b, a = getattr(before, attribute), getattr(after, attribute)
        if b is not None and a is not None:
            yield key, float(b), float(a)


@dataclass(frozen=True)
class Group:
    """Candidates the data cannot separate, and what would."""

    effects: tuple[str, ...]
    separation: dict[str, float]
    separated_by: str

    @property
    def text(self) -> str:
        return (
            f"the data cannot separate {', '.join(self.effects)} (a ranking among them is not "
            f"a finding); what would: {self.separated_by}"
        )

    def __str__(self) -> str:
        return self.text

    def __repr__(self) -> str:
        return f"<Group: {self.text}>"

    def to_dict(self) -> dict[str, Any]:
        return {
            "effects": list(self.effects),
            "separation": self.separation,
            "separated_by": self.separated_by,
            "text": self.text,
        }


@dataclass(frozen=True)
class TermGroup:
    """A term of the criticised model that catalogue effects it lacks reproduce on these
    data (:attr:`Criticism.term_groups`): a "cannot tell" statement, never a proposal.

    Attributes
    ----------
    term
        The model's effect.
    coefficient
        Its fitted coefficient.
    needed
        ``χ²`` the model loses when the term is removed and the rest refitted (at least the
        calibrated threshold: the data need it).
    effects
        The term, then the catalogue effects that stand in for it.
    separation
        Per stand-in: ``χ²`` of the model with it in place of the term (refitted) less the
        model's: below :data:`SEPARATION` (it fits as well as the term or better; at
        ``−SEPARATION`` or below the data prefer it: :attr:`favoured`).
    separated_by
        What measurement would tell them apart.
    fits
        Per stand-in: the refitted model with it in place of the term.
    """

    term: str
    coefficient: float
    needed: float
    effects: tuple[str, ...]
    separation: dict[str, float]
    separated_by: str
    fits: dict[str, FitResult] = field(default_factory=dict, compare=False, repr=False)

    @property
    def alternatives(self) -> tuple[str, ...]:
        return self.effects[1:]

    @property
    def favoured(self) -> tuple[str, ...]:
        """Stand-ins that fit better than the term by more than :data:`SEPARATION`: the data
        tell them apart and prefer the stand-in."""
        return tuple(e for e in self.alternatives if self.separation[e] <= -SEPARATION)

    @property
    def text(self) -> str:
        spec = get_effect(self.term)
        rivals = " or ".join(
            f"{effect.replace('_', ' ')} {get_effect(effect).term} (Δχ² "
            f"{self.separation[effect]:+.2g} in its place"
            + (", a better fit)" if effect in self.favoured else ")")
            for effect in self.alternatives
        )
        tell = (
            f"they fit better with {', '.join(self.favoured)} in its place (a reading, not a "
            "proposal: the loop's swap step replaces the term)"
            if self.favoured
            else "they cannot tell which it is (a reading of the model's terms, not a proposal)"
        )
        return (
            f"the model's {spec.term} ({self.term.replace('_', ' ')}, {self.coefficient:+.3g}) "
            f"is consistent with {rivals} on these data: the data need the term (removing it "
            f"costs Δχ² {self.needed:.3g}); {tell}; what would separate them: "
            f"{self.separated_by}"
        )

    def __str__(self) -> str:
        return self.text

    def __repr__(self) -> str:
        return f"<TermGroup: {self.text}>"

    def to_dict(self) -> dict[str, Any]:
        return {
            "term": self.term,
            "coefficient": self.coefficient,
            "needed_delta_chi2": self.needed,
            "effects": list(self.effects),
            "separation": self.separation,
            "separated_by": self.separated_by,
            "favoured": list(self.favoured),
            "rmse": {
                effect: {
                    "frequency_hz": fit.frequency_rmse_hz,
                    "damping_ratio": fit.damping_rmse,
                    "harmonics": fit.harmonic_rmse,
                }
                for effect, fit in self.fits.items()
            },
            "text": self.text,
        }


@dataclass(frozen=True)
class Step:
    """One step of the criticism loop: the model and how well it fits.

    ``added`` and ``removed`` are the effects this step's model gained and lost against
    the previous step's (an addition, then a swap's replacement; empty for the start).
    """

    action: str
    equation: str
    effects: tuple[str, ...]
    frequency_rmse_hz: float
    damping_rmse: float
    harmonic_rmse: float | None
    information_criterion: float
    criterion: str
    added: tuple[str, ...] = ()
    removed: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        return {
            "action": self.action,
            "equation": self.equation,
            "effects": list(self.effects),
            "added": list(self.added),
            "removed": list(self.removed),
            "frequency_rmse_hz": self.frequency_rmse_hz,
            "damping_rmse": self.damping_rmse,
            "harmonic_rmse": self.harmonic_rmse,
            "information_criterion": self.information_criterion,
            "criterion": self.criterion,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Step:
        """A step from :meth:`to_dict` (steps written before ``added``/``removed`` existed
        read with both empty)."""
        tuples = {k: tuple(data.get(k, ())) for k in ("effects", "added", "removed")}
        return cls(**{**data, **tuples})


@dataclass(frozen=True)
class Trial:
    """One trial behind the model-term groups: a catalogue ``effect`` refitted in place of
    the model's ``term`` (``effect`` None: the term is not needed, and this records what
    removing it cost).

    Attributes
    ----------
    term, effect
        The model's term and the stand-in tried in its place.
    needed
        ``χ²`` the model loses when the term is removed and the rest refitted.
    delta_chi2
        The model's ``χ²`` less the stand-in's (positive: it fits better); None without one.
    why
        Its objections in words (empty: none).
    standing
        It joins the term's group.
    fit
        The refitted model with the stand-in in the term's place.
    """

    term: str
    effect: str | None
    needed: float
    delta_chi2: float | None = None
    why: str = ""
    standing: bool = False
    fit: FitResult | None = field(default=None, compare=False, repr=False)


@dataclass(frozen=True)
class SwapTrial:
    """One change the swap step tried: ``remove`` an effect, or replace it by ``add``.

    ``delta_chi2`` is the model's ``χ²`` less the changed model's (negative for a removal:
    what it costs), ``kept`` whether the step kept the change, ``why`` the replacement's
    objections in words, ``keep_if`` the rule it was judged by.
    """

    remove: str
    add: str | None
    delta_chi2: float
    kept: bool = False
    why: str = ""
    keep_if: str = ""

    @property
    def words(self) -> str:
        """The change in words: ``− a`` or ``− a + b``."""
        return f"− {self.remove}" + (f" + {self.add}" if self.add else "")

    @property
    def decision(self) -> str:
        """What the change does to the model, as the swap study's rows say it."""
        return f"replaced by {self.add}" if self.add else "removed"

    def to_dict(self) -> dict[str, Any]:
        return {
            "remove": self.remove,
            "add": self.add,
            "delta_chi2": self.delta_chi2,
            "kept": self.kept,
            "why": self.why,
            "keep_if": self.keep_if,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SwapTrial:
        """A trial from :meth:`to_dict` (as in a report's rounds)."""
        return cls(
            **{k: data[k] for k in ("remove", "add", "delta_chi2", "kept", "why", "keep_if")}
        )


def ranking_entry(c: Candidate) -> dict[str, Any]:
    """A proposed candidate as the report's ranking lists it."""
    return {
        "effect": c.effect,
        "status": str(c.status),
        "alternative": c.alternative,
        "explained_share": c.share,
        "delta_chi2": c.delta_chi2,
        "gain": c.gain,
        "error_reduction": c.error_reduction,
        "delta_information_criterion": c.delta_ic,
        "reading": c.reading,
        "equation": c.fit.model.equation(),
    }
