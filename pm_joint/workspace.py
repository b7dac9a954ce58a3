"""One run's data, each piece read or fitted once: the campaign workspace.

A :class:`Workspace` stands for a campaign (a folder of records in the TRC or
a column layout, or one record file) or a backbones CSV, and what a run makes
of it: the records, their backbones, the joint model, the surrogate, the
likelihood densities and the posterior. Each is read, extracted or fitted on
first use and kept; the pipeline's stages read from the workspace
and put what they make back into it, so that a chain of stages never reads a
record file twice, loads a surrogate twice or refits a density.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from functools import cached_property
from pathlib import Path

import numpy as np
import xarray as xr
from numpy.typing import ArrayLike

from identification.measurements.backbone import BackboneSet
from identification.measurements.columns import (
    ColumnCampaign,
    ColumnLayout,
    is_backbone_table,
    open_records,
)
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Campaign, Record
from identification.model import JointModel
from pm_joint.distributions import BackboneDensity, amplitude_levels
from pm_joint.inference import load_posterior
from surrogates.runtime import SurrogateRuntime

__all__ = ["BACKBONES_FILE", "RecordCache", "Workspace"]

#: Where a campaign folder keeps its extracted backbones.
BACKBONES_FILE = "backbones.csv"


class RecordCache(Sequence[Record]):
    """The records of a campaign, each read on first access and kept while there is room.

    Records are kept until they hold ``max_bytes`` of sample data in all; a
    record read after that is handed out but not kept (read again if asked
    for), so a campaign of long records need not fit in memory, and a second
    pass over the campaign still finds the first records kept. ``reads``
    counts the file reads per record name.
    """

    def __init__(self, campaign: Campaign | ColumnCampaign, max_bytes: int = 2**30) -> None:
        self.campaign = campaign
        self.max_bytes = max_bytes
        self.reads: dict[str, int] = {}
        self._kept: dict[int, Record] = {}
        self._sizes: dict[int, int] = {}

    def __len__(self) -> int:
        return len(self.campaign)

    def __getitem__(self, key):  # int or slice, as Campaign
        if isinstance(key, slice):
            return [self[i] for i in range(*key.indices(len(self)))]
        index = range(len(self))[key]  # negative indices, IndexError
        if index in self._kept:
            return self._kept[index]
        record = self.campaign[index]
        self.reads[record.name] = self.reads.get(record.name, 0) + 1
        size = record.data.nbytes
        if self.kept_bytes + size <= self.max_bytes:
            self._kept[index] = record
            self._sizes[index] = size
        return record

    @property
    def kept_bytes(self) -> int:
        """Bytes of sample data held now."""
        return sum(self._sizes[i] for i in self._kept)


class Workspace:
    """A campaign folder (or a backbones CSV) and what a run makes of it, each made once.

    Parameters
    ----------
    source
        A campaign folder (TRC or column layout), one record file (TRC or column
        layout, a campaign of one), or a backbones CSV (then there are no
        records, only backbones).
    layout
        How column-layout records read and the test type of every record
        (:class:`~identification.measurements.columns.ColumnLayout`).
    model
        The joint model, or its JSON file (read on first use).
    surrogate
        The surrogate folder, or a loaded runtime (loaded on first use).
    posterior
        A posterior file or trace folder of an earlier run (read on first use).
    backbones_csv
        Where a campaign's backbones are kept; default ``source/backbones.csv``
        for a folder, ``<stem>_backbones.csv`` beside a record file.
    n_periods
        Periods per hold phase when backbones are extracted.
    decay_options
        ``window_periods``, ``edge_periods`` and ``band_hz`` of free-decay extraction
        (:func:`~identification.measurements.extraction.extract_backbone`).
    record_cache_bytes
        Sample data of records kept in memory once read (:class:`RecordCache`;
        the full demo's 25 records of 26 s at 10 kHz take about 1 GB).
    progress
        Progress bars while extracting.

    Notes
    -----
    :attr:`backbones` are read from ``backbones_csv`` when it holds a curve for
    every record and was written after every record file; else they are
    extracted from the records (each read once) and written there. A CSV
    extracted with other settings (e.g. ``n_periods``) is taken as it is: the
    file does not say how it was made. What happened is in
    :attr:`backbones_origin`. Stages put what they make back
    (``workspace.model = identified``); assigning replaces the cached value.
    """

    def __init__(
        self,
        source: str | os.PathLike,
        *,
        layout: ColumnLayout | None = None,
        model: JointModel | str | os.PathLike | None = None,
        surrogate: SurrogateRuntime | str | os.PathLike | None = None,
        posterior: str | os.PathLike | None = None,
        backbones_csv: str | os.PathLike | None = None,
        n_periods: int = 70,
        decay_options: dict | None = None,
        record_cache_bytes: int = 2**30,
        progress: bool = True,
    ) -> None:
        self.source = Path(source)
        self.layout = layout or ColumnLayout()
        self.is_campaign = not is_backbone_table(self.source)
        if not self.is_campaign:
            default_csv = self.source
        elif self.source.is_file():
            default_csv = self.source.with_name(f"{self.source.stem}_{BACKBONES_FILE}")
        else:
            default_csv = self.source / BACKBONES_FILE
        self.backbones_csv = Path(backbones_csv) if backbones_csv is not None else default_csv
        self.n_periods = n_periods
        self.decay_options = dict(decay_options or {})
        self.record_cache_bytes = record_cache_bytes
        self.progress = progress
        self.backbones_origin = "not read yet"
        self._model_source = model
        self._surrogate_source = surrogate
        self._posterior_source = posterior
        self._densities: dict[tuple, BackboneDensity] = {}

    def __repr__(self) -> str:
        return f"<Workspace {self.source}>"

    # ------------------------------------------------------------ the records
    @cached_property
    def campaign(self) -> Campaign | ColumnCampaign:
        """The campaign's records (ValueError for a backbones table: it has none)."""
        if not self.is_campaign:
            raise ValueError(f"{self.source} is a backbones table, not a campaign: no records")
        if not self.source.exists():
            raise ValueError(f"{self.source}: campaign folder not found")
        return open_records(self.source, self.layout)

    @cached_property
    def records(self) -> RecordCache:
        """The campaign's records, each read once (within ``record_cache_bytes``)."""
        return RecordCache(self.campaign, self.record_cache_bytes)

    # ----------------------------------------------------------- the backbones
    @cached_property
    def backbones(self) -> BackboneSet:
        """The measured backbones: from the CSV when it is current, else extracted and written."""
        if not self.is_campaign:
            self.backbones_origin = f"read from {self.source}"
            return BackboneSet.from_csv(self.source)
        current = self._current_csv()
        if current is not None:
            self.backbones_origin = f"read from {self.backbones_csv} (newer than every record)"
            return current
        return self.extract_backbones()

    def extract_backbones(self) -> BackboneSet:
        """Extract the backbones of every record now, write them to the CSV and keep them."""
        backbones = extract_backbones(
            self.records, n_periods=self.n_periods, progress=self.progress, **self.decay_options
        )
        backbones.to_csv(self.backbones_csv)
        self.backbones_origin = (
            f"extracted from {len(self.records)} records, written to {self.backbones_csv}"
        )
        self.backbones = backbones
        return backbones

    def _current_csv(self) -> BackboneSet | None:
        """The CSV's backbones if it was written after every record and has a curve for each."""
        csv = self.backbones_csv
        if not csv.is_file():
            return None
        written = csv.stat().st_mtime
        if any(path.stat().st_mtime > written for path in self.campaign.paths):
            return None
        try:
            backbones = BackboneSet.from_csv(csv)
        except ValueError:
            return None
        return backbones if sorted(backbones.labels) == sorted(self.campaign.names) else None

    # ------------------------------------------------ model, surrogate, posterior
    @cached_property
    def model(self) -> JointModel | None:
        """The joint model (None when none was given)."""
        source = self._model_source
        if source is None or isinstance(source, JointModel):
            return source
        return JointModel.from_json(source)

    @cached_property
    def surrogate(self) -> SurrogateRuntime | None:
        """The surrogate runtime, loaded once (None when none was given)."""
        source = self._surrogate_source
        if source is None or isinstance(source, SurrogateRuntime):
            return source
        return SurrogateRuntime.load(source)

    @cached_property
    def posterior(self) -> xr.DataTree:
        """The posterior (ValueError when none was given and no stage made one)."""
        if self._posterior_source is None:
            raise ValueError(f"{self}: no posterior given")
        return load_posterior(self._posterior_source)

    def release_records(self) -> None:
        """Let go of the records kept in memory (a later stage that needs them reads them again)."""
        self.__dict__.pop("records", None)

    @property
    def has_posterior(self) -> bool:
        """Whether a posterior was given or a stage made one."""
        return self._posterior_source is not None or "posterior" in self.__dict__

    # ------------------------------------------------------------- densities
    def density(
        self,
        amplitudes_m: ArrayLike | None = None,
        *,
        channels: Sequence[str] = ("frequency_hz",),
        family: str = "copula",
    ) -> BackboneDensity:
        """The backbones' likelihood density, fitted once per amplitude grid, channels and family.

        ``amplitudes_m`` default: :func:`~pm_joint.distributions.amplitude_levels`.
        """
        grid_m = amplitude_levels(self.backbones) if amplitudes_m is None else amplitudes_m
        grid_m = np.asarray(grid_m, dtype=float)
        key = (tuple(grid_m.tolist()), tuple(channels), family)
        if key not in self._densities:
            self._densities[key] = BackboneDensity.fit(
                self.backbones, grid_m, channels=channels, family=family
            )
        return self._densities[key]
