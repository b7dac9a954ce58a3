"""Building and sampling the stochastic-updating models.

Two models, both ordinary ``pm.Model`` objects:

:func:`build_model`
    The paper's scheme: uniform priors on the named parameters, a forward
    model (surrogate, harmonic balance or PLL, chosen by one argument) and the
    backbone-amplitude likelihood of the measured population. The posterior
    describes the population of assemblies.
:func:`hierarchical_model`
    The principled alternative for population variability: one parameter
    vector per measured curve, drawn from a population distribution, each
    measured point Normal around its curve's harmonic-balance backbone;
    sampled with NUTS through the differentiable harmonic-balance graph.
    :func:`population_coverage` checks its calibration on synthetic campaigns
    (:func:`synthetic_campaign`).

:func:`sample` runs PyMC's samplers (Metropolis as in the paper, DEMetropolisZ,
NUTS where gradients exist) and returns an arviz DataTree, optionally writing
the draws to a zarr folder as they come; :func:`save_posterior` /
:func:`load_posterior` keep posteriors on disk (and read interrupted traces).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pymc as pm
import pytensor.tensor as pt
import xarray as xr
from numpy.typing import ArrayLike
from pymc.blocking import DictToArrayBijection
from pymc.stats.convergence import log_warnings, run_convergence_checks

from identification.artifacts import check_sha256, versions
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from pm_joint.forward import BACKBONE_COLUMNS, FORWARD_KINDS, forward_model, harmonic_backbone_graph
from pm_joint.likelihood import (
    BackboneAmplitude,
    BackboneDensity,
    amplitude_levels,
    interpolate_backbone,
)
from surrogates.runtime import SurrogateRuntime

__all__ = [
    "SAMPLERS",
    "Coverage",
    "build_model",
    "continue_sampling",
    "default_bounds",
    "hierarchical_model",
    "load_posterior",
    "population_coverage",
    "posterior_sha256",
    "sample",
    "save_posterior",
    "synthetic_campaign",
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

    Raises
    ------
    ValueError
        For curves without a shared amplitude range, levels outside it, names
        or bounds that do not match the surrogate (or lie outside its training
        box), and a forward model whose prediction at the centre of the prior
        box does not reach every level (NaN there). A prediction that fails
        elsewhere in the box is not an error: it gets ``logp = -inf``, counted
        (:class:`~pm_joint.likelihood.NanCounter`), and the chain goes on.
    """
    if forward not in FORWARD_KINDS:
        raise ValueError(f"forward must be one of {FORWARD_KINDS}, got {forward!r}")
    levels = amplitude_levels(measured) if levels is None else np.asarray(levels, float)
    density = BackboneDensity.fit(measured, levels, channels=channels, family=family)
    if forward == "surrogate":
        runtime = surrogate if isinstance(surrogate, SurrogateRuntime) else None
        if runtime is None:
            if surrogate is None:
                raise ValueError("forward model 'surrogate' needs surrogate= (a runtime or folder)")
            runtime = SurrogateRuntime.load(surrogate)
        names = list(names or runtime.parameter_names)
        bounds = _surrogate_bounds(runtime, names, bounds)
        op = forward_model("surrogate", model, names, surrogate=runtime)
    else:
        if model is None:
            raise ValueError(f"forward model {forward!r} needs a JointModel")
        names = list(names or model.parameter_names)
        bounds = bounds or default_bounds(model, names)
        low, high = measured.common_range()
        # The levels themselves are grid points: the likelihood then sees the model's
        # own values there, not a linear interpolation between grid points.
        grid = np.union1d(np.linspace(0.5 * low, 1.2 * high, n_grid), levels)
        if forward == "harmonic":
            op = forward_model("harmonic", model, names, amplitudes_m=grid)
        else:
            op = forward_model("pll", model, names, levels=_pll_levels_for(model, grid, n_grid))
    missing = [n for n in names if n not in bounds]
    if missing:
        raise ValueError(f"no prior bounds for {missing}")
    bounds = {n: bounds[n] for n in names}
    with pm.Model() as pm_model:
        theta = uniform_priors(bounds)  # validates the bounds first
        _check_reaches_levels(op, forward, bounds, density)
        BackboneAmplitude("backbone", op(theta), observed=measured, density=density)
    pm_model.forward_op = op  # kept for reports and posterior-predictive backbones
    return pm_model


