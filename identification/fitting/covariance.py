"""The covariance of a population-mean residual: between-curve scatter, shrunk and floored.

Measured curves ``Y_c`` (``n`` curves, each at the same ``L`` amplitude levels in
``C`` channels, flattened to ``p = L·C`` values) scatter around the population mean
``μ``. Every point of a curve shares that assembly's offsets (a stiffer assembly
is stiffer at every level), so the points of one curve are *not* independent: the
mean curve ``Ȳ`` has covariance ``Σ/n`` with ``Σ`` the between-curve covariance of
whole curves. With a handful of curves (``n ≪ p``) the sample covariance is
singular, so it is shrunk (Schäfer & Strimmer 2005, with the data-driven intensity):
the correlations toward a target stationary along the levels
(:func:`along_levels_target`: within a channel the correlation depends on the level
distance only, pooled over the levels, which keeps the strong correlation of an
assembly's offsets along the curve that a target of zero correlation shrinks away with
few curves; zero between channels), the variances
of each channel toward its median over the levels (Opgen-Rhein & Strimmer 2007); and
floored by the hold fits' own standard errors.

A stated **systematic floor** (what the measurement chain adds that does not
average out over curves: a phase-detector bias, sensor nonlinearity) is added to
the covariance of the *mean*, not of each curve: ``V = Σ/n + diag(floor²)``.

With **one curve** there is no population scatter: ``Σ`` is the within-curve
noise, estimated per channel from the curve's roughness along the levels (the
pseudo-residuals of Gasser, Sroka & Jennen-Steinmetz 1986: each point against the
line through its neighbours), floored by the standard errors. The population
scatter is then unknown, and reports must say so.

:func:`estimate` works on a batch of campaigns at once, so that a parametric
bootstrap re-estimates the covariance of every simulated campaign exactly as the
analysis of the measured one does.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import solve_triangular

__all__ = [
    "LevelCovariance",
    "along_levels_target",
    "estimate",
    "gasser_noise_variance",
    "shrunk_covariance",
]


@dataclass(frozen=True, eq=False)
class LevelCovariance:
    """Covariance of the mean of ``n_curves`` curves at the levels, and its parts.

    Attributes
    ----------
    per_curve
        ``(p, p)`` covariance of one curve's values (between-curve scatter, or the
        within-curve noise of a single curve), shrunk and floored.
    floor
        ``(p,)`` systematic floor variances, added to the covariance of the mean.
    n_curves
        Curves averaged.
    correlation_shrinkage, variance_shrinkage
        Intensities used (1: fully shrunk to the target; NaN: not applicable).
    kind
        ``"between-curve"`` or ``"within-curve"`` (one curve: population scatter unknown).
    extra
        Added to the covariance of the mean (0, or ``(p, p)``).
    """

    per_curve: np.ndarray
    floor: np.ndarray
    n_curves: int
    correlation_shrinkage: float
    variance_shrinkage: float
    kind: str
    extra: np.ndarray | float = 0.0

    @cached_property
    def mean(self) -> np.ndarray:
        """``(p, p)`` covariance of the mean curve: ``per_curve / n + diag(floor)`` (+ ``extra``,
        e.g. the uncertainty of a posterior's population-mean curve)."""
        return self.per_curve / self.n_curves + np.diag(self.floor) + self.extra

    @cached_property
    def cholesky(self) -> np.ndarray:
        """Lower Cholesky factor of :attr:`mean`."""
        return np.linalg.cholesky(self.mean)

    @property
    def standard_error(self) -> np.ndarray:
        """``(p,)`` standard error of each entry of the mean curve."""
        return np.sqrt(np.diag(self.mean))

    def whiten(self, residual: ArrayLike) -> np.ndarray:
        """``L⁻¹ r`` (``r`` of shape ``(p,)`` or ``(p, k)``): unit covariance under the model."""
        return solve_triangular(self.cholesky, np.asarray(residual, float), lower=True)

    def widened(self, extra: np.ndarray) -> LevelCovariance:
        """This covariance with ``extra`` (``(p, p)``) added to that of the mean."""
        return dataclasses.replace(self, extra=self.extra + extra)


def shrunk_covariance(
    curves: np.ndarray, channel_of: np.ndarray, variance_floor: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shrinkage covariance of whole curves, for a batch of campaigns.

    Parameters
    ----------
    curves
        ``(batch, n, p)`` curves (``n ≥ 2``), flattened level-major (entry ``l·C + c``).
    channel_of
        ``(p,)`` channel index of each entry: the variances of a channel shrink
        toward that channel's median (channels have different units).
    variance_floor
        ``(p,)`` or ``(batch, p)`` lower bound of each variance (the hold fits' errors).

    Returns
    -------
    ``(batch, p, p)`` covariances, ``(batch,)`` correlation and ``(batch,)`` variance
    shrinkage intensities.
    """
    batch, n, p = curves.shape
    centred = curves - curves.mean(axis=1, keepdims=True)
    variance = np.einsum("bki,bki->bi", centred, centred) / (n - 1)
    # Variances: toward the channel's median, with the estimated variance of each s_ii.
    squares = centred**2
    var_of_variance = (
        n / (n - 1) ** 3 * np.sum((squares - squares.mean(axis=1, keepdims=True)) ** 2, axis=1)
    )
    target = np.empty_like(variance)
    for c in np.unique(channel_of):
        columns = channel_of == c
        target[:, columns] = np.median(variance[:, columns], axis=1, keepdims=True)
    spread = np.sum((variance - target) ** 2, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        lam_v = np.clip(np.sum(var_of_variance, axis=1) / spread, 0.0, 1.0)
    lam_v = np.where(np.isfinite(lam_v), lam_v, 1.0)
    shrunk_variance = lam_v[:, None] * target + (1 - lam_v[:, None]) * variance
    shrunk_variance = np.maximum(shrunk_variance, variance_floor)
    # Correlations: toward the stationary target, with the estimated variance of each r_ij.
    if n < 3:
        # Two curves correlate every pair by ±1: no information on the correlations.
        lam_r = np.ones(batch)
        correlation = np.broadcast_to(np.eye(p), (batch, p, p)).copy()
    else:
        scale = np.sqrt(np.where(variance > 0, variance, 1.0))
        standard = centred / scale[:, None, :]
        # Σ_k (w_kij − w̄_ij)² with w_kij = u_ki u_kj, as Σ_k u_ki² u_kj² − n w̄_ij²: two
        # matrix products instead of an (n, p, p) array per campaign.
        mean_product = np.swapaxes(standard, 1, 2) @ standard / n
        fourth = np.swapaxes(standard**2, 1, 2) @ standard**2
        var_r = n / (n - 1) ** 3 * np.clip(fourth - n * mean_product**2, 0.0, None)
        r = mean_product * n / (n - 1)
        target = along_levels_target(r, channel_of)
        off = ~np.eye(p, dtype=bool)
        with np.errstate(invalid="ignore", divide="ignore"):
            lam_r = np.clip(
                var_r[:, off].sum(axis=1) / ((r - target)[:, off] ** 2).sum(axis=1), 0.0, 1.0
            )
        lam_r = np.where(np.isfinite(lam_r), lam_r, 1.0)
        correlation = (1 - lam_r[:, None, None]) * r + lam_r[:, None, None] * target
        correlation[:, np.arange(p), np.arange(p)] = 1.0
        flat = (variance <= 0)[:, :, None] | (variance <= 0)[:, None, :]
        correlation = np.where(flat & off, 0.0, correlation)
    sd = np.sqrt(shrunk_variance)
    return correlation * sd[:, :, None] * sd[:, None, :], lam_r, lam_v


def along_levels_target(correlation: np.ndarray, channel_of: np.ndarray) -> np.ndarray:
    """Shrinkage target of the correlations: within each channel stationary along the
    levels (a function of the level distance only), between channels zero.

    An assembly's offsets move every level of a channel together (a stiffer assembly is
    stiffer at every amplitude), so neighbouring levels of a curve are strongly
    correlated; a target of zero correlation shrinks that away with few curves, and a
    bootstrap drawn from the shrunk estimate then under-disperses the smooth directions
    the candidates test. The target's correlation of a channel at levels ``l`` and
    ``l + k`` pools every such pair, divided by the number of levels (the biased,
    Bartlett autocorrelation: the sum of each curve's own, so every channel's block is
    positive definite; long distances are tapered toward zero). Correlations between
    channels are not pooled: a block-Toeplitz target across channels has rank at most
    ``n·(2L − 1)``, singular with few curves and several channels.

    Parameters
    ----------
    correlation
        ``(batch, p, p)`` sample correlations, unit diagonal, entries level-major.
    channel_of
        ``(p,)`` channel of each entry; every level has every channel, in the same order.

    Returns
    -------
    ``(batch, p, p)`` target correlations (unit diagonal).
    """
    channels = np.unique(channel_of).size
    n_levels = channel_of.size // channels
    grid = correlation.reshape(-1, n_levels, channels, n_levels, channels)
    within = np.diagonal(grid, axis1=2, axis2=4)  # (batch, l, l', c)
    # pooled[b, k, c]: the mean over l of the correlation of (l, c) with (l + k, c), k ≥ 0
    pooled = np.stack(
        [np.trace(within, offset=k, axis1=1, axis2=2) / n_levels for k in range(n_levels)], axis=1
    )
    distance = np.abs(np.arange(n_levels)[:, None] - np.arange(n_levels)[None, :])
    target = np.zeros_like(grid)
    for c in range(channels):
        target[:, :, c, :, c] = pooled[:, distance, c]
    target = target.reshape(correlation.shape)
    target[:, np.arange(channel_of.size), np.arange(channel_of.size)] = 1.0
    return target


def gasser_noise_variance(values: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Noise variance of smooth curves from their pseudo-residuals (Gasser et al. 1986).

    Parameters
    ----------
    values
        ``(batch, L, C)`` one curve per campaign at ``L ≥ 3`` positions, ``C`` channels.
    positions
        ``(L,)`` increasing positions (log-amplitudes of the levels).

    Returns
    -------
    ``(batch, C)`` variance per channel: each interior point against the straight
    line through its two neighbours, scaled so that independent noise of variance
    σ² gives σ² on average. Curvature of the true curve adds to it (conservative).
    """
    x = np.asarray(positions, float)
    a = (x[2:] - x[1:-1]) / (x[2:] - x[:-2])
    b = 1.0 - a
    pseudo = a[:, None] * values[:, :-2] + b[:, None] * values[:, 2:] - values[:, 1:-1]
    weight = 1.0 / (a**2 + b**2 + 1.0)
    return np.mean(weight[:, None] * pseudo**2, axis=1)


def estimate(
    curves: np.ndarray,
    channel_of: np.ndarray,
    positions: np.ndarray,
    variance_floor: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-curve covariance of a batch of campaigns, as the analysis estimates it.

    ``curves`` is ``(batch, n, p)`` with ``p = L·C`` (level-major: entry ``l·C + c``);
    two or more curves give :func:`shrunk_covariance`, one curve a diagonal of
    :func:`gasser_noise_variance` per channel. Returns the covariances and the
    correlation and variance shrinkage intensities (NaN for one curve).
    """
    batch, n, p = curves.shape
    if n >= 2:
        return shrunk_covariance(curves, channel_of, variance_floor)
    n_channels = int(channel_of.max()) + 1
    levels = p // n_channels
    variance = gasser_noise_variance(curves[:, 0].reshape(batch, levels, n_channels), positions)
    diagonal = np.maximum(variance[:, channel_of], variance_floor)
    nan = np.full(batch, np.nan)
    return np.einsum("bi,ij->bij", diagonal, np.eye(p)), nan, nan
