"""The decision: is something missing, and where does the model fail?

:class:`Decision` holds the statistics of one model against one campaign: the
linearised problem at the refitted base model, the observed gains of the catalogue's
best column and of the free-form reference, their bootstrap calibration (thresholds,
p-value), the per-channel ``χ²`` a candidate is judged by, the comparison of mean
curve and prediction, and :meth:`Decision.where` (amplitude ranges beyond the
calibrated bound: it describes, it does not decide). The rule that something is missing
is :attr:`Decision.significant`, the calibrated decision alone.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import cached_property

import numpy as np

from identification.criticism import calibration as cal
from identification.criticism.adequacy import admissibility
from identification.criticism.config import WORSE, CriticismConfig
from identification.criticism.directions import (
    base_jacobian,
    candidate_directions,
    mean_prediction,
    reference_directions,
)
from identification.criticism.drift import Drift, branch_drift
from identification.criticism.records import Candidate, FailureRange
from identification.criticism.reference import FreeForm, fit_reference
from identification.fitting.data import (
    BACKBONE_CHANNELS,
    FAILED_RESIDUAL,
    HARMONIC_ORDERS,
    FitData,
    Metric,
)
from identification.fitting.fitter import Fitter
from identification.fitting.least_squares import FitResult, default_free
from identification.model import JointModel

__all__ = ["Decision", "separation", "worse"]


class Decision:
    """The statistics of the refitted base model ``base`` against the campaign.

    Parameters
    ----------
    fitter
        The data and fitting options (:class:`~identification.fitting.fitter.Fitter`).
    base
        The refitted base model (the posterior median as given, with a posterior).
    candidate_effects
        The catalogue effects whose columns the catalogue test scans.
    config
        The criticism's settings.
    posterior
        ``(names, draws)`` of the model's parameters, or None; ``model`` is the model
        the draws are of.
    """

    def __init__(
        self,
        fitter: Fitter,
        base: FitResult,
        candidate_effects: Sequence[str],
        config: CriticismConfig,
        posterior: tuple[list[str], np.ndarray] | None = None,
        model: JointModel | None = None,
    ) -> None:
        self.fitter = fitter
        self.data: FitData = fitter.data
        self.base = base
        self.candidate_effects = list(candidate_effects)
        self.config = config
        self.posterior = posterior
        self.model = base.model if model is None else model

    # ------------------------------------------------------------ the metric
    @cached_property
    def metric(self) -> Metric:
        """The likelihood's metric, widened by a posterior's population-mean uncertainty."""
        metric = self.data.metric(self.base.weights)
        if self.posterior is None:
            return metric
        names, draws = self.posterior
        samples = self.fitter.predict(
            self.model, method=self.base.method, parameters=draws, names=names
        )
        tables = mean_prediction(self.data, samples).reshape(len(draws), -1)[:, metric.keep]
        ok = np.isfinite(tables).all(axis=1)
        spread = np.cov(tables[ok].T) if ok.sum() > 1 else np.zeros((metric.size,) * 2)
        if self.config.posterior_kind == "population":
            # The draws spread like the population; its mean curve is known to 1/n of that.
            spread = spread / self.data.n_curves
        return Metric(metric.keep, metric.weights, metric.covariance.widened(np.atleast_2d(spread)))

    # ------------------------------------------------------------ the statistics
    @cached_property
    def problem(self) -> cal.Problem:
        """The linearised problem at the refitted base model."""
        base = self.base
        metric = self.metric
        free = list(base.free) or default_free(base.model)
        jacobian = base_jacobian(base.model, free, self.data, base.method, metric)
        columns, directions = candidate_directions(
            base.model, self.candidate_effects, self.data, base.method, metric
        )
        reference, channels = reference_directions(self.data, metric)
        # Where the refitted model has no periodic solution the likelihood counts the miss
        # as FAILED_RESIDUAL standard errors (said in words by the summary), and a step of
        # a parameter there gives no direction.
        residual = self.data.mean_residual(base.predicted)
        failed = ~np.isfinite(residual) & self.data.used
        residual = np.where(failed, FAILED_RESIDUAL * self.standard_error, residual)
        return cal.Problem.build(
            self.data, metric, residual, np.nan_to_num(jacobian, nan=0.0, posinf=0.0,
            neginf=0.0), columns, directions, reference, channels,
        )  # fmt: skip

    @cached_property
    def observed(self) -> cal.Statistics:
        """The statistics of the measured campaign."""
        problem = self.problem
        covariance = problem.metric.covariance.mean[None]
        return cal.statistics(problem, problem.residual[None], covariance, keep_frame=True)

    @cached_property
    def calibration(self) -> cal.Calibration:
        """Thresholds by parametric bootstrap under the refitted base model."""
        config = self.config
        return cal.calibrate(
            self.problem, self.observed, alpha=config.alpha, n_bootstrap=config.n_bootstrap,
            seed=config.seed,
        )  # fmt: skip

    @cached_property
    def effect_gains(self) -> dict[str, tuple[float, int]]:
        """Per candidate effect: its best column's gain and the column's index."""
        gains = self.observed.column_gain[0]
        out: dict[str, tuple[float, int]] = {}
        for i, direction in enumerate(self.problem.directions):
            if direction.effect not in out or gains[i] > out[direction.effect][0]:
                out[direction.effect] = (float(gains[i]), i)
        return out

    @property
    def threshold(self) -> float:
        """The calibrated catalogue threshold (a ``χ²`` gain)."""
        return self.calibration.catalogue_threshold

    @cached_property
    def p_value(self) -> float:
        """Bootstrap p-value of the decision (catalogue and reference tests combined)."""
        return self.calibration.p_value(self.observed.catalogue[0], self.observed.reference[0])

    @cached_property
    def reference(self) -> FreeForm:
        """The free-form reference fitted to the data (its describing functions)."""
        table = mean_prediction(self.data, self.base.predicted)
        return fit_reference(self.problem, self.observed, self.data, table)

    @cached_property
    def drift(self) -> list[Drift]:
        """Drift seen between up- and down-stepped branches (empty without both)."""
        return branch_drift(self.data, self.config.alpha)

    # ---------------------------------------------------------------- compare
    @cached_property
    def comparison(self) -> dict[str, dict[str, np.ndarray]]:
        """Per channel at the levels: measured mean, prediction of the base model (refitted,
        or the posterior median), residual, standard error (and ``band_low``/``band_high``/
        ``coverage`` with a posterior)."""
        data = self.data
        mean_residual = data.mean_residual(self.base.predicted)
        measured_mean, _ = data.level_mean(data.values)
        se = self.standard_error
        predicted = mean_prediction(data, self.base.predicted)
        out = {}
        band = None
        if self.posterior is not None:
            names, draws = self.posterior
            samples = self.fitter.predict(
                self.model, data.levels_m, method=self.base.method, parameters=draws, names=names
            )
            band = np.nanquantile(samples, [0.025, 0.975], axis=0)
            curves = data.curves_at_levels
        for j, channel in enumerate(data.channels):
            entry = {
                "measured_mean": measured_mean[:, j],
                "predicted": predicted[:, j],
                "residual": mean_residual[:, j],
                "standard_error": se[:, j],
            }
            if band is not None:
                inside = (curves[:, :, j] >= band[0][:, j]) & (curves[:, :, j] <= band[1][:, j])
                entry |= {
                    "band_low": band[0][:, j],
                    "band_high": band[1][:, j],
                    "coverage": np.mean(inside, axis=0),
                }
            out[channel] = entry
        return out

    @cached_property
    def standard_error(self) -> np.ndarray:
        """``(n_levels, n_channels)`` standard error of the mean curve in the metric."""
        table = np.full(self.metric.keep.size, np.nan)
        table[self.metric.keep] = self.metric.covariance.standard_error
        return table.reshape(self.data.levels_m.size, -1)

    def residual(self, channel: str) -> tuple[np.ndarray, np.ndarray]:
        """Mean residual (measured − base model) of a channel at the levels and its standard
        error (the likelihood's, widened by a posterior's population-mean uncertainty)."""
        entry = self.comparison[channel]
        return entry["residual"], entry["standard_error"]

    @cached_property
    def standardised(self) -> np.ndarray:
        """``(n_levels, n_channels)`` post-fit residual over its standard error."""
        table = np.full(self.metric.keep.size, np.nan)
        table[self.metric.keep] = self.observed.standardised[0]
        return table.reshape(self.data.levels_m.size, -1)

    def where(self) -> list[FailureRange]:
        """Amplitude ranges where the refitted model's standardised residual exceeds the
        calibrated bound (runs of consecutive levels of one sign; a harmonic order fails
        where its cosine or sine part does)."""
        bound = self.calibration.where_bound
        amplitudes_mm = 1e3 * self.data.levels_m
        z = self.standardised
        ranges = []
        for channel in BACKBONE_CHANNELS:
            j = self.data.column(channel)
            residual, _ = self.residual(channel)
            # levels with no periodic solution are said in words (the summary's own line)
            significant = (np.abs(np.nan_to_num(z[:, j])) > bound) & np.isfinite(residual)
            for start, stop in runs(np.sign(residual) * significant, 1):
                worst = start + int(np.argmax(np.abs(z[start:stop, j])))
                ranges.append(
                    FailureRange(
                        channel, float(amplitudes_mm[start]), float(amplitudes_mm[stop - 1]),
                        float(residual[worst]),
                        "under-predicted" if residual[worst] > 0 else "over-predicted",
                        float(abs(z[worst, j])),
                    )
                )  # fmt: skip
        if self.data.has_harmonics:
            for order in HARMONIC_ORDERS:
                parts = [self.comparison[f"harmonic{order}_{p}"] for p in ("cos", "sin")]
                columns = [self.data.column(f"harmonic{order}_{p}") for p in ("cos", "sin")]
                size = np.abs(np.nan_to_num(z[:, columns])).max(axis=1)
                miss, measured, predicted = (
                    np.hypot(*(part[key] for part in parts))
                    for key in ("residual", "measured_mean", "predicted")
                )
                for start, stop in runs(((size > bound) & np.isfinite(miss)).astype(float), 1):
                    worst = start + int(np.argmax(size[start:stop]))
                    ranges.append(
                        FailureRange(
                            f"harmonic{order}", float(amplitudes_mm[start]),
                            float(amplitudes_mm[stop - 1]), float(miss[worst]),
                            "under-predicted" if measured[worst] > predicted[worst]
                            else "over-predicted", float(size[worst]),
                        )
                    )  # fmt: skip
        return ranges

    # ---------------------------------------------------------------- decide
    @cached_property
    def fires(self) -> dict[str, bool]:
        """Which calibrated tests fire: the catalogue's, the reference's, ``where()``'s (the
        last describes; it does not decide, see :attr:`significant`)."""
        return {
            "catalogue": bool(self.observed.catalogue[0] > self.calibration.catalogue_threshold),
            "reference": bool(self.observed.reference[0] > self.calibration.reference_threshold),
            "where": bool(self.where()),
        }

    @property
    def significant(self) -> bool:
        """Whether something is missing: the calibrated decision alone.

        The catalogue test or the free-form reference test fires; the two are combined by
        the smaller of their bootstrap p-values and calibrated jointly
        (:func:`~identification.criticism.calibration.calibrate`), so that either fires on
        a campaign the refitted model explains with probability ``alpha``. ``where()`` only
        says where: a finding no single level shows is :attr:`small`, not absent (a gate on
        it is outside the calibration and costs power where an effect is a small trend over
        many levels).
        """
        fires = self.fires
        return fires["catalogue"] or fires["reference"]

    @property
    def small(self) -> bool:
        """Something is missing that no single level shows: the decision fires, and
        ``where()`` finds no level beyond its bound — seen in the trend over the levels,
        within the scatter at each."""
        return self.significant and not self.fires["where"]

    @cached_property
    def beyond_scatter(self) -> tuple[str, ...]:
        """Channel groups where the refitted base model's post-fit ``χ²`` exceeds its
        calibrated bound: the adequacy test a candidate must pass (``Candidate.beyond``),
        applied to the model criticised."""
        bounds = self.calibration.channel_bounds
        chi2 = self.channel_chi2(self.base)
        return tuple(g for g in chi2 if chi2[g] > bounds.get(g, np.inf))

    # ------------------------------------------------------- judging a refit
    def channel_chi2(self, fit: FitResult) -> dict[str, float]:
        """Post-fit ``χ²`` per channel group in the metric (NaN entries count as failures)."""
        metric = self.metric
        residual = metric.weights * self.data.mean_residual(fit.predicted).reshape(-1)[metric.keep]
        se = metric.covariance.standard_error * metric.weights
        residual = np.where(np.isfinite(residual), residual, 1e3 * se)
        covariance = self.problem.weighted(metric.covariance.mean)
        out = {}
        for g, group in enumerate(cal.GROUPS):
            rows = np.flatnonzero(self.problem.group_of == g)
            if rows.size:
                block = np.linalg.cholesky(covariance[np.ix_(rows, rows)])
                out[group] = float(np.sum(np.linalg.solve(block, residual[rows]) ** 2))
        return out

    def chi2(self, fit: FitResult) -> float:
        """``χ²`` of a fit's mean residual in this criticism's metric."""
        z = self.metric.whiten(self.data.mean_residual(fit.predicted))
        return float(z @ z)

    def worse(self, before: Mapping[str, float], fit: FitResult) -> tuple[str, ...]:
        """Channel groups ``fit`` makes worse beyond their noise against ``before`` (their
        ``χ²``; see :data:`~identification.criticism.config.WORSE`)."""
        return worse(before, self.channel_chi2(fit), self.calibration.channel_bounds)

    def objections(self, fit: FitResult, before: Mapping[str, float]) -> list[str]:
        """Why a refitted replacement cannot stand in for what it replaced, in words: no
        periodic solution over part of the test, what makes it inadmissible as physics,
        and the channel groups it makes worse beyond their noise against ``before``.
        Empty: it can."""
        if not fit.solved:
            return [fit.outcome_text]
        table = mean_prediction(self.data, fit.predicted)
        f, z = self.data.column("frequency_hz"), self.data.column("damping_ratio")
        problems = admissibility(fit.model, self.data.levels_m, table[:, f], table[:, z])
        return [*problems, *(f"{g} worse" for g in self.worse(before, fit))]


def worse(
    before: Mapping[str, float], after: Mapping[str, float], bounds: Mapping[str, float]
) -> tuple[str, ...]:
    """Channel groups a change makes worse beyond their noise (see :data:`WORSE`)."""
    return tuple(
        g
        for g in after
        if after[g] > bounds.get(g, np.inf) and after[g] - before[g] > max(WORSE, before[g])
    )


def runs(sign: np.ndarray, min_run: int) -> list[tuple[int, int]]:
    """``[start, stop)`` of runs of equal non-zero values at least ``min_run`` long."""
    out, start = [], None
    for i in range(sign.size + 1):
        value = sign[i] if i < sign.size else 0.0
        if start is not None and value != sign[start]:
            if i - start >= min_run:
                out.append((start, i))
            start = None
        if start is None and value != 0:
            start = i
    return out


def separation(decision: Decision, best: Candidate, other: Candidate) -> float:
    """χ² gain of ``best`` over a model that already has ``other`` (linearised at the
    base, along their fitted signatures): small when the data cannot tell them apart."""
    keep, weights = decision.metric.keep, decision.metric.weights
    columns = np.column_stack(
        [weights * np.stack(list(c.signature.values()), axis=1).reshape(-1)[keep]
         for c in (best, other)]
    )  # fmt: skip
    columns = np.nan_to_num(columns)
    projected = cal.project(decision.observed, columns)
    u, v = projected[:, 0], projected[:, 1]
    if v @ v > 0:
        u = u - v * (v @ u) / (v @ v)
    norm = u @ u
    return float((u @ decision.observed.frame["z"]) ** 2 / norm) if norm > 0 else 0.0