def _surrogate_bounds(
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


def _pll_levels_for(model: JointModel, amplitudes_m: np.ndarray, n: int) -> np.ndarray:
    """``n`` base-acceleration levels whose harmonic-balance amplitudes span the grid."""
    from identification.analytical.harmonic import backbone

    hb = backbone(model, amplitudes_m)
    levels = np.abs(hb.base_acceleration[hb.converged])
    if levels.size < 3:
        raise ValueError("could not find PLL excitation levels: the model's backbone failed")
    return np.geomspace(levels.min(), levels.max(), n)


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
    trace_chunk: int = 100,
    step_options: Mapping | None = None,
    initvals: Sequence[Mapping] | Mapping | None = None,
):
    """Sample the model; returns an arviz DataTree (posterior, sample_stats, ...).

    Parameters
    ----------
    sampler
        ``"metropolis"`` (PyMC's Metropolis, one scalar coordinate at a time
        as in the paper, all coordinates in one step so that one logp function
        is compiled), ``"demetropolisz"`` (joint differential-evolution
        proposals) or ``"nuts"`` (needs a differentiable forward model).
    trace
        A zarr folder: draws are written there as they are taken, so an
        interrupted run leaves the draws so far; :func:`load_posterior` reads them.
    trace_chunk
        Draws per chain written at a time to ``trace`` (at most that many are
        lost when a run is killed).
    step_options
        Keywords of the PyMC step method (e.g. ``target_accept`` for NUTS;
        ``blocked=False`` gives PyMC's default Metropolis, one step and one
        compiled function per variable).
    initvals
        Starting points (one mapping, or one per chain), as ``pm.sample`` takes them.

    Notes
    -----
    The step's logp function is compiled (numba) and run once before the chains
    start, so forked chain processes share that work instead of repeating it.
    The DataTree's ``sampler`` attribute names the sampler.
    """
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {SAMPLERS}, got {sampler!r}")
    options = dict(step_options or {})
    kwargs = {}
    own_pickles = contextlib.nullcontext()
    if trace is not None:
        kwargs = {
            "trace": pm.backends.ZarrTrace(
                store=str(trace), draws_per_chunk=min(trace_chunk, tune + draws)
            ),
            # PyMC would read the trace back through xarray's zarr-3 reader, which
            # fails with zarr 2 installed: load_posterior reads it below.
            "return_inferencedata": False,
            "compute_convergence_checks": False,
        }
        own_pickles = _decoding_own_pickles()
    with pm_model, own_pickles, warnings.catch_warnings():
        warnings.filterwarnings("ignore", "`return_inferencedata=False` is deprecated")
        step = {
            "metropolis": lambda: pm.Metropolis(**{"blocked": True, **options}),
            "demetropolisz": lambda: pm.DEMetropolisZ(**options),
            "nuts": lambda: pm.NUTS(**options),
        }[sampler]()
        _compile_now(step, pm_model.initial_point())
        idata = pm.sample(
            draws=draws,
            tune=tune,
            chains=chains,
            cores=cores or min(chains, os.cpu_count() or 1),
            step=step,
            random_seed=random_seed,
            progressbar=progressbar,
            initvals=initvals,
            **kwargs,
        )
    if trace is not None:
        idata = load_posterior(trace)
        log_warnings(run_convergence_checks(idata, pm_model))
    idata.attrs["sampler"] = sampler
    return idata


