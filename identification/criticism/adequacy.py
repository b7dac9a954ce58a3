"""Whether a fitted model can be read as physics: admissibility and where it has no solution.

A catalogue effect that lowers the misfit is not yet an explanation. Its fitted
coefficients must describe a joint a resonance test could have measured
(:func:`admissibility`):

* **non-negative dissipation** over the tested range: the total equivalent damping
  (the predicted damping ratio) ≥ 0 at every level — a phase-locked test feeds
  power in at every level — and the terms' summed equivalent damping
  ``Σ c_i c_eq,i(a, ω(a))`` ≥ 0 at every amplitude between the lowest and the top level
  (:data:`RANGE_POINTS` log-spaced amplitudes besides the levels; ``ω(a)`` interpolated
  from the predicted frequencies), so no dip below zero hides between two levels;
* **a positive linear stiffness**: the structure's own spring restores at rest (a
  negative one made up for by a nonlinear term is a fit trading terms, not a joint);
* **friction and slip forces oppose the motion**: effects whose physics has a sign
  (:attr:`identification.effects.Effect.coefficient_sign`) have it;
* **no joint term pushes away from equilibrium at rest**: a nonlinear term whose
  stiffness at rest (its equivalent stiffness as the amplitude goes to zero) is
  negative, which a larger linear stiffness then makes up for (a hardening described
  as a stiffer structure minus a saturating spring), is a negative spring, not a joint;
* **no large cancelling terms** (over the same amplitudes): where the terms' equivalent
  stiffnesses (or dampings) ``c_i k_eq,i(a)`` add up in absolute value to much more than their net
  sum (``Σ|c_i k_eq,i| > CANCELLATION · |Σ c_i k_eq,i|``), the fit trades terms
  against each other (a 4× linear stiffness cancelled by a large tanh) and none of
  them reads as physics;
* a periodic solution at every level (:func:`no_solution`, in words).

An admissible, adequate fit may still not identify its physics: a Jenkins element
whose slip starts so high in the test that the data never reach its damping peak
shows only that something starts taking energy near the top of the range, which a
nearby mode the backbone approaches does as well (:func:`onset_only`).
"""

from __future__ import annotations

import numpy as np

from identification.criticism.directions import mean_prediction
from identification.effects import CATALOGUE, LINEAR_STIFFNESS
from identification.fitting.data import FitData
from identification.fitting.least_squares import FitResult
from identification.model import JointModel

__all__ = [
    "CANCELLATION",
    "NEARBY_MODE",
    "RANGE_POINTS",
    "admissibility",
    "fitted_problems",
    "no_solution",
    "onset_only",
]

#: Ratio of the sum of absolute term contributions to their net sum beyond which the
#: terms are said to cancel (a physical softening-then-hardening joint stays near 1).
CANCELLATION = 2.0
#: Amplitudes (log-spaced over the tested range, besides the levels) at which the summed
#: equivalent damping and the cancellation are checked: a term whose damping turns negative
#: between two levels (a negative ẋ³ beside a Coulomb term) is caught there.
RANGE_POINTS = 64


def no_solution(levels_m: np.ndarray, predicted: np.ndarray) -> str | None:
    """Where a prediction at the levels (``(n_levels, n_channels)``) has no periodic
    solution, in words (None where it has one at every level)."""
    failed = ~np.isfinite(predicted).all(axis=1)
    if not failed.any():
        return None
    mm = 1e3 * levels_m
    if failed.all():
        return "no periodic solution at any tested amplitude"
    solved = np.flatnonzero(~failed)
    if not failed[solved[0] : solved[-1] + 1].any():  # the failures are at the ends
        if not failed[: solved[0]].any():
            return f"no periodic solution above {mm[solved[-1]]:.2g} mm"
        if not failed[solved[-1] + 1 :].any():
            return f"no periodic solution below {mm[solved[0]]:.2g} mm"
    return "no periodic solution at " + ", ".join(f"{a:.2g}" for a in mm[failed]) + " mm"


