"""The model-term group study: how often a term of the truth's own structure is grouped with
a catalogue stand-in the data can tell it from, over lab-rig campaigns (by default; fast
harmonic-balance campaigns as a unit-level check)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Self

import numpy as np

from identification.criticism.config import SEPARATION
from identification.criticism.criticism import Criticism, criticize
from identification.criticism.records import Trial
from identification.effects import quadratic_stiffness, velocity_squared
from identification.fitting.data import FitData
from identification.fitting.fitter import Fitter
from identification.model import JointModel
from identification.rig.presets import lab_hidden_scenario
from studies.driver import Campaign, CampaignRow, CampaignSource, is_discovery, run_campaigns
from studies.outcomes import TermTrialOutcome
from studies.rows import EndState, Row
from studies.swaps import SWAP_TRUTHS

__all__ = ["TERM_TRUTHS", "TermGroupRow", "TermTrial", "design_chi2", "term_group_study"]

#: Truths of the model-term group study (:func:`term_group_study`): the swap study's (each
#: with near-collinear catalogue rivals) and the even pair SINDy confuses (x², ẋ²).
TERM_TRUTHS: tuple[str, ...] = (
    *SWAP_TRUTHS,
    quadratic_stiffness.EFFECT.name,
    velocity_squared.EFFECT.name,
)


@dataclass(frozen=True)
class TermTrial(Row):
    """One trial of a stand-in in place of a model term.

    Attributes
    ----------
    term
        The model's term.
    effect
        The stand-in (None: the term's removal cost alone).
    needed
        What removing the term costs in ``χ²``.
    delta_chi2
        The stand-in's ``χ²`` gain in the term's place (None without a stand-in).
    why
        Why the stand-in is inadmissible or makes a channel worse ("" if it is not).
    standing
        The stand-in stands in: the term's group holds it.
    design_lambda
        The separation at the design, ``λ``: the stand-in's structure refitted to the
        noise-free truth, its ``χ²`` in the campaign's metric (None without a stand-in).
        Written as ``lambda``.
    """

    term: str
    effect: str | None
    needed: float
    delta_chi2: float | None
    why: str
    standing: bool
    design_lambda: float | None = None

    _JSON_KEYS: ClassVar[Mapping[str, str]] = {"design_lambda": "lambda"}

    @classmethod
    def of(cls, trial: Trial) -> Self:
        """The row of a :class:`~identification.criticism.records.Trial` of
        :attr:`~identification.criticism.criticism.Criticism.term_trials` (its separation at
        the design not yet known)."""
        return cls(
            trial.term, trial.effect, trial.needed, trial.delta_chi2, trial.why, trial.standing
        )

    @property
    def outcome(self) -> TermTrialOutcome | None:
        """The trial's category (:class:`~studies.outcomes.TermTrialOutcome`) by its
        separation at the design; None for a term's removal alone (no stand-in)."""
        if self.design_lambda is None:
            return None
        if self.design_lambda >= SEPARATION:
            return TermTrialOutcome.FALSE_FLAG if self.standing else TermTrialOutcome.SEPARATED
        if self.standing:
            return TermTrialOutcome.RIGHT_GROUP
        return TermTrialOutcome.NOT_GROUPED_CLOSE


@dataclass(frozen=True, kw_only=True)
class TermGroupRow(CampaignRow):
    """One term-group campaign (:func:`term_group_study`); its ``truth`` is the effect ``T``.

    Attributes
    ----------
    verdict
        The criticism's verdict (a null campaign for the truth's structure).
    false_discovery
        The verdict proposes something (:func:`~studies.driver.is_discovery`).
    lambda_truth
        The truth's structure refitted to its noise-free twin: its ``χ²`` (≈ 0).
    trials
        Every trial of a stand-in in place of a model term.
    term_groups
        The groups: each the term and its stand-ins.
    end_state
        The criticised model (the truth's structure, refitted), its verdict and p-value:
        the study runs no loop, so round 1 is the end state.
    """

    verdict: str
    false_discovery: bool
    lambda_truth: float
    trials: tuple[TermTrial, ...]
    term_groups: tuple[tuple[str, ...], ...]
    end_state: EndState | None = None


def term_group_study(
    campaigns: int,
    *,
    truths: Sequence[str] = TERM_TRUTHS,
    curve_counts: Sequence[int] = (1, 3, 5, 10),
    seed: int = 0,
    progress: Callable[[TermGroupRow], None] | None = None,
    source: CampaignSource = CampaignSource.LAB_RIG,
    **options: Any,
) -> list[TermGroupRow]:
    """Model-term groups (:attr:`~identification.criticism.criticism.Criticism.term_groups`)
    over ``campaigns`` campaigns (truths and curve counts in turn, drawn by
    :func:`~studies.driver.run_campaigns` from ``source``: the lab rig by default), each
    criticised with its truth's own structure: the lab base model plus one effect ``T``
    (the preset ``lab-hidden-<T>``).

    Each trial of a stand-in ``C`` in place of a model term (``T`` or a term of the lab
    base) gets its separation at the design, ``lambda``: the stand-in's structure refitted
    to the noise-free truth — the population model's prediction at the campaign's points,
    driven by the excitation they measured — with the campaign's own covariance, its
    ``χ²`` in the campaign's metric. That is the noncentrality of the trial's ``Δχ²``
    (the truth's structure fits the noise-free prediction exactly: ``lambda_truth``, ≈ 0;
    the prediction is the criticism's harmonic balance, so on rig data it is the design as
    the criticism sees it, not the rig's records):
    where it is large the data can tell the term from ``C``, and a group holding ``C``
    is a false flag. Each row also carries the campaign's verdict (a null campaign for the
    truth's structure: groups do not alter it) and its groups.

    Parameters
    ----------
    campaigns
        Number of campaigns.
    truths
        The effects ``T``, in turn.
    curve_counts, seed, progress, source, **options
        As :func:`studies.swaps.swap_study`'s.

    Returns
    -------
    list of TermGroupRow
        A row per campaign, in the order :func:`~studies.driver.run_campaigns` draws them.
    """

    def judge(campaign: Campaign) -> TermGroupRow:
        truth = campaign.truth
        crit = criticize(truth, campaign.measured, **options)
        twin = _noise_free_twin(crit, truth)
        trials = []
        for trial in map(TermTrial.of, crit.term_trials):
            if trial.effect is not None:
                stand_in = crit.base.model.without(trial.term).with_effect(trial.effect, 0.0)
                trial = dataclasses.replace(trial, design_lambda=_twin_chi2(crit, twin, stand_in))
            trials.append(trial)
        return TermGroupRow.of(
            campaign,
            verdict=crit.verdict,
            false_discovery=is_discovery(crit.verdict),
            lambda_truth=_twin_chi2(crit, twin, crit.base.model),
            trials=tuple(trials),
            term_groups=tuple(tuple(g.effects) for g in crit.term_groups),
            end_state=EndState.of(crit),
        )

    return run_campaigns(
        campaigns, truths, curve_counts, seed, lab_hidden_scenario, judge, progress, source
    )


def design_chi2(crit: Criticism, truth: JointModel, model: JointModel) -> float:
    """The separation at the design: ``model``'s structure refitted to the noise-free twin
    of ``crit``'s data (``truth``'s prediction at every point, the campaign's metrics), its
    ``χ²`` in the campaign's metric — the noncentrality of ``model``'s misfit, free of the
    campaign's noise.

    Parameters
    ----------
    crit
        The criticism whose data and metric are used.
    truth
        The model that made the data.
    model
        The structure judged (refitted; its coefficients are start values).

    Returns
    -------
    float
        ``χ²`` of the refitted structure on the noise-free twin.
    """
    return _twin_chi2(crit, _noise_free_twin(crit, truth), model)


def _noise_free_twin(crit: Criticism, truth: JointModel) -> FitData:
    """The criticism's data with every measured value replaced by the truth's prediction at
    its point (driven by the point's measured excitation), keeping the campaign's metrics:
    the covariance of the noisy campaign, estimated from its scatter."""
    data = crit.data
    data.metric()
    data.metric(crit.base.weights)  # the metrics a refit asks for, estimated on the campaign
    predicted = crit.fitter.predict(truth)
    values = np.where(np.isfinite(data.values), predicted, np.nan)
    return dataclasses.replace(data, values=values, _metrics=dict(data._metrics))


def _twin_chi2(crit: Criticism, twin: FitData, model: JointModel) -> float:
    """``model``'s structure refitted to the noise-free twin, its ``χ²`` there in the
    campaign's metric."""
    keys = set(twin._metrics)
    fit = Fitter(twin, crit.method, crit.weights).fit(model, method=crit.fitter.method_for(model))
    if set(twin._metrics) != keys:
        raise RuntimeError("the refit asked for a metric the campaign's data did not estimate")
    z = crit.metric.whiten(twin.mean_residual(fit.predicted))
    return float(z @ z)
