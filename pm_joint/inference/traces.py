"""Draws on disk as they are taken: a small zarr writer for PyMC's samplers, and its reader.

:class:`DrawWriter` is a PyMC trace backend (an ``NDArray`` that also appends
each chain's draws to a zarr folder every ``chunk`` draws); :func:`read_trace`
reads such a folder back as an arviz DataTree, finished or interrupted.

The folder is written through xarray (``Dataset.to_zarr``), which speaks the
zarr 2 and zarr 3 APIs alike, so the store works beside nutpie (zarr 3) and
beside older environments (zarr 2); PyMC's own ``ZarrTrace`` needs the zarr 2
API. Layout::

    run.zarr/trace.json        what was asked (tune, draws, chains, sampler, dims, coords)
    run.zarr/chain_<c>/         one zarr group per chain: every variable and sampler
                                statistic along ``draw``, tuning steps first
    run.zarr/chain_<c>.json     how many steps of that chain are complete on disk
    run.zarr/observed_data/     the model's observed and constant data (zarr groups)
    run.zarr/constant_data/

A step counts as written only once its progress file says so (written after
the data), so a run killed mid-write reads back without half-written draws.
"""

from __future__ import annotations

import json
import os
import shutil
import time
import warnings
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import pymc as pm
import xarray as xr
import zarr
from pymc.backends.arviz import coords_and_dims_for_inferencedata, find_constants, find_observations
from pymc.backends.ndarray import NDArray

from identification.artifacts import atomic_write_text

__all__ = [
    "TRACE_FORMAT",
    "DrawWriter",
    "earlier_trace",
    "read_trace",
    "start_trace",
    "written_steps",
]

#: Name and version of the folder layout (``trace.json``'s ``format``).
TRACE_FORMAT = "pm-joint draws 1"
#: Prefix of the sampler statistics among a chain group's variables.
_STAT = "stat__"


def earlier_trace(trace: str | os.PathLike | None, resume: bool) -> bool:
    """Whether ``trace`` holds an earlier run's draws; a ValueError where it does and
    ``resume`` is not asked (an earlier run is continued or removed, never overwritten)."""
    earlier = trace is not None and Path(trace).exists()
    if earlier and not resume:
        raise ValueError(
            f"{trace} holds the draws of an earlier run: resume it, or remove it to start again"
        )
    return earlier


def start_trace(
    folder: str | os.PathLike,
    pm_model: pm.Model,
    *,
    tune: int,
    draws: int,
    chains: int,
    sampler: str,
) -> Path:
    """Create (overwrite) the trace folder: what the run is, its observed and constant data."""
    folder = Path(folder)
    if folder.exists():
        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    coords, dims = coords_and_dims_for_inferencedata(pm_model)
    meta = {
        "format": TRACE_FORMAT,
        "tune": int(tune),
        "draws": int(draws),
        "chains": int(chains),
        "sampler": sampler,
        "started": time.time(),
        "dims": dims,
        "coords": {k: np.asarray(v).tolist() for k, v in coords.items()},
    }
    atomic_write_text(folder / "trace.json", json.dumps(meta))
    for group, found in (
        ("observed_data", find_observations(pm_model)),
        ("constant_data", find_constants(pm_model)),
    ):
        data = {name: np.asarray(value) for name, value in found.items()}
        if data:
            _dataset(data, dims, coords).to_zarr(folder, group=group, mode="a", consolidated=False)
    return folder


