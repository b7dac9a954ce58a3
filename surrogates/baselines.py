"""The baselines every surrogate accuracy figure stands beside.

:class:`MeanCurve`
    One curve for every parameter vector: the weighted mean of the training
    curves at each (grid point, channel). What a surrogate that learned nothing
    about the parameters scores.
:class:`LinearBaseline`
    A separate least-squares regression on the parameters (min–max scaled to the
    box) at each (grid point, channel). What a first-order sensitivity model
    scores: a surrogate that does not beat it clearly has learned no
    nonlinearity worth a network.

Both are fitted on the same training rows and loss weights as the network
(an entry of weight 0, e.g. a masked value, is not used) and predict the same
``(n, n_levels, n_channels)`` layout; the mask channel's predictions are clipped
to [0, 1]. Plain numpy, so they run wherever the evaluation does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from surrogates.runtime import MASK_CHANNEL, SurrogateSpec

__all__ = ["LinearBaseline", "MeanCurve"]


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
class LinearBaseline:
    """Per (grid point, channel) least squares on the box-scaled parameters.

    Attributes
    ----------
    coefficients
        ``(1 + n_params, n_levels, n_channels)``: intercept, then one slope per
        parameter scaled to [0, 1] over the box. An entry with fewer weighted
        training values than coefficients keeps the weighted mean (slopes 0).
    """

    spec: SurrogateSpec
    coefficients: np.ndarray

    @classmethod
    def fit(
        cls, spec: SurrogateSpec, parameters: np.ndarray, backbones: np.ndarray, weights=1.0
    ) -> LinearBaseline:
        """Fit on ``(n, n_params)`` parameters and ``(n, n_levels, n_channels)`` values, weights."""
        x, y, w = _check(spec, parameters, backbones, weights)
        design = np.column_stack([np.ones(len(x)), x])
        coefficients = np.zeros((design.shape[1], *spec.backbone_shape))
        coefficients[0] = _weighted_means(y, w)
        for level, channel in np.ndindex(*spec.backbone_shape):
            root = np.sqrt(w[:, level, channel])
            used = root > 0
            if used.sum() <= design.shape[1]:
                continue
            solution = np.linalg.lstsq(
                design[used] * root[used, None], y[used, level, channel] * root[used], rcond=None
            )[0]
            coefficients[:, level, channel] = solution
        return cls(spec, coefficients)

    def predict(self, parameters: np.ndarray) -> np.ndarray:
        """``(n, n_levels, n_channels)`` linear predictions."""
        x = _unit(self.spec, parameters)
        design = np.column_stack([np.ones(len(x)), x])
        return _clip_mask(self.spec, np.einsum("np,plc->nlc", design, self.coefficients))