def admissibility(
    model: JointModel, levels_m: np.ndarray, frequency_hz: np.ndarray, damping_ratio: np.ndarray
) -> list[str]:
    """What makes a fitted model inadmissible as physics, in words (empty: admissible).

    ``frequency_hz`` and ``damping_ratio`` are the model's predictions at the levels.
    """
    problems = []
    where = no_solution(levels_m, np.column_stack([frequency_hz, damping_ratio]))
    if where:
        problems.append(where)
    ok = np.isfinite(frequency_hz) & np.isfinite(damping_ratio)
    mm = 1e3 * levels_m
    negative = ok & (damping_ratio < 0)
    if negative.any():
        problems.append(
            f"negative total damping (energy fed in by the joint) at {mm[negative].min():.2g}–"
            f"{mm[negative].max():.2g} mm"
        )
    if np.isfinite(frequency_hz).any():
        problems += _negative_at_rest(model, levels_m[0], 2 * np.pi * np.nanmin(frequency_hz))
    for term in model.terms:
        sign = CATALOGUE[term.effect].coefficient_sign
        if sign and np.sign(term.coefficient) == -sign:
            problems.append(
                f"{term.effect} has a negative coefficient ({term.coefficient:.3g}): a friction "
                "or slip force that pushes the motion instead of opposing it"
            )
    if LINEAR_STIFFNESS in model and model.coefficient(LINEAR_STIFFNESS) <= 0:
        problems.append(
            f"a non-positive linear stiffness ({model.coefficient(LINEAR_STIFFNESS):.3g}): the "
            "structure has no restoring spring at rest"
        )
    if ok.any():
        a, omega = _measured_range(levels_m[ok], 2 * np.pi * frequency_hz[ok])
        parts = []
        for term in model.terms:
            k_eq, c_eq = CATALOGUE[term.effect].describing(a, omega, **term.shape)
            parts.append((term.effect, term.coefficient * k_eq, term.coefficient * c_eq))
        damping = np.sum([p[2] for p in parts], axis=0)
        below = damping < 0
        if below.any() and not negative.any():  # the levels' own words said it already
            problems.append(
                "negative summed equivalent damping between the levels, at "
                f"{1e3 * a[below].min():.2g}–{1e3 * a[below].max():.2g} mm (energy fed in by "
                "the joint)"
            )
        for index, kind in ((1, "stiffness"), (2, "damping")):
            values = np.array([p[index] for p in parts])
            net = np.abs(values.sum(axis=0))
            gross = np.abs(values).sum(axis=0)
            with np.errstate(divide="ignore", invalid="ignore"):
                ratio = np.where(net > 0, gross / net, np.inf)
            worst = int(np.argmax(ratio))
            if ratio[worst] > CANCELLATION and gross[worst] > 0:
                largest = sorted(parts, key=lambda p: -abs(p[index][worst]))[:2]
                words = " against ".join(f"{p[0]} ({p[index][worst]:+.3g})" for p in largest)
                problems.append(
                    f"terms cancel in the equivalent {kind}: their sizes add up to "
                    f"{ratio[worst]:.1f}× the net at {1e3 * a[worst]:.2g} mm ({words})"
                )
    return problems


def _measured_range(levels_m: np.ndarray, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The levels and :data:`RANGE_POINTS` log-spaced amplitudes between the lowest and the
    top one (m), with the frequency (rad/s) interpolated in log-amplitude between the
    levels' predictions."""
    between = np.geomspace(levels_m[0], levels_m[-1], RANGE_POINTS)
    a = np.unique(np.concatenate([levels_m, between]))
    return a, np.interp(np.log(a), np.log(levels_m), omega)


def fitted_problems(data: FitData, fit: FitResult) -> list[str]:
    """What makes a refitted model inadmissible as physics (:func:`admissibility` on its
    mean prediction at the levels), a failed solve first; empty: admissible."""
    table = mean_prediction(data, fit.predicted)
    f, z = data.column("frequency_hz"), data.column("damping_ratio")
    problems = admissibility(fit.model, data.levels_m, table[:, f], table[:, z])
    return problems if fit.solved else [fit.outcome_text, *problems]


#: Where "at rest" is evaluated, as a share of the smallest tested amplitude; a stiffness at
#: rest below this share of the linear one is a rounding (a cubic term's there is ~1e-6 of it).
AT_REST = 1e-3


def _negative_at_rest(model: JointModel, smallest_m: float, omega: float) -> list[str]:
    """Nonlinear terms with a negative stiffness at rest, made up for by the linear one."""
    out = []
    linear = model.coefficient(LINEAR_STIFFNESS) if LINEAR_STIFFNESS in model else 0.0
    rest = np.array([AT_REST * smallest_m])
    for term in model.terms:
        if term.effect == LINEAR_STIFFNESS:
            continue
        k_eq, _ = CATALOGUE[term.effect].describing(rest, np.array([omega]), **term.shape)
        at_rest = float(term.coefficient * np.ravel(k_eq)[0])
        if linear > 0 and at_rest < -AT_REST * linear:  # beyond a rounding of the linear term
            out.append(
                f"{term.effect} has a negative stiffness at rest ({at_rest:.3g}, "
                f"{100 * -at_rest / linear:.2g} % of the linear stiffness it is added to): "
                "a spring pushing away from equilibrium, made up for by a stiffer structure"
            )
    return out


#: The physics outside the catalogue that an onset-only fit cannot be told from.
NEARBY_MODE = "a nearby mode (outside the catalogue)"


def onset_only(model: JointModel, levels_m: np.ndarray) -> str | None:
    """Why a fitted ``microslip`` term shows only its onset on these data, in words
    (None where the data reach what identifies slip, or the model has no such term).

    A Jenkins element's added damping ratio goes as ``(a − a_s)/a²`` above its slip
    amplitude ``a_s = F_s/k_t``: it peaks at ``2 a_s`` and falls back as partial slip
    turns into macroslip, while the stiffness it removes saturates at ``k_t``. That
    rise and fall (Masing hysteresis) is what identifies slip. Where the top tested
    level is below ``2 a_s`` the data show only a dissipation (and softening) that
    starts near the top of the range and is still rising there. A second mode that the
    backbone approaches as its frequency moves does the same from one sensor: the
    energy it takes grows as the detuning shrinks, and it pushes the backbone's
    frequency away (flattening it). Which of the two it is needs another measurement,
    not a better fit: a second response point or the mode shape (a second mode has its
    own shape and resonance), or levels beyond ``2 a_s`` where slip's damping must fall.
    """
    term = next((t for t in model.terms if CATALOGUE[t.effect].hysteretic), None)
    if term is None:
        return None
    slip = term.shape["F_s"] / term.shape["k_t"]
    top = float(levels_m[-1])
    if top >= 2 * slip:
        return None
    return (
        f"the data show only the onset of slip: the fitted slip amplitude {1e3 * slip:.2g} mm "
        f"is above half the top level ({1e3 * top:.2g} mm), so the damping peak at "
        f"{2e3 * slip:.2g} mm, beyond which slip's damping must fall back, is not in the test"
    )