class DrawWriter(NDArray):
    """PyMC's in-memory trace that also appends each chain's draws to a zarr folder.

    Give it to ``pm.sample(trace=...)`` after :func:`start_trace` made the
    folder. Draws and sampler statistics of every step (tuning included) are
    appended every ``chunk`` steps and when the chain closes, so a run that is
    killed loses at most ``chunk`` steps per chain. The sampler's draws stay in
    memory too, so ``pm.sample`` returns its DataTree as usual.

    PyMC records every chain in the main process (chains sampled in worker
    processes send their draws back), so one process writes the folder.
    """

    def __init__(self, folder: str | os.PathLike, *, chunk: int = 100, model=None, vars=None):
        super().__init__(model=model, vars=vars)
        self.folder = Path(folder)
        self.chunk = max(int(chunk), 1)
        meta = json.loads((self.folder / "trace.json").read_text(encoding="utf-8"))
        self._dims, self._coords = meta["dims"], meta["coords"]
        self._started = float(meta["started"])

    def setup(self, draws, chain, sampler_vars=None) -> None:
        # pm.sample hands each chain a shallow copy: give it arrays of its own.
        self.samples, self._stats = {}, None
        self._written = 0
        self._warmup = np.zeros(draws, dtype=bool)
        super().setup(draws, chain, sampler_vars)

    def record(self, point, sampler_stats=None, *, in_warmup: bool) -> None:
        self._warmup[self.draw_idx] = in_warmup
        super().record(point, sampler_stats, in_warmup=in_warmup)
        if self.draw_idx - self._written >= self.chunk:
            self._flush()

    def close(self) -> None:
        self._flush()
        super().close()

    def _slice(self, idx: slice) -> NDArray:
        # What pm.sample keeps after sampling is an in-memory NDArray: nothing more to write.
        plain = NDArray.__new__(NDArray)
        plain.__dict__.update(self.__dict__)
        return plain._slice(idx)

    def _flush(self) -> None:
        stop = self.draw_idx
        if stop == self._written:
            return
        part = slice(self._written, stop)
        data = {name: values[part] for name, values in self.samples.items()}
        for i, stats in enumerate(self._stats or []):
            for name, values in stats.items():
                if values.dtype != object:  # warnings objects: nothing to store
                    data[f"{_STAT}{i}__{name}"] = values[part]
        data[f"{_STAT}in_warmup"] = self._warmup[part]
        dataset = _dataset(data, self._dims, self._coords, leading="draw")
        group = f"chain_{self.chain}"
        first = self._written == 0
        with warnings.catch_warnings():
            # zarr 3 warns that the v3 spec has no fixed-length string dtypes.
            warnings.filterwarnings("ignore", category=UserWarning, module="zarr")
            dataset.to_zarr(
                self.folder, group=group, mode="w" if first else "a",
                append_dim=None if first else "draw", consolidated=False,
            )  # fmt: skip
        self._written = stop
        progress = {
            "written": stop,
            "tune": int(self._warmup[:stop].sum()),
            "elapsed_s": time.time() - self._started,
        }
        atomic_write_text(self.folder / f"{group}.json", json.dumps(progress))


def _dataset(
    data: Mapping[str, np.ndarray],
    dims: Mapping[str, list],
    coords: Mapping[str, list],
    leading: str | None = None,
) -> xr.Dataset:
    """Arrays named like the model's variables, with the model's dims (arviz's default names
    ``{name}_dim_{i}`` for the rest), behind an optional leading dimension."""
    variables, used = {}, {}
    for name, values in data.items():
        values = np.asarray(values)
        shape = values.shape[1:] if leading else values.shape
        base = name.split("__", 2)[-1] if name.startswith(_STAT) else name
        named = list(dims.get(base, [])) if not name.startswith(_STAT) else []
        if len(named) != len(shape):
            named = [f"{base}_dim_{i}" for i in range(len(shape))]
        variables[name] = ([leading, *named] if leading else named, values)
        used.update({d: n for d, n in zip(named, shape, strict=True)})
    kept = {d: coords[d] for d in used if d in coords and len(coords[d]) == used[d]}
    return xr.Dataset(variables, coords=kept)


def written_steps(folder: str | os.PathLike) -> list[int]:
    """Steps (tuning and draws) each chain has complete on disk; 0 for a chain not begun."""
    folder = Path(folder)
    meta = _meta(folder)
    counts = []
    for chain in range(meta["chains"]):
        progress = folder / f"chain_{chain}.json"
        counts.append(
            json.loads(progress.read_text(encoding="utf-8"))["written"] if progress.exists() else 0
        )
    return counts


