"""The criticism's statistics, linearised at the refitted model, and their calibration.

**The statistic.** Around the refitted base model the mean residual ``r`` (the
likelihood's, :mod:`identification.fitting.data`) is, to first order,
``r = J δ + g c + e`` with ``J`` the base model's own directions, ``g`` a candidate's
(:mod:`identification.criticism.directions`) and ``e ~ N(0, V)``. Whitened by ``V``
and projected off ``J`` (the base refit), the score of a candidate column is
``s = g⊥ᵀ z⊥ / |g⊥|``, and ``s²`` is the Gauss–Newton gain in ``χ²`` of adding it:
one-sided where only one sign of the coefficient is physical. The catalogue
statistic is the largest ``s²`` over every candidate and every value of its shape
grid; the free-form reference's is the gain ``|U_Bᵀ z⊥|²`` of its whole basis.
:func:`statistics` computes them, with the residual's post-fit ``χ²`` in total and per
channel group (frequency, damping, harmonics) and the residual standardised level by
level (what ``where()`` reads).

**The calibration.** A parametric bootstrap under the refitted base model
(:func:`calibrate`): whole campaigns of ``n`` curves drawn around the fitted mean like
the measured curves (:func:`scatter`: the measured assemblies' offsets along the base
model's own directions, plus the rest of their scatter drawn unfloored), plus a
systematic offset drawn from the floors; each campaign's covariance re-estimated as the
analysis estimates the measured one (shrunk and floored: with few curves the covariance's
own uncertainty matters as much as the residual's); the statistics computed on each. The
catalogue and reference tests are combined by the smaller of their bootstrap p-values,
calibrated so that *either* fires on a null campaign with probability ``α``; the
``where()`` bound, the adequacy bounds per channel group and of the total ``χ²`` are the
``1 − α`` quantiles of theirs. The floors stand for systematic errors of the measurement
chain; where a campaign carries less, the test is conservative, and the same bootstrap
without the floors' draw gives its **effective level**
(:attr:`Calibration.effective_level`). Everything is linear algebra on ``p × p``
matrices, so thousands of bootstrap campaigns are cheap.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
from scipy.linalg import solve_triangular

from identification.criticism.directions import Direction
from identification.fitting import covariance as cov
from identification.fitting.data import FitData, Metric

__all__ = [
    "ALPHA",
    "BOOTSTRAP_BATCH",
    "GROUPS",
    "N_BOOTSTRAP",
    "Calibration",
    "Problem",
    "Statistics",
    "calibrate",
    "statistics",
]

#: Default false-discovery level of one decision.
ALPHA = 0.01
#: Default number of bootstrap campaigns.
N_BOOTSTRAP = 2000
#: Channel groups of the adequacy checks.
GROUPS = ("frequency_hz", "damping_ratio", "harmonics")
#: Campaigns per batch of the bootstrap (memory: batch × p × columns floats).
BOOTSTRAP_BATCH = 250


@dataclass(frozen=True, eq=False)
class Problem:
    """The linearised problem at the refitted base model.

    Attributes
    ----------
    residual
        ``(p,)`` weighted mean residual of the refitted base model (kept entries).
    base, candidates, reference
        ``(p, ·)`` weighted directions: the base model's parameters, the candidates'
        columns (described by ``directions``), the free-form reference's columns.
    directions
        What each candidate column is.
    reference_channels
        Channel of each reference column.
    metric
        The likelihood's metric (kept entries, weights, covariance).
    channel_of, group_of
        ``(p,)`` channel index (among kept channels) and group index (:data:`GROUPS`)
        of each entry.
    positions
        ``(n_levels,)`` log-amplitudes of the levels.
    variance_floor
        ``(p,)`` floor of each per-curve variance (the hold fits' standard errors).
    curves
        ``(n, p)`` the measured curves at the levels (kept entries, unweighted): what the
        bootstrap's campaigns are drawn like (:func:`scatter`).
    """

    residual: np.ndarray
    base: np.ndarray
    candidates: np.ndarray
    directions: list[Direction]
    reference: np.ndarray
    reference_channels: list[str]
    metric: Metric
    channel_of: np.ndarray
    group_of: np.ndarray
    positions: np.ndarray
    variance_floor: np.ndarray
    curves: np.ndarray

    @classmethod
    def build(
        cls,
        data: FitData,
        metric: Metric,
        residual: np.ndarray,
        base: np.ndarray,
        candidates: np.ndarray,
        directions: list[Direction],
        reference: np.ndarray,
        reference_channels: list[str],
    ) -> Problem:
        """The problem of ``data`` in ``metric`` (``residual`` the ``(n_levels, n_channels)``
        mean residual of the refitted base model; the directions already flattened)."""
        n_levels, n_channels = data.levels_m.size, len(data.channels)
        kept_channels = metric.keep.reshape(n_levels, n_channels)[0]
        index = np.cumsum(kept_channels) - 1
        channel_of = np.tile(index[kept_channels], n_levels)
        group_names = [_group(c) for c in np.array(data.channels)[kept_channels]]
        group_of = np.tile([GROUPS.index(g) for g in group_names], n_levels)
        errors = data.at_levels(data.standard_error**2)[:, :, kept_channels]
        curves = data.curves_at_levels.reshape(data.n_curves, -1)[:, metric.keep]
        return cls(
            residual=metric.weights * residual.reshape(-1)[metric.keep],
            base=base,
            candidates=candidates,
            directions=directions,
            reference=reference,
            reference_channels=reference_channels,
            metric=metric,
            channel_of=channel_of,
            group_of=group_of,
            positions=np.log(data.levels_m),
            variance_floor=np.nanmean(errors, axis=0).reshape(-1),
            curves=curves,
        )

    @property
    def size(self) -> int:
        return self.residual.size

    @cached_property
    def drawn_scatter(self) -> tuple[np.ndarray, np.ndarray]:
        """What the bootstrap draws its curves like (:func:`scatter`)."""
        return scatter(self)

    def weighted(self, covariance: np.ndarray) -> np.ndarray:
        """The covariance of weighted residual entries, ``D_w V D_w``."""
        w = self.metric.weights
        return w[..., :, None] * covariance * w[..., None, :]

    def effects(self) -> list[str]:
        """The candidate effects, in column order, each once."""
        return list(dict.fromkeys(d.effect for d in self.directions))


def _group(channel: str) -> str:
    return "harmonics" if channel.startswith("harmonic") else channel


@dataclass(frozen=True, eq=False)
class Statistics:
    """The statistics of a batch of campaigns (leading axis), see the module notes.

    Attributes
    ----------
    scores
        ``(B, M)`` signed score of every candidate column (0 for a silent column).
    column_gain
        ``(B, M)`` its ``χ²`` gain (``s²``; 0 for the unphysical sign of a one-sided effect).
    catalogue
        ``(B,)`` the largest column gain.
    reference
        ``(B,)`` the free-form reference's ``χ²`` gain.
    chi2
        ``(B,)`` post-fit ``χ²`` of the residual.
    standardised
        ``(B, p)`` post-fit residual over its standard error, entry by entry.
    channel_chi2
        ``(B, len(GROUPS))`` post-fit ``χ²`` of each channel group (NaN where absent).
    reference_rank
        Columns of the reference left after the projection (its degrees of freedom).
    """

    scores: np.ndarray
    column_gain: np.ndarray
    catalogue: np.ndarray
    reference: np.ndarray
    chi2: np.ndarray
    standardised: np.ndarray
    channel_chi2: np.ndarray
    reference_rank: int
    frame: dict = field(default_factory=dict, repr=False)

    @property
    def where_statistic(self) -> np.ndarray:
        """``(B,)`` the largest standardised residual."""
        return np.max(np.abs(self.standardised), axis=1)


def statistics(
    problem: Problem,
    residual: np.ndarray,
    covariance: np.ndarray,
    reference_rank: int | None = None,
    keep_frame: bool = False,
) -> Statistics:
    """The statistics of campaigns: ``residual`` ``(B, p)`` weighted mean residuals,
    ``covariance`` ``(B, p, p)`` the covariance of each campaign's (unweighted) mean.

    ``reference_rank`` fixes the reference's degrees of freedom (the observed
    campaign's); ``keep_frame`` keeps the whitening of a single campaign for
    :func:`project` (the observed one).
    """
    batch, _p = residual.shape
    weighted = problem.weighted(covariance)
    factor = np.linalg.cholesky(weighted)
    k, m = problem.base.shape[1], problem.candidates.shape[1]
    columns = np.hstack([problem.base, problem.candidates, problem.reference])
    # One inverse per campaign and a batched product: thousands of small triangular
    # solves cost more in call overhead than in arithmetic.
    inverse = np.linalg.inv(factor)
    white = np.concatenate(
        [inverse @ columns, np.einsum("bij,bj->bi", inverse, residual)[:, :, None]], axis=2
    )
    basis, _ = np.linalg.qr(white[:, :, :k])
    projected = white - basis @ (np.swapaxes(basis, 1, 2) @ white)
    candidates = projected[:, :, k : k + m]
    reference = projected[:, :, k + m : -1]
    z = projected[:, :, -1]
    norms = np.linalg.norm(candidates, axis=1)
    dots = np.einsum("bpm,bp->bm", candidates, z)
    scale = np.linalg.norm(white[:, :, k : k + m], axis=1)
    silent = (norms <= 1e-9 * np.maximum(scale, 1e-300)) | (norms == 0)
    scores = np.where(silent, 0.0, dots / np.where(silent, 1.0, norms))
    signs = np.array([d.sign for d in problem.directions])
    gain = np.where((signs > 0) & (scores < 0), 0.0, scores**2)
    if reference.shape[2]:
        u, singular, _ = np.linalg.svd(reference, full_matrices=False)
        if reference_rank is None:
            reference_rank = int(np.sum(singular[0] > 1e-8 * singular[0, 0]))
        reference_gain = np.sum(np.einsum("bpr,bp->br", u[:, :, :reference_rank], z) ** 2, axis=1)
    else:
        reference_rank, reference_gain = 0, np.zeros(batch)
    post = np.einsum("bij,bj->bi", factor, z)
    standardised = post / np.sqrt(np.diagonal(weighted, axis1=1, axis2=2))
    channel_chi2 = np.full((batch, len(GROUPS)), np.nan)
    for g in range(len(GROUPS)):
        rows = np.flatnonzero(problem.group_of == g)
        if rows.size:
            block = np.linalg.cholesky(weighted[:, rows][:, :, rows])
            inner = np.linalg.solve(block, post[:, rows, None])[..., 0]
            channel_chi2[:, g] = np.sum(inner**2, axis=1)
    frame = {"factor": factor[0], "basis": basis[0], "z": z[0]} if keep_frame else {}
    return Statistics(
        scores=scores,
        column_gain=gain,
        catalogue=gain.max(axis=1) if m else np.zeros(batch),
        reference=reference_gain,
        chi2=np.sum(z**2, axis=1),
        standardised=standardised,
        channel_chi2=channel_chi2,
        reference_rank=reference_rank,
        frame=frame,
    )


def project(observed: Statistics, columns: np.ndarray) -> np.ndarray:
    """Raw weighted ``(p, q)`` columns whitened in the observed campaign's metric and
    projected off the base model's directions (as the statistics see them)."""
    white = solve_triangular(observed.frame["factor"], columns, lower=True)
    basis = observed.frame["basis"]
    return white - basis @ (basis.T @ white)


# --------------------------------------------------------------------------
# The bootstrap


@dataclass(frozen=True, eq=False)
class Calibration:
    """Thresholds of one criticism, from a parametric bootstrap under the refitted model.

    Attributes
    ----------
    alpha
        Probability that a null campaign fires the decision (catalogue or reference test).
    n_bootstrap, seed
        Bootstrap campaigns and the seed they were drawn with.
    level_each
        Level of each of the two tests (their combination fires with probability ``alpha``).
    catalogue_threshold, reference_threshold
        ``χ²`` gains above which the catalogue's best column / the reference fire.
    where_bound
        Standardised residual above which a level is reported by ``where()``.
    channel_bounds, chi2_bound
        ``1 − α`` quantiles of the post-fit ``χ²`` per channel group and in total: a model
        within them fits within the scatter.
    null_catalogue, null_reference
        The bootstrap's statistics (for p-values and their spread).
    effective_level
        Probability that the decision fires on a null campaign whose measurement chain adds
        no systematic error (the floors stated, none drawn): the level the test holds where
        the floors are larger than the errors they stand for (``alpha`` without floors).
        Measured on lab-rig nulls by ``bench/criticism_nulls.py``.
    seconds
        Time taken.
    """

    alpha: float
    n_bootstrap: int
    seed: int
    level_each: float
    catalogue_threshold: float
    reference_threshold: float
    where_bound: float
    channel_bounds: dict[str, float]
    chi2_bound: float
    null_catalogue: np.ndarray
    null_reference: np.ndarray
    effective_level: float
    seconds: float

    def p_value(self, catalogue: float, reference: float) -> float:
        """Bootstrap p-value of an observed pair, min-p combined like the decision."""
        p_c = (1 + np.sum(self.null_catalogue >= catalogue)) / (self.n_bootstrap + 1)
        p_r = (1 + np.sum(self.null_reference >= reference)) / (self.n_bootstrap + 1)
        combined = np.minimum(_upper_p(self.null_catalogue), _upper_p(self.null_reference))
        return float((1 + np.sum(combined <= min(p_c, p_r))) / (self.n_bootstrap + 1))

    def to_dict(self) -> dict[str, float | int | dict]:
        return {
            "alpha": self.alpha,
            "n_bootstrap": self.n_bootstrap,
            "seed": self.seed,
            "level_each": self.level_each,
            "catalogue": self.catalogue_threshold,
            "reference": self.reference_threshold,
            "where": self.where_bound,
            "channels": dict(self.channel_bounds),
            "chi2": self.chi2_bound,
            "effective_level": self.effective_level,
            "seconds": self.seconds,
        }


def _upper_p(values: np.ndarray) -> np.ndarray:
    """Each bootstrap value's upper-tail p-value within its own sample."""
    order = np.sort(values)
    return (values.size - np.searchsorted(order, values, side="left")) / values.size


def scatter(problem: Problem) -> tuple[np.ndarray, np.ndarray]:
    """What the bootstrap draws its curves like: ``(n, p)`` each measured curve's offsets
    along the base model's directions and the ``(p, p)`` covariance of the rest of its
    scatter (unweighted, kept entries).

    Each curve's deviation from the mean is split into the part the base model's own
    parameters take (its assembly's offsets: a generalised least-squares fit of the base
    directions in the likelihood's metric) and the rest. A bootstrap campaign keeps the
    measured offsets (the refit takes them out of every statistic; they matter only through
    the covariance re-estimated from the curves, which they inflate) and draws the rest
    from the shrinkage estimate of its own covariance, *without* the hold fits' variance
    floor; the analysis' estimator (shrunk, floored) then runs on the drawn curves as it
    ran on the measured ones. The analysis' estimate itself is the wrong thing to draw
    from: shrinkage spreads the offsets, which lie along the model's own directions, into
    every direction, and the floor puts noise where the curves show none; a bootstrap drawn
    from it scatters more than the data off the model's directions, and its p-values pile
    at 1. One curve: no offsets, its within-curve noise
    (:func:`~identification.fitting.covariance.estimate`), unfloored.
    """
    curves = problem.curves
    n, p = curves.shape
    unfloored = np.zeros(p)
    if n == 1:
        noise = cov.estimate(curves[None], problem.channel_of, problem.positions, unfloored)[0]
        return np.zeros((1, p)), noise[0]
    weights = problem.metric.weights
    deviation = curves - curves.mean(axis=0)
    factor = np.linalg.cholesky(problem.weighted(problem.metric.covariance.mean))
    white_base = solve_triangular(factor, problem.base, lower=True)
    white_deviation = solve_triangular(factor, (weights * deviation).T, lower=True)
    offsets = np.linalg.lstsq(white_base, white_deviation, rcond=None)[0].T  # (n, k)
    along = offsets @ problem.base.T / weights
    rest = deviation - along
    noise = cov.estimate(rest[None], problem.channel_of, problem.positions, unfloored)[0][0]
    return along, noise


def simulate(
    problem: Problem, n: int, rng: np.random.Generator, systematic: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """``n`` null campaigns: weighted mean residuals ``(n, p)`` and their re-estimated
    covariances of the mean ``(n, p, p)`` (curves drawn from :func:`scatter`, the covariance
    re-estimated as the analysis estimates the measured one). ``systematic``: the mean
    carries an error drawn from the systematic floors (else none; the floors stay in the
    covariance, as the analysis states them)."""
    covariance = problem.metric.covariance
    p, curves = problem.size, covariance.n_curves
    along, noise = problem.drawn_scatter
    noise = noise + 1e-12 * np.diag(np.maximum(np.diag(noise), np.diag(covariance.per_curve)))
    draws = along + rng.standard_normal((n, curves, p)) @ np.linalg.cholesky(noise).T
    mean = draws.mean(axis=1)
    if systematic:
        mean += rng.standard_normal((n, p)) * np.sqrt(covariance.floor)
    extra = np.asarray(covariance.extra)
    if extra.ndim == 2:  # low rank (a posterior of a few parameters): a square root by eigh
        values, vectors = np.linalg.eigh(extra)
        mean += rng.standard_normal((n, p)) @ (vectors * np.sqrt(np.clip(values, 0, None))).T
    estimated, _, _ = cov.estimate(draws, problem.channel_of, problem.positions,
                                   problem.variance_floor)  # fmt: skip
    of_mean = estimated / curves + np.diag(covariance.floor) + extra
    return problem.metric.weights * mean, of_mean


def calibrate(
    problem: Problem,
    observed: Statistics,
    *,
    alpha: float = ALPHA,
    n_bootstrap: int = N_BOOTSTRAP,
    seed: int = 0,
) -> Calibration:
    """Thresholds of the decision by parametric bootstrap under the refitted base model."""
    if not 0 < alpha < 0.5:
        raise ValueError(f"alpha must be in (0, 0.5), got {alpha}")
    if n_bootstrap < 5 / alpha:  # fewer than 5 exceedances: the quantile is a guess
        raise ValueError(f"n_bootstrap must be ≥ 5/alpha = {5 / alpha:.0f}, got {n_bootstrap}")
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    parts = []
    for first in range(0, n_bootstrap, BOOTSTRAP_BATCH):
        residual, covariance = simulate(problem, min(BOOTSTRAP_BATCH, n_bootstrap - first), rng)
        parts.append(statistics(problem, residual, covariance, observed.reference_rank))
    catalogue = np.concatenate([s.catalogue for s in parts])
    reference = np.concatenate([s.reference for s in parts])
    # Either test fires: min of the two p-values, its α quantile sets each test's level.
    combined = np.minimum(_upper_p(catalogue), _upper_p(reference))
    level = float(np.quantile(combined, alpha, method="inverted_cdf"))
    catalogue_threshold = float(np.quantile(catalogue, 1 - level))
    reference_threshold = float(np.quantile(reference, 1 - level))
    effective = alpha
    if np.any(problem.metric.covariance.floor > 0):
        # The same campaigns less the floors' draw: how often such a campaign fires.
        fired = 0
        for first in range(0, n_bootstrap, BOOTSTRAP_BATCH):
            residual, covariance = simulate(
                problem, min(BOOTSTRAP_BATCH, n_bootstrap - first), rng, systematic=False
            )
            quiet = statistics(problem, residual, covariance, observed.reference_rank)
            fires = (quiet.catalogue > catalogue_threshold) | (
                quiet.reference > reference_threshold
            )
            fired += int(np.sum(fires))
        effective = fired / n_bootstrap
    channel = np.concatenate([s.channel_chi2 for s in parts])
    bounds = {
        g: float(np.quantile(channel[:, i], 1 - alpha))
        for i, g in enumerate(GROUPS)
        if np.isfinite(channel[:, i]).all()
    }
    return Calibration(
        alpha=alpha,
        n_bootstrap=n_bootstrap,
        seed=seed,
        level_each=level,
        catalogue_threshold=catalogue_threshold,
        reference_threshold=reference_threshold,
        where_bound=float(
            np.quantile(np.concatenate([s.where_statistic for s in parts]), 1 - alpha)
        ),
        channel_bounds=bounds,
        chi2_bound=float(np.quantile(np.concatenate([s.chi2 for s in parts]), 1 - alpha)),
        null_catalogue=catalogue,
        null_reference=reference,
        effective_level=effective,
        seconds=time.perf_counter() - start,
    )
