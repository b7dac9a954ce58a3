"""Sampling the updating models with PyMC, to memory or to a trace folder as it goes.

:func:`sample` runs PyMC's samplers (Metropolis as in the paper, DEMetropolisZ,
NUTS where gradients exist) and returns an arviz DataTree, optionally writing
the draws to a zarr folder as they come; :func:`continue_sampling` carries a
stopped run on from that folder.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pymc as pm
import xarray as xr
from pymc.blocking import DictToArrayBijection
from pymc.stats.convergence import log_warnings, run_convergence_checks

from pm_joint.inference.storage import attach_density, load_posterior

__all__ = ["SAMPLERS", "continue_sampling", "sample"]

SAMPLERS = ("metropolis", "demetropolisz", "nuts")


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
) -> xr.DataTree:
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
    The DataTree's ``sampler`` attribute names the sampler; a model of
    :func:`~pm_joint.inference.models.build_model` also leaves its likelihood
    density there (:func:`~pm_joint.inference.storage.stored_density`).
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
    density = getattr(pm_model, "backbone_density", None)
    if density is not None:  # the likelihood travels with its draws, to reports and files
        attach_density(idata, density)
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


def _joined(first: xr.DataTree, second: xr.DataTree) -> xr.Dataset:
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
