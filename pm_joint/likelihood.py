"""The backbone-amplitude likelihood of the paper, as a PyMC distribution.

At chosen amplitude levels every measured backbone gives a frequency (and,
optionally, a damping ratio). Across the measured curves these values form a
joint distribution: per-level marginals (the best scipy.stats family by AIC)
joined by a Gaussian copula, or a multivariate normal. A parameter vector is
scored by that joint density at the forward model's prediction interpolated to
the same levels. The posterior then describes the population of assemblies
the measurements came from, which is what the paper's updating is after.

:class:`BackboneDensity` is the fitted joint density (numpy, scipy);
:func:`logp_graph` is the same density as a pytensor graph (so NUTS can
differentiate through it); :func:`BackboneAmplitude` puts it into a PyMC model.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numba
import numpy as np
import pymc as pm
import pytensor.tensor as pt
from numpy.typing import ArrayLike
from pytensor.graph.basic import Apply
from pytensor.graph.op import Op
from pytensor.link.numba.dispatch.basic import numba_njit, register_funcify_default_op_cache_key
from scipy import stats
from sklearn.covariance import ledoit_wolf_shrinkage

from identification.measurements.backbone import BackboneSet
from pm_joint.fitting import UNBOUNDED_CANDIDATES, DistributionFit, fit_best
from pm_joint.forward import BACKBONE_COLUMNS

__all__ = [
    "BackboneAmplitude",
    "BackboneDensity",
    "amplitude_levels",
    "interpolate_backbone",
    "level_marks",
    "logp_graph",
]

CHANNELS = ("frequency_hz", "damping_ratio")


def amplitude_levels(measured: BackboneSet, n: int = 9, inset: float = 0.02) -> np.ndarray:
    """A grid of ``n`` amplitudes (m) over the range all measured curves share.

    ``inset`` trims that fraction of the range at both ends so that every
    curve is interpolated, never extrapolated.
    """
    if n < 3:
        raise ValueError(f"need at least 3 amplitude levels (low, mid, high), got {n}")
    low, high = measured.common_range()
    if not high > low:
        raise ValueError(
            f"the measured backbones share no amplitude range (common range {low:.4g}–{high:.4g} m)"
        )
    span = high - low
    return np.linspace(low + inset * span, high - inset * span, n)


def level_marks(amplitudes_m: ArrayLike) -> dict[str, int]:
    """Indices of the low, mid and high amplitude levels (the paper's Fig. 22)."""
    n = len(np.asarray(amplitudes_m))
    return {"low": 0, "mid": n // 2, "high": n - 1}


def _observations(
    measured: BackboneSet | ArrayLike, amplitudes_m: np.ndarray, channels: Sequence[str]
) -> np.ndarray:
    """Measured values at the levels, (n_curves, n_levels × n_channels), channel-major."""
    if isinstance(measured, BackboneSet):
        low, high = measured.common_range()
        outside = (amplitudes_m < low) | (amplitudes_m > high)
        if np.any(outside):
            raise ValueError(
                f"amplitude levels {amplitudes_m[outside]} m lie outside the range all measured "
                f"curves share ({low:.4g}–{high:.4g} m)"
            )
        blocks = []
        for channel in channels:
            if channel == "frequency_hz":
                blocks.append(measured.frequency_matrix(amplitudes_m))
            else:
                blocks.append(measured.damping_matrix(amplitudes_m))
        return np.concatenate(blocks, axis=1)
    values = np.asarray(measured, dtype=float)
    expected = len(amplitudes_m) * len(channels)
    if values.ndim != 2 or values.shape[1] != expected:
        raise ValueError(
            f"measured values must be (n_curves, {expected}) for {len(amplitudes_m)} levels × "
            f"{len(channels)} channel(s), got shape {values.shape}"
        )
    return values


@dataclass(frozen=True)
class BackboneDensity:
    """Joint density of measured backbone values across amplitude levels.

    Attributes
    ----------
    amplitudes_m
        The amplitude levels (m).
    channels
        ``("frequency_hz",)`` or ``("frequency_hz", "damping_ratio")``.
    observations
        The measured values, (n_curves, n_levels × n_channels), channel-major.
    family
        ``"copula"`` (fitted marginals + Gaussian copula) or ``"mvn"``.
    marginals
        One :class:`~pm_joint.fitting.DistributionFit` per dimension (copula).
    correlation
        Copula correlation of the normal scores, or the MVN covariance.
    mean
        MVN mean (empty for the copula).
    """

    amplitudes_m: np.ndarray
    channels: tuple[str, ...]
    observations: np.ndarray
    family: str
    marginals: tuple[DistributionFit, ...]
    correlation: np.ndarray
    mean: np.ndarray

    @classmethod
    def fit(
        cls,
        measured: BackboneSet | ArrayLike,
        amplitudes_m: ArrayLike | None = None,
        *,
        channels: Sequence[str] = ("frequency_hz",),
        family: str = "copula",
        candidates: tuple[str, ...] = UNBOUNDED_CANDIDATES,
        shrinkage: float | None = None,
    ) -> BackboneDensity:
        """Fit the joint density to measured backbones.

        Parameters
        ----------
        measured
            A :class:`~identification.measurements.backbone.BackboneSet`, or a ready matrix
            (n_curves, n_levels × n_channels).
        amplitudes_m
            Amplitude levels (m); default :func:`amplitude_levels` of ``measured``.
        channels
            Which backbone channels enter the density.
        family
            ``"copula"`` or ``"mvn"``.
        candidates
            scipy.stats families tried for each marginal (copula), ranked by AICc;
            unbounded ones by default, so a prediction just beyond the measured
            values is unlikely rather than impossible.
        shrinkage
            Weight of the diagonal in the covariance (or correlation) estimate;
            default: the Ledoit–Wolf optimum for the number of curves and
            levels, which keeps the joint density well conditioned when there
            are few curves for many levels.
        """
        channels = tuple(channels)
        for channel in channels:
            if channel not in CHANNELS:
                raise ValueError(f"unknown channel {channel!r}; choose from {CHANNELS}")
        if family not in ("copula", "mvn"):
            raise ValueError(f"family must be 'copula' or 'mvn', got {family!r}")
        if amplitudes_m is None:
            if not isinstance(measured, BackboneSet):
                raise ValueError("amplitude levels are required when measured is a matrix")
            amplitudes_m = amplitude_levels(measured)
        amplitudes_m = np.asarray(amplitudes_m, dtype=float)
        if amplitudes_m.ndim != 1 or amplitudes_m.size == 0:
            raise ValueError(f"amplitude levels must be a non-empty 1-D array, got {amplitudes_m}")
        if not (np.all(np.diff(amplitudes_m) > 0) and amplitudes_m[0] > 0):
            raise ValueError(
                f"amplitude levels must be positive and strictly increasing, got {amplitudes_m}"
            )
        values = _observations(measured, amplitudes_m, channels)
        if values.shape[0] < 3:
            raise ValueError(f"need at least 3 measured curves, got {values.shape[0]}")
        if not np.all(np.isfinite(values)):
            raise ValueError("measured values at the amplitude levels contain NaN or inf")
        flat = np.flatnonzero(np.ptp(values, axis=0) == 0)
        if flat.size:
            channel, level = divmod(int(flat[0]), amplitudes_m.size)
            raise ValueError(
                f"every measured curve has the same {channels[channel]} at the amplitude level "
                f"{1e3 * amplitudes_m[level]:.4g} mm: no spread to build a density from"
            )
        identity = np.eye(values.shape[1])
        if family == "mvn":
            cov = np.cov(values, rowvar=False)
            weight = _shrinkage(values) if shrinkage is None else shrinkage
            cov = (1 - weight) * cov + weight * np.diag(np.diag(cov))
            return cls(amplitudes_m, channels, values, family, (), cov, values.mean(axis=0))
        marginals = tuple(fit_best(column, candidates, "aicc")[0] for column in values.T)
        scores = np.column_stack(
            [_normal_scores(m, column) for m, column in zip(marginals, values.T, strict=True)]
        )
        corr = np.corrcoef(scores, rowvar=False)
        weight = _shrinkage(scores) if shrinkage is None else shrinkage
        corr = (1 - weight) * corr + weight * identity
        return cls(amplitudes_m, channels, values, family, marginals, corr, np.empty(0))

    @property
    def n_dims(self) -> int:
        return self.observations.shape[1]

    def logpdf(self, values: ArrayLike) -> np.ndarray:
        """Joint log density of values (..., n_dims); -inf where any is NaN."""
        y = np.asarray(values, dtype=float)
        if y.shape[-1] != self.n_dims:
            raise ValueError(f"values must end in {self.n_dims} dimensions, got shape {y.shape}")
        if self.family == "mvn":
            # Cholesky by hand: frequency (~1e2) and damping (~1e-3) make the
            # covariance badly scaled for scipy's eigenvalue-based singularity test.
            chol = np.linalg.cholesky(self.correlation)
            r = np.linalg.solve(chol, np.moveaxis(y - self.mean, -1, 0).reshape(self.n_dims, -1))
            quad = np.sum(r**2, axis=0).reshape(y.shape[:-1])
            logdet = 2 * np.sum(np.log(np.diag(chol)))
            out = -0.5 * (quad + logdet + self.n_dims * np.log(2 * np.pi))
        else:
            log_marginal = sum(m.dist.logpdf(y[..., j]) for j, m in enumerate(self.marginals))
            z = np.stack([_normal_scores(m, y[..., j]) for j, m in enumerate(self.marginals)], -1)
            precision = np.linalg.inv(self.correlation) - np.eye(self.n_dims)
            _, logdet = np.linalg.slogdet(self.correlation)
            quad = np.einsum("...i,ij,...j->...", z, precision, z)
            out = log_marginal - 0.5 * quad - 0.5 * logdet
        out = np.where(np.any(np.isnan(y), axis=-1), -np.inf, out)
        return np.nan_to_num(out, nan=-np.inf)

    def sample(self, n: int, rng: np.random.Generator | int | None = None) -> np.ndarray:
        """Draw ``n`` synthetic measured curves (n, n_dims) from the density."""
        rng = np.random.default_rng(rng)
        if self.family == "mvn":
            return rng.multivariate_normal(self.mean, self.correlation, size=n)
        z = rng.multivariate_normal(np.zeros(self.n_dims), self.correlation, size=n)
        u = stats.norm.cdf(z)
        return np.column_stack([m.dist.ppf(u[:, j]) for j, m in enumerate(self.marginals)])

    def split(self, values: ArrayLike) -> dict[str, np.ndarray]:
        """Split (..., n_dims) values into one (..., n_levels) array per channel."""
        y = np.asarray(values)
        n = len(self.amplitudes_m)
        return {c: y[..., i * n : (i + 1) * n] for i, c in enumerate(self.channels)}


def _shrinkage(values: np.ndarray) -> float:
    """Ledoit–Wolf shrinkage weight of standardised columns (toward the identity)."""
    standardised = (values - values.mean(0)) / values.std(0)
    return float(ledoit_wolf_shrinkage(standardised, assume_centered=True))


#: Log-probabilities are floored here before Φ⁻¹ (|z| ≤ 37): far beyond the
#: measured spread the marginal log density already decides, and a tail
#: probability that underflows to 0 would turn a poor fit into logp = -inf.
_LOG_TAIL_FLOOR = -700.0


def _normal_scores(fit: DistributionFit, values: np.ndarray) -> np.ndarray:
    """Φ⁻¹(F(y)) through log-probabilities, accurate in both tails."""
    dist = fit.dist
    lower = np.maximum(dist.logcdf(values), _LOG_TAIL_FLOOR)
    upper = np.maximum(dist.logsf(values), _LOG_TAIL_FLOOR)
    return np.where(
        lower < np.log(0.5), stats.norm.ppf(np.exp(lower)), -stats.norm.ppf(np.exp(upper))
    )


# ---------------------------------------------------------------------------
# pytensor graph of the same density


def _marginal_graph(fit: DistributionFit, y):
    """(logpdf, logcdf, logsf) of a fitted scipy family as pytensor expressions."""
    p = fit.params
    family = fit.family
    if family == "gumbel_l":  # the mirror image of gumbel_r
        dist = pm.Gumbel.dist(mu=-p[0], beta=p[1])
        return pm.logp(dist, -y), pm.logccdf(dist, -y), pm.logcdf(dist, -y)
    shifted = y
    if family == "norm":
        dist = pm.Normal.dist(mu=p[0], sigma=p[1])
    elif family == "logistic":
        dist = pm.Logistic.dist(mu=p[0], s=p[1])
    elif family == "t":
        dist = pm.StudentT.dist(nu=p[0], mu=p[1], sigma=p[2])
    elif family == "gumbel_r":
        dist = pm.Gumbel.dist(mu=p[0], beta=p[1])
    elif family == "lognorm":
        dist, shifted = pm.LogNormal.dist(mu=np.log(p[2]), sigma=p[0]), y - p[1]
    elif family == "gamma":
        dist, shifted = pm.Gamma.dist(alpha=p[0], beta=1.0 / p[2]), y - p[1]
    elif family == "weibull_min":
        dist, shifted = pm.Weibull.dist(alpha=p[0], beta=p[2]), y - p[1]
    else:
        raise ValueError(f"no pytensor form for the {family!r} family")
    return pm.logp(dist, shifted), pm.logcdf(dist, shifted), pm.logccdf(dist, shifted)


def _normal_score_graph(logcdf, logsf):
    # Φ⁻¹(u) = −√2 erfcinv(2u): from the lower tail below the median, from the
    # upper tail above it, so neither branch loses precision.
    logcdf = pt.maximum(logcdf, _LOG_TAIL_FLOOR)
    logsf = pt.maximum(logsf, _LOG_TAIL_FLOOR)
    lower = -np.sqrt(2.0) * pt.erfcinv(2.0 * pt.exp(logcdf))
    upper = np.sqrt(2.0) * pt.erfcinv(2.0 * pt.exp(logsf))
    return pt.switch(logcdf < np.log(0.5), lower, upper)


def logp_graph(density: BackboneDensity, values):
    """The density's log value at ``values`` (pytensor, (..., n_dims) → (...))."""
    y = pt.as_tensor_variable(values)
    if density.family == "mvn":
        logp = pm.logp(pm.MvNormal.dist(mu=density.mean, cov=density.correlation), y)
    else:
        parts = [_marginal_graph(m, y[..., j]) for j, m in enumerate(density.marginals)]
        log_marginal = pt.sum(pt.stack([lp for lp, _, _ in parts], axis=-1), axis=-1)
        z = pt.stack([_normal_score_graph(lc, ls) for _, lc, ls in parts], axis=-1)
        precision = np.linalg.inv(density.correlation) - np.eye(density.n_dims)
        _, logdet = np.linalg.slogdet(density.correlation)
        quad = pt.sum(pt.dot(z, precision) * z, axis=-1)
        logp = log_marginal - 0.5 * quad - 0.5 * logdet
    return pt.switch(pt.any(pt.isnan(y), axis=-1) | pt.isnan(logp), -np.inf, logp)


# ---------------------------------------------------------------------------
# forward-model output → values at the levels


class NanCounter(Op):
    """Identity that counts (and warns about) forward-model outputs with NaN.

    A forward model that fails for some parameter vector returns NaN; the
    likelihood turns that into logp = -inf so a chain rejects the proposal
    and goes on. This Op keeps the count (per process) so it can be reported.
    Under the numba backend it runs natively (see :func:`_numba_nan_counter`).
    """

    __props__ = ("label",)

    def __init__(self, label: str) -> None:
        self.label = label

    counts: dict[str, int] = {}  # noqa: RUF012 - a shared tally across instances is the point

    def make_node(self, x):
        x = pt.as_tensor_variable(x)
        return Apply(self, [x], [x.type()])

    def perform(self, node, inputs, outputs):
        (x,) = inputs
        if np.isnan(x).any():
            _count_nan(self.label)
        outputs[0][0] = np.array(x, copy=True)

    def pullback(self, inputs, outputs, cotangents):
        return [cotangents[0]]


def _count_nan(label: str) -> None:
    """One more NaN output under ``label``; warn at 1, 10, 100, 1000 and every 10 000."""
    n = NanCounter.counts.get(label, 0) + 1
    NanCounter.counts[label] = n
    if n in (1, 10, 100, 1000) or n % 10_000 == 0:
        warnings.warn(
            f"{label}: forward model returned NaN {n} time(s); those proposals get logp = -inf",
            RuntimeWarning,
            stacklevel=2,
        )


@register_funcify_default_op_cache_key(NanCounter)
def _numba_nan_counter(op, node=None, **kwargs):
    # Python's perform would run in numba object mode: a per-call toll and, worse,
    # a compiled logp that numba cannot cache. Natively, only the rare NaN call
    # drops to object mode to count.
    label = op.label

    @numba_njit
    def nan_counter(x):
        if np.isnan(x).any():
            with numba.objmode():
                _count_nan(label)
        return x.copy()

    return nan_counter


def interpolate_backbone(backbone, amplitudes_m: ArrayLike, channels: Sequence[str]):
    """Values of a predicted backbone at amplitude levels (pytensor, channel-major).

    ``backbone`` is a (n_points, 3) tensor in the common layout
    ``[amplitude_m, frequency_hz, damping_ratio]``. Levels outside the predicted
    amplitude range give NaN (the prediction does not reach them), never a
    clamped end value.
    """
    backbone = pt.as_tensor_variable(backbone)
    order = pt.argsort(backbone[:, 0])
    amplitude = backbone[order, 0]
    levels = np.asarray(amplitudes_m, dtype=float)
    blocks = []
    for channel in channels:
        column = BACKBONE_COLUMNS.index(channel)
        blocks.append(
            pt.interp(levels, amplitude, backbone[order, column], left=np.nan, right=np.nan)
        )
    return pt.concatenate(blocks)


def BackboneAmplitude(
    name: str,
    backbone,
    *,
    observed: BackboneSet | ArrayLike,
    levels: ArrayLike | None = None,
    channels: Sequence[str] = ("frequency_hz",),
    family: str = "copula",
    density: BackboneDensity | None = None,
):
    """The paper's backbone-amplitude likelihood inside a ``pm.Model``.

    Parameters
    ----------
    name
        Name of the observed variable.
    backbone
        Forward-model output in the common layout, (n_points, 3).
    observed
        The measured backbones (a BackboneSet), or a ready matrix with ``levels``.
    levels
        Amplitude levels (m); default: a grid over the range all curves share.
    channels
        ``("frequency_hz",)`` (the paper) or with ``"damping_ratio"``.
    family
        ``"copula"`` or ``"mvn"`` (see :class:`BackboneDensity`).
    density
        A ready :class:`BackboneDensity` (skips fitting).

    Notes
    -----
    Each row of the observed matrix (one measured curve) carries 1/n_curves of
    ``log p(prediction)``, so the sum PyMC forms is the paper's log-likelihood
    and the measured values are kept in the trace's ``observed_data``. Draws of
    the variable (prior/posterior predictive) are the model's prediction at the
    levels, to be compared with the measured population. The prediction is
    stored as the deterministic ``{name}_predicted``.
    """
    density = density or BackboneDensity.fit(observed, levels, channels=channels, family=family)
    # Counted at the levels: NaN there (and only there) is what makes logp = -inf.
    predicted = NanCounter(name)(
        interpolate_backbone(backbone, density.amplitudes_m, density.channels)
    )
    predicted = pm.Deterministic(f"{name}_predicted", predicted)
    n_curves = density.observations.shape[0]

    def logp(value, prediction):
        return pt.zeros(value.shape[:-1]) + logp_graph(density, prediction) / n_curves

    def random(prediction, rng=None, size=None):
        shape = (*(size or ()), prediction.shape[-1])
        return np.broadcast_to(prediction, shape).copy()

    return pm.CustomDist(
        name,
        predicted,
        logp=logp,
        random=random,
        signature="(d)->(d)",
        observed=density.observations,
    )