def continue_sampling(
    pm_model: pm.Model,
    trace: str | os.PathLike,
    *,
    draws: int,
    tune: int = 500,
    sampler: str = "metropolis",
    random_seed: int | None = 1,
    progressbar: bool = True,
    continued_trace: str | os.PathLike | None = None,
    step_options: Mapping | None = None,
):
    """Continue a stopped run until every chain has ``draws`` posterior draws.

    Reads the draws ``trace`` holds (:func:`load_posterior`; the run must have
    finished tuning), restarts each chain at its last draw, tunes the step
    there again for ``tune`` steps and samples the draws still missing into
    ``continued_trace`` (default: ``<trace>-continued``), written as they are
    taken, so a second stop loses no more than the first. Returns both parts
    joined along ``draw`` (attribute ``continued_at``: the draws of the first).

    Notes
    -----
    The step's tuned state is stored in the trace only as a pickle, which is
    not read back (a trace may come from someone else): the step is tuned
    again instead, starting from posterior draws, so every kept draw is still a
    draw of the posterior. The first part's draws are not changed.
    """
    trace = Path(trace)
    done = load_posterior(trace)
    have, chains = done.posterior.sizes["draw"], done.posterior.sizes["chain"]
    if have >= draws:
        return done
    names = [rv.name for rv in pm_model.free_RVs]
    missing = [n for n in names if n not in done.posterior]
    if missing:
        raise ValueError(f"{trace}: the trace has no draws of {missing}: not a run of this model")
    last = done.posterior.isel(draw=-1)
    initvals = [{n: last[n].isel(chain=c).values for n in names} for c in range(chains)]
    rest = sample(
        pm_model, sampler=sampler, draws=draws - have, tune=tune, chains=chains,
        random_seed=random_seed, progressbar=progressbar, step_options=step_options,
        trace=continued_trace or trace.with_name(f"{trace.name}-continued"), initvals=initvals,
    )  # fmt: skip
    joined = {"/posterior": _joined(done.posterior, rest.posterior)}
    joined["/sample_stats"] = _joined(done.sample_stats, rest.sample_stats)
    for name, node in rest.children.items():
        joined.setdefault(f"/{name}", node.to_dataset())
    tree = xr.DataTree.from_dict(joined)
    tree.attrs.update(rest.attrs, continued_at=have, interrupted=0)
    return tree


def _joined(first, second) -> xr.Dataset:
    """Two runs' draws one after the other (variables both have), draws renumbered."""
    first, second = first.to_dataset(), second.to_dataset()
    common = [v for v in first.data_vars if v in second.data_vars]
    joined = xr.concat([first[common], second[common]], dim="draw")
    return joined.assign_coords(draw=np.arange(joined.sizes["draw"]))


@contextlib.contextmanager
def _decoding_own_pickles():
    """Let numcodecs unpickle while ZarrTrace updates the sampler states it pickled itself.

    ZarrTrace keeps each chain's step state as a pickle and reads that chunk back
    when it writes the next one; numcodecs ≥ 0.15 refuses to unpickle unless the
    process opts in. The store was created (overwritten) by this run, so what is
    unpickled is this run's own data. The environment variable carries the opt-in
    to chain processes that are spawned rather than forked.
    """
    from numcodecs import pickles

    previous = pickles.ALLOW_UNSAFE_PICKLE_DECODE, os.environ.get(pickles._ENV_VAR)
    pickles.ALLOW_UNSAFE_PICKLE_DECODE = True
    os.environ[pickles._ENV_VAR] = "1"
    try:
        yield
    finally:
        pickles.ALLOW_UNSAFE_PICKLE_DECODE = previous[0]
        if previous[1] is None:
            os.environ.pop(pickles._ENV_VAR, None)
        else:
            os.environ[pickles._ENV_VAR] = previous[1]


def _compile_now(step, point: Mapping[str, np.ndarray]) -> None:
    """Run the step's compiled function once.

    pytensor's numba functions compile on their first call; called here, before
    the chain processes fork, the machine code is made once and inherited.
    """
    for method in getattr(step, "methods", [step]):  # a CompoundStep: each of its steps
        q = DictToArrayBijection.map({v.name: point[v.name] for v in method.vars}).data
        if isinstance(method, pm.NUTS):
            method._logp_dlogp_func._pytensor_function(q)
        else:
            method.delta_logp(q, q)


def posterior_sha256(idata) -> str:
    """SHA-256 over the posterior draws: variable names, dtypes, shapes and bytes."""
    digest = hashlib.sha256()
    posterior = idata["posterior"].to_dataset() if "posterior" in idata.children else idata
    for name in sorted(posterior.data_vars):
        values = np.ascontiguousarray(posterior[name].values)
        digest.update(f"{name}|{values.dtype.str}|{values.shape}|".encode())
        digest.update(values.tobytes())
    return digest.hexdigest()


