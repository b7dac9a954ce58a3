"""Posteriors on disk: netCDF files with their provenance and likelihood, zarr traces.

:func:`save_posterior` writes a DataTree atomically with the hash of its draws,
the versions that made it and the likelihood density it was sampled with;
:func:`load_posterior` checks the hash and also reads the trace folders
:func:`~pm_joint.inference.sampling.sample` writes as it goes (interrupted runs
included); :func:`stored_density` gives the density back, so a report draws
exactly what was sampled.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import xarray as xr

from identification.artifacts import check_sha256, versions
from pm_joint.distributions import BackboneDensity
from pm_joint.inference.traces import read_trace

__all__ = [
    "attach_density",
    "load_posterior",
    "posterior_sha256",
    "save_posterior",
    "stored_density",
]

#: Attribute of a saved posterior holding its likelihood density (JSON).
DENSITY_ATTR = "pm_joint_density"


def posterior_sha256(idata: xr.DataTree | xr.Dataset) -> str:
    """SHA-256 over the posterior draws: variable names, dtypes, shapes and bytes."""
    digest = hashlib.sha256()
    posterior = idata["posterior"].to_dataset() if "posterior" in idata.children else idata
    for name in sorted(posterior.data_vars):
        values = np.ascontiguousarray(posterior[name].values)
        digest.update(f"{name}|{values.dtype.str}|{values.shape}|".encode())
        digest.update(values.tobytes())
    return digest.hexdigest()


def save_posterior(
    idata: xr.DataTree,
    path: str | os.PathLike,
    metadata: Mapping | None = None,
    *,
    density: BackboneDensity | None = None,
) -> Path:
    """Write a DataTree to netCDF atomically, with its provenance in the attributes.

    The attributes carry the hash of the posterior draws and the versions that
    produced them (:func:`load_posterior` checks the hash) and, given
    ``density``, the likelihood density the draws were sampled with (its levels,
    channels, family and fitted parameters; :func:`stored_density` reads it).
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    idata.attrs["pm_joint_metadata"] = json.dumps(dict(metadata or {}), default=str)
    if density is not None:
        attach_density(idata, density)
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


def load_posterior(path: str | os.PathLike) -> xr.DataTree:
    """Read a posterior: a netCDF file of :func:`save_posterior`, or a trace folder.

    A trace folder written by :func:`~pm_joint.inference.sampling.sample`
    (``trace=``; :func:`~pm_joint.inference.traces.read_trace`) is read whether
    the run finished or was interrupted; an interrupted run gives the posterior
    draws every chain had written (the same number per chain), without its
    tuning steps.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such posterior file or trace folder")
    if path.is_dir():
        return read_trace(path)
    idata = xr.open_datatree(path).load()
    expected = idata.attrs.get("pm_joint_posterior_sha256")
    if expected is not None:
        check_sha256(expected, posterior_sha256(idata), str(path), "the posterior draws")
    return idata


def attach_density(
    idata: xr.DataTree, density: BackboneDensity, attribute: str = DENSITY_ATTR
) -> None:
    """Keep ``density`` in the DataTree's attributes (JSON) for :func:`stored_density`
    (``attribute``: another name, for one density of several)."""
    idata.attrs[attribute] = json.dumps(density.to_dict())


def stored_density(idata: xr.DataTree, attribute: str = DENSITY_ATTR) -> BackboneDensity | None:
    """The likelihood density stored with the draws; None if there is none.

    :func:`~pm_joint.inference.sampling.sample` attaches the density of a
    :func:`~pm_joint.inference.models.build_model` model, and
    :func:`save_posterior` writes it with the draws.

    Posteriors written before the density was stored have none: their levels
    cannot be known for sure, so the caller decides what to fall back on.
    """
    text = idata.attrs.get(attribute)
    return None if text is None else BackboneDensity.from_dict(json.loads(text))
