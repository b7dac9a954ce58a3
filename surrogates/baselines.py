"""The baselines every surrogate accuracy figure stands beside.

:class:`MeanCurve`
    One curve for every parameter vector: the weighted mean of the training
    curves at each (grid point, channel). What a surrogate that learned nothing
    about the parameters scores.
:class:`PolynomialBaseline`
    A separate least-squares regression on the parameters (min–max scaled to the
    box) at each (grid point, channel): with ``degree=1`` the per-point linear
    regression, what a first-order sensitivity model scores (a surrogate that
    does not beat it clearly has learned no nonlinearity worth a network); with
    ``degree=3`` a cubic response surface, the classical surrogate a network
    has to beat to earn its keep.

Both are fitted on the same training rows and loss weights as the network
(an entry of weight 0, e.g. a masked value, is not used) and predict the same
``(n, n_levels, n_channels)`` layout; the mask channel's predictions are clipped
to [0, 1]. An entry keeps the monomials up to the highest degree that leaves at
least two weighted training values per coefficient (the mean alone if none
does). Plain numpy, so they run wherever the evaluation does.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np

from surrogates.runtime import MASK_CHANNEL, SurrogateSpec

__all__ = ["MeanCurve", "PolynomialBaseline", "monomial_factors", "monomials"]

#: Weighted training values an entry needs per coefficient of its regression.
ROWS_PER_COEFFICIENT = 2


def monomial_factors(n_params: int, degree: int) -> np.ndarray:
    """``(n_monomials, degree)`` factors of every monomial of degree ≤ ``degree``.

    Each row names ``degree`` factors from ``[1, u_1, …, u_n]`` (index 0 is the
    constant 1). The rows are ordered by degree: the first ``C(n + d, d)`` rows
    are the monomials of degree ≤ ``d``, the intercept first, then ``u_1 … u_n``.
    """
    if degree < 1:
        raise ValueError(f"degree must be ≥ 1, got {degree}")
    return np.array(list(itertools.combinations_with_replacement(range(n_params + 1), degree)))


def monomials(unit: np.ndarray, degree: int) -> np.ndarray:
    """``(n, n_monomials)`` values of the monomials of :func:`monomial_factors`."""
    augmented = np.column_stack([np.ones(len(unit)), unit])
    return np.prod(augmented[:, monomial_factors(unit.shape[1], degree)], axis=2)


def _unit(spec: SurrogateSpec, parameters: np.ndarray) -> np.ndarray:
    bounds = spec.bounds
    return (spec.check_parameters(parameters) - bounds[:, 0]) / (bounds[:, 1] - bounds[:, 0])


def _weighted_means(backbones: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``(n_levels, n_channels)`` weighted means; a point without weight takes its channel's."""
    total = weights.sum(axis=0)
    channel = (weights * backbones).sum(axis=(0, 1)) / np.maximum(weights.sum(axis=(0, 1)), 1e-300)
    means = (weights * backbones).sum(axis=0) / np.where(total > 0, total, 1.0)
    return np.where(total > 0, means, channel)


def _clip_mask(spec: SurrogateSpec, backbones: np.ndarray) -> np.ndarray:
    if MASK_CHANNEL in spec.channels:
        index = spec.channel_index(MASK_CHANNEL)
        backbones[..., index] = np.clip(backbones[..., index], 0.0, 1.0)
    return backbones


def _check(spec: SurrogateSpec, parameters, backbones, weights) -> tuple[np.ndarray, ...]:
    x = _unit(spec, parameters)
    y = spec.check_backbones(backbones, "baseline training backbones")
    w = np.broadcast_to(np.asarray(weights, dtype=float), y.shape)
    if x.shape[0] != y.shape[0] or not np.all(np.isfinite(w) & (w >= 0)):
        raise ValueError(
            f"baseline: {x.shape[0]} parameter vectors, {y.shape[0]} backbones; weights must be "
            "finite and ≥ 0"
        )
    return x, y, w


@dataclass(frozen=True)
class MeanCurve:
    """The weighted mean training curve, predicted for every parameter vector."""

    spec: SurrogateSpec
    curve: np.ndarray

    @classmethod
    def fit(
        cls, spec: SurrogateSpec, parameters: np.ndarray, backbones: np.ndarray, weights=1.0
    ) -> MeanCurve:
        """Fit on ``(n, n_params)`` parameters and ``(n, n_levels, n_channels)`` values, weights."""
        _, y, w = _check(spec, parameters, backbones, weights)
        return cls(spec, _weighted_means(y, w))

    def predict(self, parameters: np.ndarray) -> np.ndarray:
        """``(n, n_levels, n_channels)``: the mean curve, once per vector."""
        n = self.spec.check_parameters(parameters).shape[0]
        return _clip_mask(self.spec, np.repeat(self.curve[None], n, axis=0))


@dataclass(frozen=True)
class PolynomialBaseline:
    """Per (grid point, channel) polynomial least squares on the box-scaled parameters.

    Attributes
    ----------
    degree
        Highest total degree of the monomials.
    coefficients
        ``(n_monomials, n_levels, n_channels)`` in the order of
        :func:`monomial_factors` (intercept, then one slope per parameter scaled
        to [0, 1] over the box, then the higher degrees); an entry with too few
        weighted training values has zeros beyond the degree it could carry.
    carried_degree
        ``(n_levels, n_channels)`` the degree each entry carries (≤ ``degree``;
        0: the mean alone): where masked values leave too few weighted training
        rows, e.g. at the top of the amplitude grid, a "cubic" is quadratic.
    """

    spec: SurrogateSpec
    degree: int
    coefficients: np.ndarray
    carried_degree: np.ndarray

    @classmethod
    def fit(
        cls,
        spec: SurrogateSpec,
        parameters: np.ndarray,
        backbones: np.ndarray,
        weights=1.0,
        degree: int = 1,
    ) -> PolynomialBaseline:
        """Fit on ``(n, n_params)`` parameters and ``(n, n_levels, n_channels)`` values, weights."""
        x, y, w = _check(spec, parameters, backbones, weights)
        design = monomials(x, degree)
        sizes = [math.comb(spec.n_params + d, d) for d in range(1, degree + 1)]
        coefficients = np.zeros((design.shape[1], *spec.backbone_shape))
        coefficients[0] = _weighted_means(y, w)
        carried = np.zeros(spec.backbone_shape, dtype=int)
        for level, channel in np.ndindex(*spec.backbone_shape):
            root = np.sqrt(w[:, level, channel])
            used = root > 0
            fitting = [s for s in sizes if ROWS_PER_COEFFICIENT * s <= used.sum()]
            if not fitting:
                continue
            columns = fitting[-1]
            solution = np.linalg.lstsq(
                design[used, :columns] * root[used, None],
                y[used, level, channel] * root[used],
                rcond=None,
            )[0]
            coefficients[:, level, channel] = 0.0
            coefficients[:columns, level, channel] = solution
            carried[level, channel] = len(fitting)
        return cls(spec, degree, coefficients, carried)

    def predict(self, parameters: np.ndarray) -> np.ndarray:
        """``(n, n_levels, n_channels)`` predictions."""
        design = monomials(_unit(self.spec, parameters), self.degree)
        return _clip_mask(self.spec, np.einsum("np,plc->nlc", design, self.coefficients))