def save_posterior(idata, path: str | os.PathLike, metadata: Mapping | None = None) -> Path:
    """Write a DataTree to netCDF atomically, with its provenance in the attributes.

    The attributes carry the hash of the posterior draws and the versions that
    produced them; :func:`load_posterior` checks the hash.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    idata.attrs["pm_joint_metadata"] = json.dumps(dict(metadata or {}), default=str)
    idata.attrs["pm_joint_versions"] = json.dumps(
        versions("pm-joint", "pymc", "pytensor", "arviz", "numpy", "scipy")
    )
    idata.attrs["pm_joint_posterior_sha256"] = posterior_sha256(idata)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        idata.to_netcdf(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def load_posterior(path: str | os.PathLike):
    """Read a posterior: a netCDF file of :func:`save_posterior`, or a zarr trace folder.

    A zarr folder written by :func:`sample` (``trace=``) is read whether the run
    finished or was interrupted; an interrupted run gives the posterior draws
    every chain had written (the same number per chain), without its tuning steps.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such posterior file or trace folder")
    if path.is_dir():
        return _read_zarr_trace(path)
    idata = xr.open_datatree(path).load()
    expected = idata.attrs.get("pm_joint_posterior_sha256")
    if expected is not None:
        check_sha256(expected, posterior_sha256(idata), str(path), "the posterior draws")
    return idata


def _read_zarr_trace(path: Path):
    import zarr

    try:
        root = zarr.open_group(str(path), mode="r")
        state = root["_sampling_state"]
    except (KeyError, ValueError, zarr.errors.GroupNotFoundError):
        raise ValueError(f"{path}: not a zarr trace written by pm_joint.updating.sample") from None
    tune = int(state["tuning_steps"][...])
    written = int(np.min(state["draw_idx"][:]))  # tuning steps + draws every chain has written
    # Until a run ends, the posterior arrays hold the tuning steps first.
    offset = 0 if "warmup_posterior" in root.group_keys() else tune
    total = tune + root["posterior"]["draw"].shape[0] - offset
    if written <= tune:
        raise ValueError(
            f"{path}: the run was stopped while tuning ({written} of {tune} tuning steps "
            "written): no posterior draws yet"
        )
    draws = slice(offset, offset + written - tune)
    groups = {
        f"/{name}": _zarr_dataset(root[name], draws)
        for name in ("posterior", "sample_stats", "observed_data", "constant_data")
        if name in root.group_keys()
    }
    stats = groups["/sample_stats"].drop_vars("in_warmup")  # the tuning steps are cut off
    prefix = "sampler_0__"  # one step method: PyMC's usual stat names carry no prefix
    if all(n.startswith(prefix) for n in stats.data_vars):
        stats = stats.rename({n: n.removeprefix(prefix) for n in stats.data_vars})
    groups["/sample_stats"] = stats
    tree = xr.DataTree.from_dict(groups)
    tree.attrs.update(
        tuning_steps=tune,
        sampling_time=float(state["sampling_time"][...]),
        interrupted=int(written < total),
    )
    return tree


def _zarr_dataset(group, draws: slice) -> xr.Dataset:
    """A zarr-2 group written in xarray's layout, its ``draw`` axis cut to ``draws``."""
    variables, coords = {}, {}
    for name, array in group.arrays():
        dims = tuple(array.attrs["_ARRAY_DIMENSIONS"])
        if array.dtype == object:  # pickled sampler warnings: nothing to read back safely
            continue
        if dims == (name,):
            coords[name] = array[draws] if name == "draw" else array[:]
        else:
            index = tuple(draws if d == "draw" else slice(None) for d in dims)
            variables[name] = (dims, array.get_orthogonal_selection(index))
    if "draw" in coords:
        coords["draw"] = np.arange(len(coords["draw"]))
    return xr.Dataset(variables, coords=coords)


