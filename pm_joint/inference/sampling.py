"""Sampling the updating models by sampler name, to memory or to a trace folder as it goes.

:func:`sample` runs PyMC's samplers (Metropolis as in the paper, with its proposal
covariance learned while tuning, in the prior box's coordinates; DEMetropolisZ;
NUTS) or nutpie's NUTS and returns an arviz DataTree, optionally writing the
draws to a folder as they come (:mod:`~pm_joint.inference.traces`);
:func:`continue_sampling` carries a stopped run on from that folder.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pymc as pm
import xarray as xr
from pymc.blocking import DictToArrayBijection

from pm_joint.inference.models import HIERARCHICAL
from pm_joint.inference.steps import CovarianceMetropolis, KeptLogp
from pm_joint.inference.storage import attach_density, load_posterior
from pm_joint.inference.traces import DrawWriter, start_trace
from pm_joint.sampler_defaults import (
    GRADIENT_SAMPLERS,
    POPULATION_MODELS,
    SAMPLER_DEFAULTS,
    SAMPLERS,
)

__all__ = [
    "GRADIENT_SAMPLERS",
    "HIERARCHICAL_TARGET_ACCEPT",
    "POPULATION_MODELS",
    "SAMPLERS",
    "SAMPLER_DEFAULTS",
    "continue_sampling",
    "sample",
]

#: Target acceptance of a gradient sampler on the hierarchical model: closer to 1 than PyMC's
#: 0.8 because population spreads near 0 make a funnel where large steps diverge; the coverage
#: bench (bench/results/population_coverage.json) and its CI test are calibrated at this value.
HIERARCHICAL_TARGET_ACCEPT = 0.95


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
    trace_chunk: int = 500,
    step_options: Mapping | None = None,
    initvals: Sequence[Mapping] | Mapping | None = None,
) -> xr.DataTree:
    """Sample the model; returns an arviz DataTree (posterior, sample_stats, ...).

    Parameters
    ----------
    sampler
        ``"metropolis"``: PyMC's Metropolis, the paper's sampler, with its proposal
        covariance learned while tuning (:class:`~pm_joint.inference.steps.CovarianceMetropolis`:
        a coordinate-wise pilot, then joint proposals, in the prior box's linear
        coordinates, one model evaluation per proposal; ``step_options=
        {"adapt_covariance": False}`` keeps the paper's coordinate-wise proposals
        throughout, ``{"coordinates": "value"}`` walks in PyMC's logit coordinates).
        ``"demetropolisz"``: PyMC's differential-evolution Metropolis. ``"nuts"``:
        PyMC's NUTS, ``"nutpie"``: nutpie's NUTS (numba backend); both need a
        differentiable forward model.
    trace
        A folder: draws are written there as they are taken
        (:class:`~pm_joint.inference.traces.DrawWriter`, zarr 2 or 3), so an
        interrupted run leaves the draws so far; :func:`load_posterior` reads them.
        Not with ``nutpie``, which keeps its draws in memory here.
    trace_chunk
        Steps per chain written at a time to ``trace`` (at most that many are
        lost when a run is killed).
    step_options
        Keywords of the step method (e.g. ``target_accept`` for NUTS and nutpie,
        :data:`HIERARCHICAL_TARGET_ACCEPT` unless given on a hierarchical model;
        ``tune_interval`` for Metropolis).
    initvals
        Starting points (one mapping, or one per chain), as ``pm.sample`` takes
        them (the PyMC samplers only).

    Notes
    -----
    The step's logp function is compiled (numba) and run once before the chains
    start, so forked chain processes share that work instead of repeating it.
    The DataTree's ``sampler`` attribute names the sampler and ``free_variables``
    lists the model's free variables (what a convergence verdict judges); a
    model of :func:`~pm_joint.inference.models.build_model` also leaves its
    likelihood density there (:func:`~pm_joint.inference.storage.stored_density`).
    """
    if sampler not in SAMPLERS:
        raise ValueError(f"sampler must be one of {SAMPLERS}, got {sampler!r}")
    options = dict(step_options or {})
    if sampler in GRADIENT_SAMPLERS and getattr(pm_model, "population_model", None) == HIERARCHICAL:
        options.setdefault("target_accept", HIERARCHICAL_TARGET_ACCEPT)
    if sampler == "nutpie":
        if trace is not None:
            raise ValueError(
                "sampler 'nutpie' keeps its draws in memory: use 'nuts' (or a Metropolis "
                "sampler) for draws written to a trace folder as they are taken"
            )
        idata = _sample_nutpie(pm_model, draws, tune, chains, cores, random_seed, progressbar,
                               options)  # fmt: skip
    else:
        idata = _sample_pymc(
            pm_model, sampler, draws, tune, chains, cores, random_seed, progressbar, trace,
            trace_chunk, options, initvals,
        )  # fmt: skip
    idata.attrs["sampler"] = sampler
    idata.attrs["free_variables"] = json.dumps([rv.name for rv in pm_model.free_RVs])
    for key in ("population_model", "hierarchical_options"):
        if hasattr(pm_model, key):
            idata.attrs[key] = getattr(pm_model, key)
    density = getattr(pm_model, "backbone_density", None)
    if density is not None:  # the likelihood travels with its draws, to reports and files
        attach_density(idata, density)
    return idata


def _sample_pymc(
    pm_model, sampler, draws, tune, chains, cores, random_seed, progressbar, trace, trace_chunk,
    options, initvals,
) -> xr.DataTree:  # fmt: skip
    """One ``pm.sample`` call with the named PyMC step, optionally writing a trace folder."""
    with pm_model:
        if sampler == "metropolis":
            step = CovarianceMetropolis(**options)
            step.set_tune_steps(tune)
        elif sampler == "demetropolisz":
            step = pm.DEMetropolisZ(**options)
        else:
            step = pm.NUTS(**options)
        _compile_now(step, pm_model.initial_point())
        kwargs = {}
        if trace is not None:
            start_trace(trace, pm_model, tune=tune, draws=draws, chains=chains, sampler=sampler)
            kwargs["trace"] = DrawWriter(trace, chunk=min(trace_chunk, tune + draws))
        return pm.sample(
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


def _sample_nutpie(
    pm_model, draws, tune, chains, cores, random_seed, progressbar, options
) -> xr.DataTree:
    """nutpie's NUTS on the PyMC model (compiled with numba), in PyMC's DataTree layout."""
    import nutpie

    compiled = nutpie.compile_pymc_model(pm_model, backend="numba")
    start = time.perf_counter()
    idata = nutpie.sample(
        compiled, draws=draws, tune=tune, chains=chains,
        cores=cores or min(chains, os.cpu_count() or 1), seed=random_seed,
        progress_bar=progressbar, save_warmup=False, **options,
    )  # fmt: skip
    seconds = time.perf_counter() - start
    groups = {f"/{name}": node.to_dataset() for name, node in idata.children.items()}
    for name in ("posterior", "sample_stats"):
        groups[f"/{name}"].attrs.update(sampling_time=seconds, tuning_steps=tune)
    return xr.DataTree.from_dict(groups)


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
) -> xr.DataTree:
    """Continue a stopped run until every chain has ``draws`` posterior draws.

    Reads the draws ``trace`` holds (:func:`load_posterior`; the run must have
    finished tuning), restarts each chain at its last draw, tunes the step
    there again for ``tune`` steps and samples the draws still missing into
    ``continued_trace`` (default: ``<trace>-continued``), written as they are
    taken, so a second stop loses no more than the first. Returns both parts
    joined along ``draw`` (attribute ``continued_at``: the draws of the first).

    Notes
    -----
    The step's tuned state (scales, proposal covariance) is not stored in the
    trace: the step is tuned again, starting from posterior draws, so every
    kept draw is still a draw of the posterior. The first part's draws are not
    changed.
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


def _joined(first: xr.DataTree, second: xr.DataTree) -> xr.Dataset:
    """Two runs' draws one after the other (variables both have), draws renumbered."""
    first, second = first.to_dataset(), second.to_dataset()
    common = [v for v in first.data_vars if v in second.data_vars]
    joined = xr.concat([first[common], second[common]], dim="draw")
    return joined.assign_coords(draw=np.arange(joined.sizes["draw"]))


def _compile_now(step, point: Mapping[str, np.ndarray]) -> None:
    """Run the step's compiled function once.

    pytensor's numba functions compile on their first call; called here, before
    the chain processes fork, the machine code is made once and inherited.
    """
    for method in getattr(step, "methods", [step]):  # a CompoundStep: each of its steps
        q = DictToArrayBijection.map({v.name: point[v.name] for v in method.vars}).data
        if isinstance(method, pm.NUTS):
            method._logp_dlogp_func._pytensor_function(q)
        elif isinstance(method.delta_logp, KeptLogp):
            method.delta_logp.logp(q)  # the model's logp, in the value variables
        else:
            method.delta_logp(q, q)
