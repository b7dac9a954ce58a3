"""The paper's backbone-amplitude term (population matching) for PyMC.

A parameter vector is scored by the joint density of the measured backbone
values (:class:`~pm_joint.distributions.density.BackboneDensity`) at the
forward model's prediction interpolated to the same amplitude levels. The
posterior then describes a population range of assemblies: the paper's
method, valid as the population's distribution where the forward model is
one-to-one over the prior box. It is a potential, not a likelihood of the
measured curves (:func:`BackboneAmplitude`).

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
    has_backbone: TensorLike | None = None,
) -> TensorVariable:
    """The paper's population matching inside a ``pm.Model``: a potential, not a likelihood.

    The term is ``log p(prediction)``, the log density of the forward model's
    prediction at the amplitude levels under the population density fitted to
    the measured curves (:class:`BackboneDensity`). The measured values enter
    only through that density: the term is not a likelihood of the measured
    curves, so it is a ``pm.Potential`` and ``pm.compute_log_likelihood``,
    LOO and WAIC have nothing of it to score (:func:`pm_joint.analysis.loo`
    says so). Its posterior over θ is the set of parameter vectors whose
    predictions look like members of the measured population: a population
    range, valid as the population's distribution only where the forward
    model is one-to-one over the prior box
    (:func:`pm_joint.analysis.identifiability` checks that at the draws);
    else the prior box shapes the marginals.

    Parameters
    ----------
    name
        Name of the potential; the prediction is the deterministic
        ``{name}_predicted`` and the measured matrix the data ``{name}_measured``.
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
    has_backbone
        ``(n_points,)`` probabilities that the model has a backbone point at each
        of ``backbone``'s amplitudes (the mask channel of an amplitude-grid
        surrogate, :meth:`~pm_joint.forward.surrogate.SurrogateOp.has_backbone`).
        Interpolated onto the levels, their log sum (the levels taken as
        independent) is added as the potential ``{name}_has_backbone``: a
        parameter vector without a backbone where the curves were measured is
        improbable by that much, with a gradient, instead of giving NaN.

    Notes
    -----
    Posterior draws of ``{name}_predicted`` are noise-free predictions of the
    model at the levels: their spread is the spread of θ, to be compared with
    the measured population.
    """
    density = density or BackboneDensity.fit(
        observed, amplitudes_m, channels=channels, family=family
    )
    # Counted at the levels: NaN there (and only there) is what makes logp = -inf.
    predicted = NanCounter(name)(
        interpolate_backbone(backbone, density.amplitudes_m, density.channels)
    )
    predicted = pm.Deterministic(f"{name}_predicted", predicted)
    if has_backbone is not None:
        backbone = pt.as_tensor_variable(backbone)
        order = pt.argsort(backbone[:, 0])
        probability = pt.interp(
            density.amplitudes_m, backbone[order, 0], pt.as_tensor_variable(has_backbone)[order]
        )
        pm.Potential(f"{name}_has_backbone", pt.sum(pt.log(pt.clip(probability, 1e-12, 1.0))))
    # Kept with the draws (constant_data), so a report can check the density it is given.
    pm.Data(f"{name}_measured", density.observations)
    return pm.Potential(name, logp_graph(density, predicted))
