"""The criticism in words: the verdict, the caveats, the summary of a round.

Each function reads a finished :class:`~identification.criticism.criticism.Criticism`
(``crit``) and says one thing; none computes a statistic of its own.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from identification.criticism.adequacy import no_solution
from identification.criticism.config import Verdict
from identification.criticism.directions import mean_prediction
from identification.criticism.participation import EXCHANGE_LEVEL, PARTICIPATION
from identification.criticism.readings import CHANNEL_LABELS
from identification.criticism.records import Candidate, rmse_pairs
from identification.effects import CATALOGUE
from identification.model import JointModel

if TYPE_CHECKING:
    from identification.criticism.criticism import Criticism

__all__ = [
    "SMALL",
    "caveats",
    "nearby_mode_words",
    "no_solution_texts",
    "second_mode_words",
    "separates_nearby_mode",
    "summary",
    "verdict_text",
]

#: What a finding no single level shows is (:attr:`Decision.small
#: <identification.criticism.decision.Decision.small>`), in words.
SMALL = "missing, small: seen in the trend over the levels, within the scatter at each"


def verdict_text(crit: Criticism) -> str:
    """The verdict in one sentence (with :data:`SMALL` where no single level shows it)."""
    text = _verdict_words(crit)
    return f"{text}; {SMALL}" if crit.small else text


def _verdict_words(crit: Criticism) -> str:
    verdict, share = crit.verdict, crit.explained_share
    if verdict == Verdict.NOTHING_MISSING:
        return "nothing missing beyond the scatter"
    if verdict == Verdict.DRIFT:
        return "nothing missing as physics; the branches show drift (see below)"
    if verdict == Verdict.SECOND_MODE:
        return f"explained by a second mode: {second_mode_words(crit)}"
    best = crit.best
    if verdict == Verdict.EXPLAINED:
        return f"explained by {best.effect} ({100 * (share or 1):.0f} % of the free-form gain)"
    if verdict == Verdict.PARTLY_EXPLAINED and best.alternative:
        captured = f"{100 * share:.0f} %" if share is not None else "all"
        return (
            f"partly explained: {best.effect} fits ({captured} of the free-form gain) but is "
            f"not identified; consistent with {best.effect} OR with {best.alternative}"
        )
    if verdict == Verdict.PARTLY_EXPLAINED:
        captured = f"{100 * share:.0f} %" if share is not None else "all"
        text = (
            f"partly explained: {best.effect} captures {captured} of what a free-form "
            "stiffness and damping gain"
        )
        if best.beyond:
            text += f" and leaves the residual beyond the scatter in {', '.join(best.beyond)}"
        return text
    text = "not explained by the catalogue"
    if best is not None and share is not None:
        text += f" (the best catalogue effect, {best.effect}, captures {100 * share:.0f} %)"
    return text + "; the free-form describing functions show the shape of what is missing"


def second_mode_words(crit: Criticism) -> str:
    """The second-mode finding in words: the mode, how it beats the catalogue, where it shows."""
    mode = crit.second_mode
    if mode.named_by == PARTICIPATION and np.isfinite(mode.resonance_gain):
        beyond = (
            f"its coordinate's fundamental at the sensors is shaped by its resonance: "
            f"Δχ² {mode.resonance_gain:.4g} off a mode too far to resonate; whether it "
            "exchanges energy through the joint is not told at the fundamental"
        )
    elif mode.named_by == PARTICIPATION:
        level = f"{100 * EXCHANGE_LEVEL:g} %"
        beyond = (
            f"its drive of the second mode's coordinate at 2ω takes Δχ² {mode.exchange:.4g} off "
            f"a linear mode's fit, beyond χ² {mode.exchange_threshold:.3g} at {level}"
        )
    else:
        beyond = (
            f"Δχ² {mode.gain:.4g} against the catalogue's best {mode.catalogue_gain:.4g} and its "
            f"calibrated threshold {mode.threshold:.3g}"
        )
    return f"{mode.text} ({beyond}); where it shows: " + "; ".join(mode.where)


def caveats(crit: Criticism) -> list[str]:
    """What the user must know to read the verdict."""
    out = []
    covariance = crit.metric.covariance
    if covariance.kind == "within-curve":
        out.append(
            "one curve: it is compared with its own within-hold noise (estimated from its "
            "roughness along the levels); the population scatter is unknown, so a finding "
            "says this assembly departs from the model, not the population"
        )
    data = crit.data
    unused = [c for c, u in zip(data.channels, data.used, strict=True) if not u]
    if unused:
        out.append(f"channels some curves lack are not compared: {', '.join(unused)}")
    where = no_solution(data.levels_m, mean_prediction(data, crit.fit.predicted))
    if where:
        out.append(f"the model as given has {where}")
    if not crit.base.solved:
        out.append(crit.base.outcome_text)
    return out


def no_solution_texts(crit: Criticism) -> list[str]:
    """Where the refitted model has no periodic solution, in words (empty: everywhere)."""
    where = no_solution(crit.data.levels_m, mean_prediction(crit.data, crit.base.predicted))
    return [f"the refitted model has {where}"] if where else []


def summary(crit: Criticism) -> str:
    """A few lines in words: the decision, where the model fails, what it lacks."""
    cal_, obs, base = crit.calibration, crit.observed, crit.base
    lines = [f"model: {base.model.equation()}", f"data: {_data_words(crit)}"]
    chi2 = crit.decision.chi2
    if crit.posterior is None and crit.fit.model.equation() != base.model.equation():
        lines.append(f"(coefficients refitted; as given: χ² {chi2(crit.fit):.4g} → "
                     f"{chi2(base):.4g})")  # fmt: skip
    lines.append(
        f"frequency RMSE {base.frequency_rmse_hz:.3g} Hz, damping RMSE "
        f"{100 * base.damping_rmse:.3g} %-points"
        + (
            f", harmonics RMSE {100 * base.harmonic_rmse:.3g} % of the fundamental"
            if base.harmonic_rmse is not None
            else ""
        )
    )
    lines.append(
        f"decision: catalogue gain Δχ² {obs.catalogue[0]:.4g} (threshold "
        f"{cal_.catalogue_threshold:.3g}), free-form gain {obs.reference[0]:.4g} (threshold "
        f"{cal_.reference_threshold:.3g}, {obs.reference_rank} dof); α = {crit.alpha:g} "
        f"(effective level {cal_.effective_level:.2g} if the chain adds no systematic error), "
        f"{cal_.n_bootstrap} bootstrap campaigns, p = {crit.p_value:.2g}; where-bound "
        f"{cal_.where_bound:.2f} standard errors"
    )
    lines += [f"caveat: {c}" for c in crit.caveats]
    failures = crit.where()
    nowhere = "at no single level" if crit.small else "nowhere"
    nowhere += " beyond the scatter"
    lines += [f"fails: {f.text}" for f in failures] or [f"fails: {nowhere}"]
    for text in no_solution_texts(crit):
        lines.append(f"fails: {text}")
    lines.append(f"verdict: {crit.verdict_text}")
    if crit.significant and not crit.second_mode.named:
        mode = crit.second_mode
        lines.append(f"second mode: not named — {mode.why} (best: {mode.text})")
    proposed = crit.missing()
    groups, term_groups = crit.groups, crit.term_groups
    lines.append(
        f"counts: {len(crit.candidate_effects)} catalogue effects tried, "
        f"{sum(c.fit is not None for c in crit.candidates)} refitted, {len(proposed)} "
        f"proposed, {len(groups)} ambiguity group{'s' if len(groups) != 1 else ''}"
        f", {len(term_groups)} model-term group{'s' if len(term_groups) != 1 else ''}"
    )
    if not proposed:
        lines.append("missing: nothing proposed")
    for c in proposed[:3]:
        lines.append(f"missing: {c.effect} ({c.status}; {_numbers(c)}): {c.reading}")
    for c in crit.candidates:
        if c.fit is not None and c.status == "improves the fit but does not explain it":
            why = "; ".join(c.problems) or (
                f"makes {', '.join(c.worse)} worse beyond the noise" if c.worse
                else "not significant on its own"
            )  # fmt: skip
            lines.append(f"improves the fit but does not explain it: {c.effect} ({why})")
    lines += [g.text for g in groups]
    lines += [g.text for g in term_groups]
    lines += [
        f"model-term trial: {t.effect} in place of {t.term} was not judged ({t.why})"
        for t in crit.term_trials
        if t.fit is not None and not t.fit.solved
    ]
    lines += [f"drift: {d.text}" for d in crit.drift if d.significant]
    if crit.significant:
        lines.append(f"free-form reference: {_shape_words(crit)}")
    lines += crit.loop_end.lines() if crit.loop_end else []
    return "\n".join(lines)


def _data_words(crit: Criticism) -> str:
    """What the likelihood used: curves, levels, channels, the covariance's kind."""
    data, covariance = crit.data, crit.metric.covariance
    mm = 1e3 * data.levels_m
    used = [c for c, u in zip(data.channels, data.used, strict=True) if u]
    text = (
        f"{data.n_curves} curve{'s' if data.n_curves != 1 else ''}, {mm.size} levels "
        f"{mm[0]:.2g}–{mm[-1]:.2g} mm, channels {', '.join(used)}; {covariance.kind} "
        "covariance"
    )
    if covariance.kind == "between-curve":
        text += f" (correlation shrinkage {covariance.correlation_shrinkage:.2f})"
    return text