def hierarchical_model(
    model: JointModel,
    measured: BackboneSet,
    names: Sequence[str],
    *,
    levels: ArrayLike | None = None,
    population_scale: float = 0.2,
    channels: Sequence[str] = ("frequency_hz",),
    centred: bool = True,
) -> pm.Model:
    """Per-curve parameters from a population distribution, for NUTS.

    Each named parameter of curve i is ``θ0 · exp(η_i)`` with θ0 the template's
    value (so signs are kept and scales are O(1)) and ``η_i ~ Normal(μ, σ)``:
    population log-location ``μ ~ Normal(0, 0.5)`` (``log_mean``) and spread
    ``σ ~ HalfNormal(population_scale)`` (``log_spread``) per parameter. Each
    measured value is Normal around the curve's harmonic-balance backbone at the
    same amplitude, with one measurement error per channel (``{channel}_noise``,
    half-normal with the spread of the measured values as its scale).

    Parameters
    ----------
    model
        Template model: the structure, and θ0 for the named parameters.
    measured
        Measured backbones, one per assembly.
    names
        Parameters that vary from assembly to assembly.
    levels
        Amplitude levels (m) to interpolate every curve at; default (None)
        every measured point as it is, which leaves out the interpolation error.
    population_scale
        Scale of the half-normal prior of the spreads (relative, log scale).
    channels
        ``("frequency_hz",)`` or with ``"damping_ratio"``.
    centred
        Centred parameters ``η_i`` (default) suit curves that pin their own
        parameters, as backbones with many points do: the non-centred form
        ``η_i = μ + σ z_i`` then couples ``z_i`` and ``σ`` into a funnel. Use
        ``False`` for parameters the individual curves hardly inform.

    Notes
    -----
    ``θ0·exp(μ_p)``, the population's geometric mean (its median), is the
    deterministic ``{p}_population``; ``theta`` holds the per-curve values.
    """
    names = list(names)
    template = model.parameters
    unknown = [n for n in names if n not in template]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the model has {list(template)}")
    zero = [n for n in names if template[n] == 0]
    if zero:
        raise ValueError(f"parameters {zero} are 0 in the template: give them a value")
    if not channels or any(c not in ("frequency_hz", "damping_ratio") for c in channels):
        raise ValueError(f"channels must be 'frequency_hz' and/or 'damping_ratio', got {channels}")
    curve, amplitude, values = _curve_points(measured, levels)
    # One amplitude grid for every curve; each point then picks its curve and amplitude.
    grid, at = np.unique(amplitude, return_inverse=True)
    theta0 = np.array([template[n] for n in names])
    coords = {"curve": measured.labels, "parameter": names, "point": np.arange(amplitude.size)}
    with pm.Model(coords=coords) as pm_model:
        mu = pm.Normal("log_mean", 0.0, 0.5, dims="parameter")
        sigma = pm.HalfNormal("log_spread", population_scale, dims="parameter")
        if centred:
            eta = pm.Normal("eta", mu, sigma, dims=("curve", "parameter"))
        else:
            z = pm.Normal("z", 0.0, 1.0, dims=("curve", "parameter"))
            eta = mu + sigma * z
        theta = pm.Deterministic("theta", theta0 * pt.exp(eta), dims=("curve", "parameter"))
        for j, name in enumerate(names):
            pm.Deterministic(f"{name}_population", theta0[j] * pt.exp(mu[j]))
        backbone = harmonic_backbone_graph(model, theta, names, grid)
        pm.Data("amplitude_m", amplitude, dims="point")
        for channel in channels:
            # Data, not constants: campaigns on the same points then share one compiled graph.
            observed = pm.Data(f"{channel}_measured", values[channel], dims="point")
            noise = pm.HalfNormal(f"{channel}_noise", observed.std())
            predicted = backbone[curve, at, BACKBONE_COLUMNS.index(channel)]
            pm.Normal(channel, predicted, noise, observed=observed, dims="point")
    return pm_model


