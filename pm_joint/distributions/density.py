"""The joint density of measured backbone values across amplitude levels.

At chosen amplitude levels every measured backbone gives a frequency (and,
optionally, a damping ratio). Across the measured curves these values form a
joint distribution: per-level marginals (the normal, unless another unbounded
scipy.stats family beats its AICc by a margin calibrated for the number of curves:
:mod:`~pm_joint.distributions.family_choice`) joined by a Gaussian copula, or a
multivariate normal. :class:`BackboneDensity`
is that fitted density (numpy, scipy); the same density as a pytensor graph
and as a PyMC distribution is in :mod:`pm_joint.distributions.backbone_amplitude`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats
from sklearn.covariance import ledoit_wolf_shrinkage

from identification.measurements.backbone import BackboneSet
from pm_joint.distributions.families import UNBOUNDED_CANDIDATES, DistributionFit
from pm_joint.distributions.family_choice import choose_family

__all__ = ["CHANNELS", "BackboneDensity", "amplitude_levels", "level_marks"]

CHANNELS = ("frequency_hz", "damping_ratio")


def amplitude_levels(measured: BackboneSet, n_levels: int = 9, inset: float = 0.02) -> np.ndarray:
    """A grid of ``n_levels`` amplitudes (m) over the range all measured curves share.

    ``inset`` trims that fraction of the range at both ends so that every
    curve is interpolated, never extrapolated.
    """
    if n_levels < 3:
        raise ValueError(f"need at least 3 amplitude levels (low, mid, high), got {n_levels}")
    low, high = measured.common_range()
    if not high > low:
        raise ValueError(
            f"the measured backbones share no amplitude range (common range {low:.4g}–{high:.4g} m)"
        )
    span = high - low
    return np.linspace(low + inset * span, high - inset * span, n_levels)


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
        One :class:`~pm_joint.distributions.families.DistributionFit` per dimension (copula).
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
        prefer_normal: bool = True,
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
        marginals = tuple(
            choose_family(column, candidates, prefer_normal=prefer_normal) for column in values.T
        )
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

    def sample(self, n_curves: int, rng: np.random.Generator | int | None = None) -> np.ndarray:
        """Draw ``n_curves`` synthetic measured curves (n_curves, n_dims) from the density."""
        rng = np.random.default_rng(rng)
        if self.family == "mvn":
            return rng.multivariate_normal(self.mean, self.correlation, size=n_curves)
        z = rng.multivariate_normal(np.zeros(self.n_dims), self.correlation, size=n_curves)
        u = stats.norm.cdf(z)
        return np.column_stack([m.dist.ppf(u[:, j]) for j, m in enumerate(self.marginals)])

    def to_dict(self) -> dict[str, Any]:
        """Everything the density is made of, as JSON types (floats kept exactly)."""
        return {
            "amplitudes_m": self.amplitudes_m.tolist(),
            "channels": list(self.channels),
            "observations": self.observations.tolist(),
            "family": self.family,
            "marginals": [m.to_dict() for m in self.marginals],
            "correlation": self.correlation.tolist(),
            "mean": self.mean.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> BackboneDensity:
        """Inverse of :meth:`to_dict`: the same density, not a refit."""
        return cls(
            amplitudes_m=np.asarray(data["amplitudes_m"], dtype=float),
            channels=tuple(data["channels"]),
            observations=np.asarray(data["observations"], dtype=float),
            family=data["family"],
            marginals=tuple(DistributionFit.from_dict(m) for m in data["marginals"]),
            correlation=np.asarray(data["correlation"], dtype=float),
            mean=np.asarray(data["mean"], dtype=float),
        )

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
LOG_TAIL_FLOOR = -700.0


def _normal_scores(fit: DistributionFit, values: np.ndarray) -> np.ndarray:
    """Φ⁻¹(F(y)) through log-probabilities, accurate in both tails."""
    dist = fit.dist
    lower = np.maximum(dist.logcdf(values), LOG_TAIL_FLOOR)
    upper = np.maximum(dist.logsf(values), LOG_TAIL_FLOOR)
    return np.where(
        lower < np.log(0.5), stats.norm.ppf(np.exp(lower)), -stats.norm.ppf(np.exp(upper))
    )