def _numbers(c: Candidate) -> str:
    reduction = ", ".join(
        f"{CHANNEL_LABELS[k][0] if k in CHANNEL_LABELS else k} RMSE "
        f"{CHANNEL_LABELS.get(k, ('', '', 100.0))[2] * before:.2g} → "
        f"{CHANNEL_LABELS.get(k, ('', '', 100.0))[2] * after:.2g}"
        for k, before, after in rmse_pairs(c.base, c.fit)
    )
    share = "" if c.share is None else f", {100 * c.share:.0f} % of the free-form gain"
    return f"Δχ² {c.delta_chi2:.4g}{share}; {reduction}"


def _shape_words(crit: Criticism) -> str:
    ref = crit.reference
    k_base, c_base = ref.describing(ref.base_frequency_hz, ref.base_damping_ratio)
    k_ref, c_ref = ref.describing(ref.frequency_hz, ref.damping_ratio)
    dk = 100 * (k_ref / k_base - 1)
    dc = 100 * (c_ref / c_base - 1)
    mm = 1e3 * ref.levels_m
    i, j = int(np.nanargmax(np.abs(dk))), int(np.nanargmax(np.abs(dc)))
    return (
        f"k_eq departs from the model's by up to {dk[i]:+.2g} % (at {mm[i]:.2g} mm), c_eq by "
        f"up to {dc[j]:+.2g} % (at {mm[j]:.2g} mm); Δχ² {ref.gain:.4g} with "
        f"{ref.degrees_of_freedom} degrees of freedom"
    )


def separates_nearby_mode(model: JointModel) -> str:
    """What separates a slip onset from a nearby mode (see
    :func:`~identification.criticism.adequacy.onset_only`)."""
    shape = next(t.shape for t in model.terms if CATALOGUE[t.effect].hysteretic)
    return (
        "a second response point or the mode shape (a second mode has its own shape and "
        f"resonance), or levels beyond {2e3 * shape['F_s'] / shape['k_t']:.2g} mm, where "
        "slip's damping must fall back"
    )


def nearby_mode_words(onset: str, model: JointModel) -> str:
    """The out-of-catalogue alternative to an onset-only slip fit, in words."""
    return (
        "a nearby mode exchanging energy with this one as the backbone approaches it "
        f"({onset}); one sensor cannot tell them apart — what would: "
        f"{separates_nearby_mode(model)}"
    )
