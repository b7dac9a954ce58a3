"""Building and sampling the stochastic-updating models.

Two models, both ordinary ``pm.Model`` objects:

:func:`build_model`
    The paper's scheme: uniform priors on the named parameters, a forward
    model (surrogate, harmonic balance or PLL, chosen by one argument) and the
    backbone-amplitude likelihood of the measured population. The posterior
    describes the population of assemblies.
:func:`hierarchical_model`
    The principled alternative for population variability: one parameter
    vector per measured curve, drawn from a population distribution, and a
    per-level measurement error; sampled with NUTS through the differentiable
    harmonic-balance graph.

:func:`sample` runs PyMC's samplers (Metropolis as in the paper, DEMetropolisZ,
NUTS where gradients exist) and returns an arviz DataTree;
:func:`save_posterior` / :func:`load_posterior` keep it on disk.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pymc as pm
import pytensor.tensor as pt
import xarray as xr
from numpy.typing import ArrayLike

from identification.backbone import BackboneSet
from identification.model import JointModel
from pm_joint.likelihood import BackboneAmplitude, BackboneDensity, amplitude_levels
from pm_joint.ops import forward_model, harmonic_backbone_graph
from surrogates.runtime import SurrogateRuntime

__all__ = [
    "SAMPLERS",
    "build_model",
    "default_bounds",
    "hierarchical_model",
    "load_posterior",
    "sample",
    "save_posterior",
    "uniform_priors",
]

SAMPLERS = ("metropolis", "demetropolisz", "nuts")


def default_bounds(
    model: JointModel, names: Sequence[str], spread: float = 0.5
) -> dict[str, tuple[float, float]]:
    """Bounds ``value·(1 ± spread)`` around the model's parameter values."""
    values = model.parameters
    bounds = {}
    for name in names:
        if name not in values:
            raise ValueError(f"unknown parameter {name!r}; the model has {list(values)}")
        value = values[name]
        if value == 0:
            raise ValueError(f"parameter {name!r} is 0: give its bounds explicitly")
        low, high = sorted((value * (1 - spread), value * (1 + spread)))
        bounds[name] = (low, high)
    return bounds


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
    levels: ArrayLike | None = None,
    channels: Sequence[str] = ("frequency_hz",),
    family: str = "copula",
    n_grid: int = 41,
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
        Uniform prior bounds; default: the surrogate's training box, else ±50 %.
    surrogate
        The surrogate runtime or its folder (for ``forward="surrogate"``).
    levels
        Amplitude levels (m) of the likelihood; default a grid over the
        measured curves' shared range.
    channels, family
        Passed to :class:`~pm_joint.likelihood.BackboneDensity`.
    n_grid
        Number of amplitude (harmonic) or excitation (PLL) points of the
        forward model's backbone.
    """
    levels = amplitude_levels(measured) if levels is None else np.asarray(levels, float)
    density = BackboneDensity.fit(measured, levels, channels=channels, family=family)
    if forward == "surrogate":
        runtime = surrogate if isinstance(surrogate, SurrogateRuntime) else None
        runtime = runtime or SurrogateRuntime.load(surrogate)
        names = list(names or runtime.parameter_names)
        if bounds is None:
            box = dict(zip(runtime.parameter_names, runtime.bounds, strict=True))
            bounds = {n: tuple(box[n]) for n in names}
        op = forward_model("surrogate", model, names, surrogate=runtime)
    else:
        if model is None:
            raise ValueError(f"forward model {forward!r} needs a JointModel")
        names = list(names or model.parameter_names)
        bounds = bounds or default_bounds(model, names)
        low, high = measured.common_range()
        grid = np.linspace(0.5 * low, 1.2 * high, n_grid)
        pll_levels = None
        if forward == "pll":
            pll_levels = _pll_levels_for(model, grid)
        op = forward_model(
            forward, model, names, amplitudes_m=grid if forward == "harmonic" else None,
            levels=pll_levels,
        )  # fmt: skip
    missing = [n for n in names if n not in bounds]
    if missing:
        raise ValueError(f"no prior bounds for {missing}")
    with pm.Model() as pm_model:
        theta = uniform_priors({n: bounds[n] for n in names})
        BackboneAmplitude("backbone", op(theta), observed=measured, density=density)
    pm_model.forward_op = op  # kept for reports and posterior-predictive backbones
    return pm_model


def _pll_levels_for(model: JointModel, amplitudes_m: np.ndarray) -> np.ndarray:
    """Base-acceleration levels whose harmonic-balance amplitudes span the grid."""
    from identification.harmonic import backbone

    hb = backbone(model, amplitudes_m)
    levels = np.abs(hb.base_acceleration[hb.converged])
    if levels.size < 3:
        raise ValueError("could not find PLL excitation levels: the model's backbone failed")
    return np.geomspace(levels.min(), levels.max(), min(len(amplitudes_m), 41))


def sample(
    pm_model: pm.Model,
    *,
    sampler: str = "metropolis",
    draws: int = 30_000,
    tune: int = 2_000,
    chains: int = 2,
    cores: int | None = None,
    random_seed: int | None = 0,
    progressbar: bool = True,
    trace: str | os.PathLike | None = None,
):
    """Sample the model; returns an arviz DataTree (posterior, sample_stats, ...).

    Parameters
    ----------
    sampler
        ``"metropolis"`` (PyMC's one-coordinate-at-a-time Metropolis, the
        paper's), ``"demetropolisz"`` (joint differential-evolution proposals)
        or ``"nuts"`` (needs a differentiable forward model).
    trace
        A zarr folder: draws are written there as they are taken, so an
        interrupted run leaves the draws so far readable.
    """
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {SAMPLERS}, got {sampler!r}")
    kwargs = {}
    if trace is not None:
        kwargs["trace"] = pm.backends.zarr.ZarrTrace(store=str(trace), draws_per_chunk=500)
    with pm_model:
        step = {
            "metropolis": lambda: pm.Metropolis(),
            "demetropolisz": lambda: pm.DEMetropolisZ(),
            "nuts": lambda: pm.NUTS(),
        }[sampler]()
        return pm.sample(
            draws=draws,
            tune=tune,
            chains=chains,
            cores=cores or min(chains, os.cpu_count() or 1),
            step=step,
            random_seed=random_seed,
            progressbar=progressbar,
            **kwargs,
        )


def save_posterior(idata, path: str | os.PathLike, metadata: Mapping | None = None) -> Path:
    """Write a DataTree to netCDF atomically, with its provenance in the attributes."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    idata.attrs["pm_joint_metadata"] = json.dumps(dict(metadata or {}), default=str)
    idata.to_netcdf(tmp)
    os.replace(tmp, path)
    return path


def load_posterior(path: str | os.PathLike):
    """Read a DataTree written by :func:`save_posterior` (or any arviz netCDF)."""
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such posterior file")
    return xr.open_datatree(path).load()


def hierarchical_model(
    model: JointModel,
    measured: BackboneSet,
    names: Sequence[str],
    *,
    levels: ArrayLike | None = None,
    population_scale: float = 0.2,
) -> pm.Model:
    """Per-curve parameters from a population distribution, for NUTS.

    Each named parameter of curve i is ``θ0 · exp(μ + σ z_i)`` with θ0 the
    template's value (so signs are kept and scales are O(1)), population mean
    ``μ ~ Normal(0, 0.5)`` and spread ``σ ~ HalfNormal(population_scale)``
    per parameter, ``z_i ~ Normal(0, 1)`` (non-centred). Measured frequencies
    at the amplitude levels are Normal around the curve's harmonic-balance
    backbone with a per-level measurement error.

    The population mean of parameter p in physical units is reported as the
    deterministic ``{p}_population`` = θ0·exp(μ_p).
    """
    names = list(names)
    template = model.parameters
    unknown = [n for n in names if n not in template]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the model has {list(template)}")
    zero = [n for n in names if template[n] == 0]
    if zero:
        raise ValueError(f"parameters {zero} are 0 in the template: give them a value")
    levels = amplitude_levels(measured) if levels is None else np.asarray(levels, float)
    observed = measured.frequency_matrix(levels)
    theta0 = np.array([template[n] for n in names])
    coords = {"curve": measured.labels, "parameter": names, "level": levels * 1e3}
    with pm.Model(coords=coords) as pm_model:
        mu = pm.Normal("log_mean", 0.0, 0.5, dims="parameter")
        sigma = pm.HalfNormal("log_spread", population_scale, dims="parameter")
        z = pm.Normal("z", 0.0, 1.0, dims=("curve", "parameter"))
        theta = pm.Deterministic(
            "theta", theta0 * pt.exp(mu + sigma * z), dims=("curve", "parameter")
        )
        for j, name in enumerate(names):
            pm.Deterministic(f"{name}_population", theta0[j] * pt.exp(mu[j]))
        predicted = harmonic_backbone_graph(model, theta, names, levels)[..., 1]
        noise = pm.HalfNormal("frequency_noise_hz", 0.5, dims="level")
        pm.Normal(
            "frequency_hz", mu=predicted, sigma=noise, observed=observed, dims=("curve", "level")
        )
    return pm_model