def _curve_points(
    measured: BackboneSet, levels: ArrayLike | None
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Curve index, amplitude (m) and channel values of every point, flat.

    With ``levels`` every curve is interpolated there (inside the range all
    curves share); without, each curve's own points are taken.
    """
    if levels is None:
        amplitudes = [b.amplitude_m for b in measured]
        frequency = np.concatenate([b.frequency_hz for b in measured])
        damping = np.concatenate([b.damping_ratio for b in measured])
    else:
        levels = np.asarray(levels, dtype=float)
        low, high = measured.common_range()
        if np.any((levels < low) | (levels > high)):
            raise ValueError(
                f"amplitude levels {levels} m must lie in the range all measured curves share "
                f"({low:.4g}–{high:.4g} m)"
            )
        amplitudes = [levels] * len(measured)
        frequency = measured.frequency_matrix(levels).ravel()
        damping = measured.damping_matrix(levels).ravel()
    curve = np.concatenate([np.full(a.size, i) for i, a in enumerate(amplitudes)])
    return curve, np.concatenate(amplitudes), {"frequency_hz": frequency, "damping_ratio": damping}


def synthetic_campaign(
    model: JointModel,
    names: Sequence[str],
    log_mean: ArrayLike,
    log_spread: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    n_curves: int = 25,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    rng: np.random.Generator | int | None = None,
) -> tuple[BackboneSet, np.ndarray]:
    """Backbones of assemblies drawn from a known population, with measurement noise.

    Curve i has ``θ_i = θ0·exp(log_mean + log_spread·N(0, 1))`` (θ0 the template's
    values of ``names``, the hierarchical model's population), its
    single-harmonic backbone at ``amplitudes_m``, and independent Normal noise:
    ``frequency_noise_hz`` on each frequency, ``damping_noise`` relative on each
    damping ratio. Returns the curves and the θ_i ``(n_curves, len(names))``.
    """
    from identification.analytical.harmonic import backbone

    rng = np.random.default_rng(rng)
    theta0 = np.array([model.parameters[n] for n in names])
    eta = np.asarray(log_mean, float) + np.asarray(log_spread, float) * rng.standard_normal(
        (n_curves, theta0.size)
    )
    theta = theta0 * np.exp(eta)
    hb = backbone(model, amplitudes_m, parameters=theta, names=names)
    if not hb.converged.all():
        raise ValueError(
            f"some draws of the population of {list(names)} have no backbone at every amplitude "
            "(no positive stiffness?): narrow log_spread or move log_mean"
        )
    frequency = hb.frequency_hz + frequency_noise_hz * rng.standard_normal(hb.frequency_hz.shape)
    damping = hb.damping_ratio * (1 + damping_noise * rng.standard_normal(hb.damping_ratio.shape))
    curves = [
        Backbone(hb.amplitude_m, f, d, label=f"assembly{i + 1}", source="synthetic_campaign")
        for i, (f, d) in enumerate(zip(frequency, damping, strict=True))
    ]
    return BackboneSet(curves), theta


@dataclass(frozen=True)
class Coverage:
    """Intervals of the population log-location ``μ`` over synthetic campaigns.

    ``lower``/``upper`` are ``(n_campaigns, n_params)`` central ``prob``
    intervals, ``truth`` the ``μ`` the campaigns were drawn with,
    ``divergences`` the NUTS divergences per campaign.
    """

    names: tuple[str, ...]
    truth: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    divergences: np.ndarray
    prob: float

    @property
    def covered(self) -> np.ndarray:
        return (self.lower <= self.truth) & (self.truth <= self.upper)

    @property
    def count(self) -> int:
        return int(self.covered.sum())

    def __str__(self) -> str:
        per_parameter = ", ".join(
            f"{n} {c}/{len(self.covered)}"
            for n, c in zip(self.names, self.covered.sum(0), strict=True)
        )
        return (
            f"population log-mean inside the {100 * self.prob:g} % interval in {self.count} of "
            f"{self.covered.size} cases ({per_parameter}); NUTS divergences per campaign: "
            f"{self.divergences.tolist()}"
        )


def population_coverage(
    model: JointModel,
    names: Sequence[str],
    log_mean: ArrayLike,
    log_spread: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    n_campaigns: int = 20,
    n_curves: int = 25,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    prob: float = 0.9,
    draws: int = 500,
    tune: int = 500,
    chains: int = 2,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    seed: int = 0,
    progress: bool = True,
) -> Coverage:
    """Simulation-based check of :func:`hierarchical_model`: how often its interval holds the truth.

    Draws ``n_campaigns`` campaigns of ``n_curves`` assemblies with
    :func:`synthetic_campaign` (its noise levels), samples each with NUTS and
    records the central ``prob`` interval of every ``log_mean``. A calibrated
    model holds the truth in about ``prob`` of the cases. Campaigns share their
    amplitudes, so the compiled model is reused (numba's cache) after the first.
    """
    from tqdm.auto import tqdm

    names = tuple(names)
    truth = np.asarray(log_mean, dtype=float)
    lower, upper, divergences = [], [], []
    tail = 0.5 * (1 - prob)
    for campaign in tqdm(range(n_campaigns), desc="campaigns", disable=not progress):
        measured, _ = synthetic_campaign(
            model, names, truth, log_spread, amplitudes_m,
            n_curves=n_curves, frequency_noise_hz=frequency_noise_hz,
            damping_noise=damping_noise, rng=[seed, campaign],
        )  # fmt: skip
        pm_model = hierarchical_model(model, measured, names, channels=channels)
        idata = sample(
            pm_model, sampler="nuts", draws=draws, tune=tune, chains=chains,
            random_seed=seed + campaign, progressbar=False,
        )  # fmt: skip
        draws_mu = idata.posterior["log_mean"].values.reshape(-1, len(names))
        low, high = np.quantile(draws_mu, [tail, 1 - tail], axis=0)
        lower.append(low)
        upper.append(high)
        divergences.append(int(idata.sample_stats["diverging"].sum()))
    return Coverage(names, truth, np.array(lower), np.array(upper), np.array(divergences), prob)