def _meta(folder: Path) -> dict:
    try:
        meta = json.loads((folder / "trace.json").read_text(encoding="utf-8"))
    except (FileNotFoundError, json.JSONDecodeError):
        raise ValueError(f"{folder}: not a trace folder written by pm_joint.sample") from None
    if meta.get("format") != TRACE_FORMAT:
        raise ValueError(f"{folder}: trace format {meta.get('format')!r}, not {TRACE_FORMAT!r}")
    return meta


def _read_steps(folder: Path, chain: int, steps: slice) -> xr.Dataset:
    """One chain's ``steps``. A run killed in the middle of an append leaves variables of
    different lengths on disk, which xarray refuses to open as one dataset: then each variable
    is opened alone and cut to ``steps`` (all of them hold at least the steps the chain's
    progress file counts, which is written after the append)."""
    group = f"chain_{chain}"
    try:
        with xr.open_zarr(folder, group=group, consolidated=False) as store:
            return store.isel(draw=steps).load()
    except ValueError:
        names = list(zarr.open_group(folder / group, mode="r").array_keys())
    parts = []
    for name in names:
        others = [other for other in names if other != name]
        with xr.open_zarr(folder, group=group, consolidated=False, drop_variables=others) as one:
            parts.append(one.isel(draw=steps, missing_dims="ignore").load())
    return xr.merge(parts)


def read_trace(folder: str | os.PathLike) -> xr.DataTree:
    """The posterior draws of a trace folder (:class:`DrawWriter`), as a DataTree.

    Every chain is cut to the posterior draws all chains have on disk, without
    the tuning steps; ``interrupted`` (attribute) is 1 when fewer draws than
    asked for are there. A run stopped before every chain finished tuning has
    no posterior draws yet: ValueError.
    """
    folder = Path(folder)
    meta = _meta(folder)
    tune, chains = meta["tune"], meta["chains"]
    written = written_steps(folder)
    if min(written) <= tune:
        raise ValueError(
            f"{folder}: the run was stopped while tuning ({min(written)} of {tune} tuning steps "
            "written): no posterior draws yet"
        )
    n_draws = min(written) - tune
    parts, elapsed = [], []
    for chain in range(chains):
        parts.append(_read_steps(folder, chain, slice(tune, tune + n_draws)))
        progress = json.loads((folder / f"chain_{chain}.json").read_text(encoding="utf-8"))
        elapsed.append(progress["elapsed_s"])
    joined = xr.concat(parts, dim="chain").assign_coords(
        chain=np.arange(chains), draw=np.arange(n_draws)
    )
    stats = [n for n in joined.data_vars if str(n).startswith(_STAT)]
    posterior = joined.drop_vars(stats)
    sample_stats = joined[stats].drop_vars(f"{_STAT}in_warmup")
    prefixes = {str(n).split("__", 2)[1] for n in sample_stats.data_vars}
    # One step method: PyMC's usual stat names carry no prefix; more: sampler_<i>__name.
    sample_stats = sample_stats.rename(
        {
            n: str(n).split("__", 2)[2]
            if len(prefixes) == 1
            else "sampler_{}__{}".format(*str(n).split("__", 2)[1:])
            for n in sample_stats.data_vars
        }
    )
    attrs = {"sampling_time": float(max(elapsed)), "tuning_steps": tune}
    posterior.attrs.update(attrs)
    sample_stats.attrs.update(attrs)
    groups = {"/posterior": posterior, "/sample_stats": sample_stats}
    for group in ("observed_data", "constant_data"):
        if (folder / group).is_dir():
            with xr.open_zarr(folder, group=group, consolidated=False) as data:
                groups[f"/{group}"] = data.load()
    tree = xr.DataTree.from_dict(groups)
    tree.attrs.update(attrs, sampler=meta["sampler"], interrupted=int(n_draws < meta["draws"]))
    return tree
