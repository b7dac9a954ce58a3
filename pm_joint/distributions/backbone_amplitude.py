"""The paper's backbone-amplitude likelihood as a PyMC distribution.

A parameter vector is scored by the joint density of the measured backbone
values (:class:`~pm_joint.distributions.density.BackboneDensity`) at the
forward model's prediction interpolated to the same amplitude levels. The
posterior then describes the population of assemblies the measurements came
from, which is what the paper's updating is after.

:func:`logp_graph` is the density as a pytensor graph (so NUTS can
differentiate through it); :func:`BackboneAmplitude` puts it into a PyMC model.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence

import numba
import numpy as np
import pymc as pm
import pytensor.tensor as pt
from numpy.typing import ArrayLike
from pytensor.graph.basic import Apply
from pytensor.graph.op import Op
from pytensor.link.numba.dispatch.basic import numba_njit, register_funcify_default_op_cache_key
from pytensor.tensor.variable import TensorVariable

from identification.measurements.backbone import BackboneSet
from pm_joint.distributions.density import LOG_TAIL_FLOOR, BackboneDensity
from pm_joint.distributions.families import DistributionFit
from pm_joint.forward import BACKBONE_COLUMNS

__all__ = ["BackboneAmplitude", "NanCounter", "interpolate_backbone", "logp_graph"]

#: What a graph input may be: a pytensor variable or anything pytensor makes a constant of.
TensorLike = TensorVariable | ArrayLike


# ---------------------------------------------------------------------------
# pytensor graph of the density


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
    logcdf = pt.maximum(logcdf, LOG_TAIL_FLOOR)
    logsf = pt.maximum(logsf, LOG_TAIL_FLOOR)
    lower = -np.sqrt(2.0) * pt.erfcinv(2.0 * pt.exp(logcdf))
    upper = np.sqrt(2.0) * pt.erfcinv(2.0 * pt.exp(logsf))
    return pt.switch(logcdf < np.log(0.5), lower, upper)


def logp_graph(density: BackboneDensity, values: TensorLike) -> TensorVariable:
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


def interpolate_backbone(
    backbone: TensorLike, amplitudes_m: ArrayLike, channels: Sequence[str]
) -> TensorVariable:
    """Values of a predicted backbone at amplitude levels (pytensor, channel-major).

    ``backbone`` is a (n_points, 3) tensor in the common layout
    ``[amplitude_m, frequency_hz, damping_ratio]``. Levels outside the predicted
    amplitude range give NaN (the prediction does not reach them), never a
    clamped end value.
    """
    backbone = pt.as_tensor_variable(backbone)
    order = pt.argsort(backbone[:, 0])
    amplitude = backbone[order, 0]
    amplitudes_m = np.asarray(amplitudes_m, dtype=float)
    blocks = []
    for channel in channels:
        column = BACKBONE_COLUMNS.index(channel)
        blocks.append(
            pt.interp(amplitudes_m, amplitude, backbone[order, column], left=np.nan, right=np.nan)
        )
    return pt.concatenate(blocks)


def BackboneAmplitude(
    name: str,
    backbone: TensorLike,
    *,
    observed: BackboneSet | ArrayLike,
    amplitudes_m: ArrayLike | None = None,
    channels: Sequence[str] = ("frequency_hz",),
    family: str = "copula",
    density: BackboneDensity | None = None,
) -> TensorVariable:
    """The paper's backbone-amplitude likelihood inside a ``pm.Model``.

    Parameters
    ----------
    name
        Name of the observed variable.
    backbone
        Forward-model output in the common layout, (n_points, 3).
    observed
        The measured backbones (a BackboneSet), or a ready matrix with ``amplitudes_m``.
    amplitudes_m
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
    density = density or BackboneDensity.fit(
        observed, amplitudes_m, channels=channels, family=family
    )
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
