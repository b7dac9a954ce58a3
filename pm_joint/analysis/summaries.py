"""Numbers of a posterior, the arviz way: DataTrees in, tables and dicts out.

:func:`summarize` (arviz's summary: mean, sd, 94 % interval, ESS, r̂),
:func:`correlation_matrix` (the paper's Fig. 20) and :func:`sampler_info`
(sampler, draws, chains, wall time, acceptance). No figures here: they are in
:mod:`pm_joint.plotting`.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

import arviz as az
import numpy as np
import pandas as pd
import xarray as xr

__all__ = [
    "CI_PROB",
    "SAMPLE_DIMS",
    "correlation_matrix",
    "default_var_names",
    "group_dataset",
    "resolve_var_names",
    "sampler_info",
    "summarize",
    "unmoved_components",
]

SAMPLE_DIMS = ("chain", "draw")
#: Probability of the central intervals reported (the paper's 94 %).
CI_PROB = 0.94


def group_dataset(idata: xr.DataTree, name: str) -> xr.Dataset:
    """The group ``name`` of a DataTree as a Dataset; ValueError naming the groups it has."""
    if name not in idata.children:
        raise ValueError(f"the DataTree has no {name!r} group (groups: {list(idata.children)})")
    return idata[name].to_dataset()


def default_var_names(idata: xr.DataTree) -> list[str]:
    """Posterior variables that are one scalar per draw (the free parameters).

    Vector deterministics such as ``backbone_predicted`` are left out.
    """
    posterior = group_dataset(idata, "posterior")
    return [str(n) for n, da in posterior.data_vars.items() if set(da.dims) == set(SAMPLE_DIMS)]


def resolve_var_names(idata: xr.DataTree, var_names: Sequence[str] | None) -> list[str]:
    """``var_names`` checked against the posterior; None gives :func:`default_var_names`."""
    if var_names is None:
        names = default_var_names(idata)
        if not names:
            raise ValueError("the posterior has no scalar variables; pass var_names")
        return names
    names = [var_names] if isinstance(var_names, str) else list(var_names)
    posterior = group_dataset(idata, "posterior")
    unknown = [n for n in names if n not in posterior.data_vars]
    if unknown:
        raise ValueError(f"unknown posterior variable(s) {unknown}; have {list(posterior)}")
    if not names:
        raise ValueError("var_names is empty")
    return names


def summarize(idata: xr.DataTree, var_names: Sequence[str] | None = None) -> pd.DataFrame:
    """arviz summary: mean, sd, 94 % interval, ess_bulk, ess_tail, r_hat, MCSE (unrounded)."""
    names = resolve_var_names(idata, var_names)
    return az.summary(idata, var_names=names, ci_prob=CI_PROB, round_to="none")


def _draws_table(idata: xr.DataTree, var_names: Sequence[str]) -> pd.DataFrame:
    """One row per draw (all chains pooled), one column per scalar component.

    Components of vector variables are labelled like arviz does, ``name[i, j]``.
    """
    posterior = group_dataset(idata, "posterior")
    columns = {}
    for name in var_names:
        da = posterior[name].stack(__sample__=SAMPLE_DIMS)
        others = [d for d in da.dims if d != "__sample__"]
        if not others:
            columns[name] = da.values
            continue
        flat = da.stack(__component__=others).transpose("__sample__", "__component__")
        for j, label in enumerate(flat["__component__"].values):
            columns[f"{name}[{', '.join(map(str, label))}]"] = flat.values[:, j]
    return pd.DataFrame(columns)


def unmoved_components(idata: xr.DataTree, var_names: Sequence[str] | None = None) -> list[str]:
    """Components (labelled like :func:`correlation_matrix`'s columns) whose draws hold fewer
    than two distinct finite values: the chains never moved them, so they have no spread to
    bin, smooth or correlate."""
    table = _draws_table(idata, resolve_var_names(idata, var_names))
    return [c for c in table.columns if table[c][np.isfinite(table[c])].nunique() < 2]


def correlation_matrix(idata: xr.DataTree, var_names: Sequence[str] | None = None) -> pd.DataFrame:
    """Pearson correlation of the posterior draws, chains pooled (the paper's Fig. 20)."""
    return _draws_table(idata, resolve_var_names(idata, var_names)).corr()


# (stat present in sample_stats, sampler) — PyMC records no sampler name.
_SAMPLER_SIGNATURES = (
    ("lambda", "demetropolisz"),
    ("diverging", "nuts"),
    ("accepted", "metropolis"),
)


def sampler_info(idata: xr.DataTree, sampler: str | None = None) -> dict[str, Any]:
    """Sampler name, why it ran, draws, chains, tuning steps, wall time (s), mean acceptance.

    The name is ``sampler`` if given, else a ``sampler`` attribute of the
    DataTree (or of its ``pm_joint_metadata``), else guessed from the
    sampler statistics PyMC records; None where nothing tells.
    """
    posterior = group_dataset(idata, "posterior")
    stats = idata["sample_stats"].to_dataset() if "sample_stats" in idata.children else xr.Dataset()
    attrs = {**posterior.attrs, **stats.attrs}
    metadata = json.loads(idata.attrs.get("pm_joint_metadata", "{}"))
    sampler = sampler or idata.attrs.get("sampler") or metadata.get("sampler")
    reason = idata.attrs.get("sampler_reason") or metadata.get("sampler_reason")
    if sampler is None:
        sampler = next((s for stat, s in _SAMPLER_SIGNATURES if stat in stats), None)
    acceptance = None
    # "accepted" is the 0/1 outcome (Metropolis family), "acceptance_rate" NUTS's
    # mean acceptance probability; Metropolis's "accept" is a likelihood ratio, not a rate.
    for stat in ("accepted", "acceptance_rate"):
        if stat in stats:
            acceptance = float(np.nanmean(stats[stat].values.astype(float)))
            break
    wall = attrs.get("sampling_time")
    tuning = attrs.get("tuning_steps")
    return {
        "sampler": sampler,
        "reason": reason,
        "draws": int(posterior.sizes["draw"]),
        "chains": int(posterior.sizes["chain"]),
        "tuning_steps": None if tuning is None else int(tuning),
        "wall_time_s": None if wall is None else float(wall),
        "acceptance_rate": acceptance,
    }
