"""The stochastic-updating models, both ordinary ``pm.Model`` objects.

:func:`build_model`
    The paper's population matching: uniform priors on the named parameters,
    a forward model (surrogate, harmonic balance or PLL, chosen by one
    argument) and the backbone-amplitude potential of the measured population.
    The posterior is a population range: the parameter vectors whose
    predictions look like members of the measured population. It is the
    population's distribution only where the forward model is one-to-one over
    the prior box (:func:`pm_joint.analysis.identifiability`); it has no
    likelihood of the measured curves, so LOO refuses it.
:func:`hierarchical_model`
    The statistical population model: one parameter vector per measured
    curve, drawn from a population distribution, each measured point Normal
    around its curve's harmonic-balance backbone with a noise that may change
    with amplitude; a log-likelihood per point (LOO works), posterior
    predictive draws of new assemblies include the population scatter
    (:func:`pm_joint.analysis.population_predictive`). Sampled with NUTS or
    nutpie through the differentiable harmonic-balance graph;
    :func:`studies.population_coverage` checks its calibration on
    campaigns simulated with the PLL simulator.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence

import numpy as np
import pymc as pm
import pytensor.tensor as pt
from numpy.typing import ArrayLike

from identification.analytical.harmonic import backbone
from identification.measurements.backbone import BackboneSet
from identification.model import JointModel, parameter_bounds
from pm_joint.distributions import (
    BackboneAmplitude,
    BackboneDensity,
    amplitude_levels,
    interpolate_backbone,
)
from pm_joint.forward import BACKBONE_COLUMNS, FORWARD_KINDS, forward_model, harmonic_backbone_graph
from pm_joint.inference.truncation import centred_choice, truncation_correction
from surrogates.runtime import SurrogateRuntime

__all__ = [
    "HIERARCHICAL",
    "POPULATION_MATCHING",
    "amplitudes_within_surrogate",
    "build_model",
    "hierarchical_model",
    "surrogate_bounds",
    "uniform_priors",
]

#: Relative half-width of the default prior box around an analytical model's values.
DEFAULT_RELATIVE_SPREAD = 0.5
#: The two population models, as ``sample`` records them (attribute ``population_model``).
POPULATION_MATCHING, HIERARCHICAL = "population matching", "hierarchical"
#: Suffix of the hierarchical model's population-median parameters (``{name}_population``).
POPULATION_SUFFIX = "_population"


def uniform_priors(bounds: Mapping[str, tuple[float, float]]) -> pt.TensorVariable:
    """One ``pm.Uniform`` per named parameter; returns them stacked as θ.

    Call inside ``with pm.Model():``. The order of θ is the order of ``bounds``.
    """
    priors = []
    for name, (low, high) in bounds.items():
        if not (np.isfinite(low) and np.isfinite(high) and low < high):
            raise ValueError(f"bounds of {name!r} must be finite with low < high, got {low, high}")
        priors.append(pm.Uniform(name, lower=low, upper=high))
    return pt.stack(priors)


def build_model(
    model: JointModel | None,
    measured: BackboneSet,
    *,
    forward: str = "harmonic",
    names: Sequence[str] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    surrogate: SurrogateRuntime | str | os.PathLike | None = None,
    amplitudes_m: ArrayLike | None = None,
    channels: Sequence[str] = ("frequency_hz",),
    family: str = "copula",
    density: BackboneDensity | None = None,
    n_grid: int = 41,
    native_graph: bool = False,
) -> pm.Model:
    """The paper's updating model as a ``pm.Model``.

    Parameters
    ----------
    model
        Template joint model (not needed for the surrogate).
    measured
        Measured backbones.
    forward
        ``"surrogate"``, ``"harmonic"`` or ``"pll"``.
    names
        Parameters to update; default: the surrogate's, else all of the model's.
    bounds
        Uniform prior bounds; default: the surrogate's training box, else ±50 %
        (:func:`~identification.model.parameter_bounds`).
    surrogate
        The surrogate runtime or its folder (for ``forward="surrogate"``).
    amplitudes_m
        Amplitude levels (m) of the likelihood; default a grid over the
        measured curves' shared range (:func:`~pm_joint.distributions.amplitude_levels`).
    channels, family
        Passed to :meth:`BackboneDensity.fit <pm_joint.distributions.BackboneDensity.fit>`.
    density
        The likelihood's density, already fitted to ``measured`` (then its own
        levels, channels and family are used and nothing is refitted); give it
        or ``amplitudes_m``, not both.
    n_grid
        Number of amplitude (harmonic) or excitation (PLL) points of the
        forward model's backbone.
    native_graph
        The surrogate's network as a native pytensor graph
        (:class:`~pm_joint.forward.SurrogateGraph`) rather than an onnxruntime
        Op: what gradient samplers (nutpie, NUTS) need to compile the model
        whole. The harmonic balance is native already; the PLL has none.

    Raises
    ------
    ValueError
        For curves without a shared amplitude range, levels outside it, names
        or bounds that do not match the surrogate (or lie outside its training
        box), and a forward model whose prediction at the centre of the prior
        box does not reach every level (NaN there). A prediction that fails
        elsewhere in the box is not an error: it gets ``logp = -inf``, counted
        (:class:`~pm_joint.distributions.NanCounter`), and the chain goes on.
    """
    if forward not in FORWARD_KINDS:
        raise ValueError(f"forward must be one of {FORWARD_KINDS}, got {forward!r}")
    if native_graph and forward == "pll":
        raise ValueError("the PLL simulator has no native pytensor graph (native_graph=True)")
    if density is None:
        grid_m = amplitude_levels(measured) if amplitudes_m is None else amplitudes_m
        density = BackboneDensity.fit(measured, grid_m, channels=channels, family=family)
    elif amplitudes_m is not None:
        raise ValueError("give the likelihood's amplitudes_m or a fitted density, not both")
    if forward == "surrogate":
        runtime = surrogate if isinstance(surrogate, SurrogateRuntime) else None
        if runtime is None:
            if surrogate is None:
                raise ValueError("forward model 'surrogate' needs surrogate= (a runtime or folder)")
            runtime = SurrogateRuntime.load(surrogate)
        names = list(names or runtime.parameter_names)
        bounds = surrogate_bounds(runtime, names, bounds)
        op = forward_model("surrogate", model, names, surrogate=runtime, native_graph=native_graph)
    else:
        if model is None:
            raise ValueError(f"forward model {forward!r} needs a JointModel")
        names = list(names or model.parameter_names)
        if bounds is None:
            box = parameter_bounds(model, names, DEFAULT_RELATIVE_SPREAD)
            bounds = {
                n: (float(low), float(high)) for n, (low, high) in zip(names, box, strict=True)
            }
        low, high = measured.common_range()
        # The levels themselves are grid points: the likelihood then sees the model's
        # own values there, not a linear interpolation between grid points.
        grid = np.union1d(np.linspace(0.5 * low, 1.2 * high, n_grid), density.amplitudes_m)
        if forward == "harmonic":
            op = forward_model("harmonic", model, names, amplitudes_m=grid)
        else:
            excitation_levels = _pll_excitation_levels(model, grid, n_grid)
            op = forward_model("pll", model, names, levels=excitation_levels)
    missing = [n for n in names if n not in bounds]
    if missing:
        raise ValueError(f"no prior bounds for {missing}")
    bounds = {n: bounds[n] for n in names}
    with pm.Model() as pm_model:
        theta = uniform_priors(bounds)  # validates the bounds first
        _check_reaches_levels(op, forward, bounds, density)
        # An amplitude-grid surrogate says where the model has no backbone: a probability.
        grid_surrogate = forward == "surrogate" and op.amplitudes_m is not None
        mask = op.has_backbone(theta) if grid_surrogate else None
        BackboneAmplitude(
            "backbone", op(theta), observed=measured, density=density, has_backbone=mask
        )
    pm_model.forward_op = op  # kept for reports and posterior-predictive backbones
    pm_model.backbone_density = density  # sample() keeps it with the draws
    pm_model.population_model = POPULATION_MATCHING  # sample() keeps it with the draws
    return pm_model


def surrogate_bounds(
    runtime: SurrogateRuntime,
    names: Sequence[str],
    bounds: Mapping[str, tuple[float, float]] | None,
) -> dict[str, tuple[float, float]]:
    """Prior bounds for a surrogate: its training box, or given ones checked against it."""
    expected = list(runtime.parameter_names)
    if sorted(names) != sorted(expected):
        raise ValueError(
            f"the priors name {list(names)} but the surrogate {runtime.source} takes {expected}: "
            f"missing {[n for n in expected if n not in names]}, "
            f"unknown {[n for n in names if n not in expected]}"
        )
    box = {n: tuple(float(v) for v in b) for n, b in zip(expected, runtime.bounds, strict=True)}
    if bounds is None:
        return {n: box[n] for n in names}
    unknown = [n for n in bounds if n not in box]
    if unknown:
        raise ValueError(f"prior bounds for {unknown}, which the surrogate does not take")
    for name, (low, high) in bounds.items():
        (box_low, box_high) = box[name]
        if low < box_low or high > box_high:
            raise ValueError(
                f"prior bounds of {name!r} [{low:.6g}, {high:.6g}] leave the surrogate's training "
                f"box [{box_low:.6g}, {box_high:.6g}]: it would extrapolate there"
            )
    return dict(bounds)


def _check_reaches_levels(op, forward: str, bounds, density: BackboneDensity) -> None:
    """The forward model at the centre of the prior box must predict every level."""
    centre = np.array([0.5 * (low + high) for low, high in bounds.values()])
    # FAST_COMPILE: one evaluation is not worth a numba compile.
    backbone = op(pt.as_tensor(centre)).eval(mode="FAST_COMPILE")
    values = interpolate_backbone(backbone, density.amplitudes_m, density.channels)
    bad = np.isnan(values.eval(mode="FAST_COMPILE")).reshape(len(density.channels), -1)
    if bad.any():
        amplitude = backbone[:, 0][np.isfinite(backbone[:, 1])]
        reach = (
            f"{1e3 * amplitude.min():.4g}–{1e3 * amplitude.max():.4g} mm"
            if amplitude.size
            else "nothing (every point NaN)"
        )
        missed = density.amplitudes_m[bad.any(axis=0)]
        raise ValueError(
            f"the {forward} forward model at the centre of the prior box "
            f"({dict(zip(bounds, centre.round(6).tolist(), strict=True))}) predicts {reach}, "
            f"not the likelihood's levels {np.round(1e3 * missed, 4).tolist()} mm: "
            "check its excitation levels or amplitude grid against the measured range"
        )


def _pll_excitation_levels(
    model: JointModel, amplitudes_m: np.ndarray, n_levels: int
) -> np.ndarray:
    """``n_levels`` base accelerations (m/s²) whose harmonic-balance amplitudes span the grid."""
    hb = backbone(model, amplitudes_m)
    excitation = np.abs(hb.base_acceleration[hb.converged])
    if excitation.size < 3:
        raise ValueError("could not find PLL excitation levels: the model's backbone failed")
    return np.geomspace(excitation.min(), excitation.max(), n_levels)


def amplitudes_within_surrogate(measured: BackboneSet, runtime: SurrogateRuntime) -> np.ndarray:
    """Likelihood levels (m) over the amplitudes both the measurements and the surrogate cover.

    An amplitude-grid surrogate covers its grid for every parameter vector (its
    mask channel says where a backbone exists, which the likelihood scores). On
    excitation levels the surrogate's range is that of its prediction at the
    centre of its training box; a model that cannot be held at the largest
    measured amplitudes (its excitation would have to fall) is compared where it
    can. As many levels as :func:`~pm_joint.distributions.amplitude_levels` gives.
    """
    if runtime.amplitudes_m is not None:
        amplitude = runtime.amplitudes_m
    else:
        centre = np.mean(np.asarray(runtime.bounds, dtype=float), axis=1)
        amplitude = runtime.amplitude_m(centre)
    low, high = measured.common_range()
    low, high = max(low, float(np.min(amplitude))), min(high, float(np.max(amplitude)))
    grid_m = amplitude_levels(measured)
    inside = grid_m[(grid_m >= low) & (grid_m <= high)]
    if inside.size < 3:
        raise ValueError(
            f"the surrogate covers {1e3 * np.min(amplitude):.3g}–{1e3 * np.max(amplitude):.3g} mm "
            f"at the centre of its box: fewer than 3 likelihood levels of the measured range"
        )
    return np.linspace(inside[0], inside[-1], grid_m.size)


def hierarchical_model(
    model: JointModel,
    measured: BackboneSet,
    names: Sequence[str],
    *,
    amplitudes_m: ArrayLike | None = None,
    location_scale: float = 0.5,
    population_scale: float = 0.2,
    channels: Sequence[str] = ("frequency_hz",),
    heteroscedastic: bool = True,
    relative_noise: Sequence[str] = ("damping_ratio",),
    centred: bool | str | Sequence[bool] = True,
    truncation: int | None = 5,
) -> pm.Model:
    """Per-curve parameters from a population distribution, for NUTS or nutpie.

    Each named parameter of curve i is ``θ0 · exp(η_i)`` with θ0 the template's
    value (so signs are kept and scales are O(1)) and ``η_i ~ Normal(μ, σ)``:
    population log-location ``μ ~ Normal(0, location_scale)`` (``log_mean``)
    and spread ``σ ~ HalfNormal(population_scale)`` (``log_spread``) per
    parameter. Each measured value, less the truncation error of the
    single-harmonic balance (``truncation``), is Normal around the curve's
    single-harmonic backbone at the same amplitude. The measurement error of a
    channel is ``σ_c (a / a_ref)^γ_c``, times the measured value for the
    channels of ``relative_noise``: ``{channel}_noise`` (σ_c, half-normal with
    the spread of the measured values, of their logarithms where relative, as
    its scale) at the geometric-mean amplitude ``a_ref`` and, with
    ``heteroscedastic``, a slope ``{channel}_noise_slope`` (γ_c ~ Normal(0, 1)),
    as extraction noise grows where the response is small.

    Parameters
    ----------
    model
        Template model: the structure, and θ0 for the named parameters.
    measured
        Measured backbones, one per assembly.
    names
        Parameters that vary from assembly to assembly.
    amplitudes_m
        Amplitude levels (m) to interpolate every curve at, those inside its
        own measured range (a level a curve did not reach gives it no point);
        default (None) every measured point as it is, which leaves out the
        interpolation error.
    location_scale, population_scale
        Scales of the priors of the log-locations (normal) and of the spreads
        (half-normal), relative, log scale.
    channels
        ``("frequency_hz",)`` or with ``"damping_ratio"``.
    heteroscedastic
        Let the measurement error change with amplitude (a power law);
        False: one error per channel.
    relative_noise
        Channels whose measurement error is relative (proportional to the
        measured value): the damping ratio's by default, as damping estimates
        err in proportion to the damping (on the ``trc-like`` rig the damping
        ratio changes fivefold over the amplitudes, which an absolute power law
        in the amplitude cannot follow).
    centred
        Centred parameters ``η_i`` (True) suit curves that pin their own
        parameters, as backbones with many points do: the non-centred form
        ``η_i = μ + σ z_i`` then couples ``z_i`` and ``σ`` into a funnel (its
        chains do not mix: r̂ up to 1.7 for the linear stiffness on ``trc-like``
        PLL campaigns). ``False`` suits parameters the individual curves hardly
        inform. One bool per parameter mixes the two; ``"auto"`` centres those
        each curve's points pin more tightly than the curves scatter
        (:func:`~pm_joint.inference.truncation.centred_choice`, from the
        per-curve fits of ``truncation``, which it needs).
    truncation
        Highest harmonic of the harmonic balance whose gap to the single-harmonic
        one, at a per-curve point estimate, is subtracted from the measured
        values (:func:`~pm_joint.inference.truncation.truncation_correction`,
        the approximation-error approach); stored as the data
        ``{channel}_truncation``. None: the values as measured (data simulated
        with the single-harmonic balance itself).

    Notes
    -----
    ``θ0·exp(μ_p)``, the population's geometric mean (its median), is the
    deterministic ``{p}_population``; ``theta`` holds the per-curve values.
    The observed variables (one per channel, dims ``point``) give
    ``pm.compute_log_likelihood`` a value per measured point; the data
    ``curve_index`` tells which curve each point belongs to.
    """
    names = list(names)
    template = model.parameters
    check_varying(template, names, channels)
    curve, amplitude, values = curve_points(measured, amplitudes_m)
    theta0 = np.array([template[n] for n in names])
    gaps = {channel: np.zeros(amplitude.size) for channel in channels}
    correction = None
    if truncation is not None:
        correction = truncation_correction(
            model, names, curve, amplitude, values["frequency_hz"], values["damping_ratio"],
            prior_scale=float(np.hypot(location_scale, population_scale)), harmonics=truncation,
        )  # fmt: skip
        gaps = {channel: getattr(correction, channel) for channel in channels}
    if isinstance(centred, str):
        if centred != "auto" or correction is None:
            raise ValueError(
                f"centred='auto' needs truncation (the per-curve fits), got {centred!r}"
            )
        centred = centred_choice(correction)
    centred = np.broadcast_to(np.asarray(centred, dtype=bool), (len(names),))
    log_relative_amplitude = np.log(amplitude) - np.mean(np.log(amplitude))
    coords = {"curve": measured.labels, "parameter": names, "point": np.arange(amplitude.size)}
    with pm.Model(coords=coords) as pm_model:
        theta = population_theta(theta0, names, location_scale, population_scale, centred)
        # Each curve at its own points only (not every curve at every curve's points).
        backbone = harmonic_backbone_graph(model, theta[curve], names, amplitude, pointwise=True)
        pm.Data("amplitude_m", amplitude, dims="point")
        pm.Data("curve_index", curve, dims="point")
        for channel in channels:
            predicted = backbone[:, BACKBONE_COLUMNS.index(channel)]
            observe_channel(
                channel, predicted, values[channel], gaps[channel], log_relative_amplitude,
                heteroscedastic=heteroscedastic, relative=channel in relative_noise,
            )  # fmt: skip
    pm_model.population_model = HIERARCHICAL  # sample() keeps it with the draws
    pm_model.template = model
    pm_model.varying = names
    pm_model.centred = [n for n, c in zip(names, centred, strict=True) if c]
    # What a prediction of new measurements needs (sample() keeps it with the draws).
    pm_model.hierarchical_options = json.dumps(
        {"relative_noise": [c for c in channels if c in relative_noise], "truncation": truncation,
         "centred": pm_model.centred}
    )  # fmt: skip
    return pm_model


def check_varying(
    template: Mapping[str, float], names: Sequence[str], channels: Sequence[str]
) -> None:
    """A hierarchical model's varying parameters (known, not 0 in the template: θ = θ0 e^η)
    and channels (frequency and/or damping ratio); ValueError naming what is wrong."""
    unknown = [n for n in names if n not in template]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the model has {list(template)}")
    zero = [n for n in names if template[n] == 0]
    if zero:
        raise ValueError(f"parameters {zero} are 0 in the template: give them a value")
    if not channels or any(c not in ("frequency_hz", "damping_ratio") for c in channels):
        raise ValueError(f"channels must be 'frequency_hz' and/or 'damping_ratio', got {channels}")


def observe_channel(
    channel: str,
    predicted: pt.TensorVariable,
    values: np.ndarray,
    gaps: np.ndarray,
    log_relative_amplitude: np.ndarray,
    *,
    heteroscedastic: bool,
    relative: bool,
    groups: np.ndarray | None = None,
) -> None:
    """The observed variable ``channel`` (dims ``point``) of a hierarchical model and its noise.

    The measured ``values`` less ``gaps`` are Normal around ``predicted`` with the noise
    of :func:`hierarchical_model` (``{channel}_noise``, with ``heteroscedastic`` its slope
    ``{channel}_noise_slope``, with ``relative`` scaled by the measured value). ``groups``
    (an integer per point, dims ``group`` in the model's coordinates) gives every group of
    points its own noise and slope, as the modes of an N-mode model need (a frequency noise
    in Hz of one mode says nothing of another's); None: one of each, as for one mode.
    """
    # Data: the values scored and the gap subtracted from them travel with the
    # posterior (its constant data).
    pm.Data(f"{channel}_truncation", gaps, dims="point")
    scored = values - gaps
    observed = pm.Data(f"{channel}_measured", scored, dims="point")
    logs = np.log(np.abs(values))  # a measured 0 has no log: left out
    parts = [np.ones(values.size, bool)] if groups is None else [
        groups == g for g in range(int(groups.max()) + 1)
    ]  # fmt: skip
    spread = [
        np.std(logs[p][np.isfinite(logs[p])]) if relative else np.std(values[p]) for p in parts
    ]
    if groups is None:
        noise = pm.HalfNormal(f"{channel}_noise", spread[0])
    else:
        noise = pm.HalfNormal(f"{channel}_noise", np.array(spread), dims="group")[groups]
    if heteroscedastic:
        if groups is None:
            slope = pm.Normal(f"{channel}_noise_slope", 0.0, 1.0)
        else:
            slope = pm.Normal(f"{channel}_noise_slope", 0.0, 1.0, dims="group")[groups]
        noise = noise * pt.exp(slope * log_relative_amplitude)
    if relative:
        # Scaled by the measured value, not the predicted one: a noise that follows
        # the prediction lets the sampler trade fit for noise (chains that diverge
        # and do not mix); at 2 % noise the two scales differ by about 2 %.
        noise = noise * np.abs(scored)
    pm.Normal(channel, predicted, noise, observed=observed, dims="point")


def population_theta(
    theta0: np.ndarray,
    names: Sequence[str],
    location_scale: float,
    population_scale: float,
    centred: np.ndarray,
) -> pt.TensorVariable:
    """Each curve's parameters ``θ = θ₀ exp(η)`` (curve × parameter) of the hierarchical
    population: ``log_mean`` μ, ``log_spread`` σ, η by :func:`population_draws`, and each
    parameter's population value ``θ₀ exp(μ)`` as ``{name}{POPULATION_SUFFIX}``. Inside a
    ``pm.Model`` with the coords ``curve`` and ``parameter``."""
    mu = pm.Normal("log_mean", 0.0, location_scale, dims="parameter")
    sigma = pm.HalfNormal("log_spread", population_scale, dims="parameter")
    return population_values(theta0, names, mu, population_draws(mu, sigma, centred, names))


def population_values(
    theta0: np.ndarray, names: Sequence[str], mu: pt.TensorVariable, eta: pt.TensorVariable
) -> pt.TensorVariable:
    """Each curve's parameters ``θ = θ₀ exp(η)`` as ``theta`` (curve × parameter) and each
    parameter's population value ``θ₀ exp(μ)`` as ``{name}{POPULATION_SUFFIX}``."""
    theta = pm.Deterministic("theta", theta0 * pt.exp(eta), dims=("curve", "parameter"))
    for j, name in enumerate(names):
        pm.Deterministic(f"{name}{POPULATION_SUFFIX}", theta0[j] * pt.exp(mu[j]))
    return theta


def population_draws(
    mu: pt.TensorVariable, sigma: pt.TensorVariable, centred: np.ndarray, names: Sequence[str]
) -> pt.TensorVariable:
    """``η`` (curve × parameter): centred columns as the variable ``eta``, the others as
    ``μ + σ z`` with ``z`` standard normal; one form only where every column has it."""
    if centred.all():
        return pm.Normal("eta", mu, sigma, dims=("curve", "parameter"))
    if not centred.any():
        z = pm.Normal("z", 0.0, 1.0, dims=("curve", "parameter"))
        return mu + sigma * z
    n_curves = pm.modelcontext(None).dim_lengths["curve"]
    columns = np.flatnonzero(centred)
    others = np.flatnonzero(~centred)
    eta_c = pm.Normal("eta_centred", mu[columns], sigma[columns], shape=(n_curves, columns.size))
    z = pm.Normal("z", 0.0, 1.0, shape=(n_curves, others.size))
    eta = pt.zeros((n_curves, len(names)))
    eta = pt.set_subtensor(eta[:, columns], eta_c)
    return pt.set_subtensor(eta[:, others], mu[others] + sigma[others] * z)


def curve_points(
    measured: BackboneSet, amplitudes_m: ArrayLike | None
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Curve index, amplitude (m) and channel values of every point, flat.

    With ``amplitudes_m`` every curve is interpolated at the levels inside its
    own measured range (a curve that did not reach a level has no point there,
    as in the test); without, each curve's own points are taken.
    """
    if amplitudes_m is None:
        amplitudes = [b.amplitude_m for b in measured]
        frequency = np.concatenate([b.frequency_hz for b in measured])
        damping = np.concatenate([b.damping_ratio for b in measured])
    else:
        grid_m = np.asarray(amplitudes_m, dtype=float)
        amplitudes = [grid_m[(grid_m >= b.amplitude_m.min()) & (grid_m <= b.amplitude_m.max())]
                      for b in measured]  # fmt: skip
        empty = [b.label for b, a in zip(measured, amplitudes, strict=True) if a.size == 0]
        if empty:
            raise ValueError(f"curves {empty} reach none of the amplitude levels {grid_m} m")
        pairs = list(zip(measured, amplitudes, strict=True))
        frequency = np.concatenate([b.frequency_at(a) for b, a in pairs])
        damping = np.concatenate([b.damping_at(a) for b, a in pairs])
    curve = np.concatenate([np.full(a.size, i) for i, a in enumerate(amplitudes)])
    return curve, np.concatenate(amplitudes), {"frequency_hz": frequency, "damping_ratio": damping}
