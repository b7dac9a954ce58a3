"""Finding records in a folder: TRC campaigns, read lazily one record at a time.

A folder's TRC data files (``ConfigN_PRT_AssembA[_R]``,
:mod:`identification.measurements.trc_layout`) are grouped with the step and
modes files of their configuration and ordered by (config, assembly, run),
numbers in numeric order.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from pathlib import Path

from identification.measurements.modes import Modes, read_modes
from identification.measurements.quantities import TEST_TYPES, check_choice
from identification.measurements.record import Record, read_record
from identification.measurements.steps import StepSchedule, read_steps
from identification.measurements.trc_layout import DATA_RE, config_files, name_part

__all__ = ["Campaign", "RecordFiles", "is_trc_source", "natural_key"]


def natural_key(text: str | None) -> tuple:
    """Sort key of a name with its numbers in numeric order (``Assemb2`` before ``Assemb10``)."""
    parts = re.split(r"(\d+)", text or "")
    return tuple((0, int(p), "") if p.isdigit() else (1, 0, p) for p in parts)


#: Extensions of binary files, which are never TRC text tables.
_BINARY = (".mat", ".h5", ".hdf5", ".he5", ".nc", ".npz", ".zarr")


def _is_data_file(path: Path) -> bool:
    return (
        path.is_file()
        and DATA_RE.match(path.name) is not None
        and path.suffix.lower() not in _BINARY
    )


def is_trc_source(source: str | Path) -> bool:
    """Whether ``source`` is a TRC data file or a folder holding one (a binary file, such as
    the HDF5 records of the force-driven rig, is never one, whatever its name)."""
    source = Path(source)
    if source.is_dir():
        return any(_is_data_file(p) for p in source.iterdir())
    return _is_data_file(source)


class RecordFiles(Sequence):
    """Records of files (``paths``), read lazily one at a time by index, slice or name.

    Subclasses give ``folder``, ``names`` (one per path) and ``_read(index)``.
    """

    paths: list[Path] | tuple[Path, ...]
    folder: Path

    @property
    def names(self) -> list[str]:
        raise NotImplementedError

    def _read(self, index: int):
        raise NotImplementedError

    def __len__(self) -> int:
        return len(self.paths)

    def __getitem__(self, key):  # int, slice or record name
        if isinstance(key, str):
            try:
                key = self.names.index(key)
            except ValueError:
                raise KeyError(f"no record {key!r} in {self.folder}") from None
        if isinstance(key, slice):
            return [self[i] for i in range(*key.indices(len(self)))]
        return self._read(key)

    def __iter__(self) -> Iterator:
        for i in range(len(self)):
            yield self[i]


class Campaign(RecordFiles):
    """All TRC records of a folder (or one data file), read lazily one at a time.

    Data files are grouped with the step and modes files of their configuration
    and ordered by (config, assembly, run), numbers in numeric order. A data
    file given instead of a folder is a campaign of that one record (its step
    and modes files beside it). Every record gets the test type ``test``;
    ``decimal_comma`` says the files write ``0,5`` for 0.5 (None detects it).

    Examples
    --------
    >>> campaign = Campaign("campaign_folder")  # doctest: +SKIP
    >>> for record in campaign: ...             # doctest: +SKIP
    """

    def __init__(
        self,
        folder: str | Path,
        test: str = "phase-resonance",
        decimal_comma: bool | None = None,
    ) -> None:
        source = Path(folder)
        self.test = check_choice("test", test, TEST_TYPES)
        self.decimal_comma = decimal_comma
        single = _is_data_file(source)
        self.folder = source.parent if single else source
        if not self.folder.is_dir():
            raise ValueError(f"{self.folder}: campaign folder not found")
        configs = config_files(self.folder)
        paths = [source] if single else [p for p in self.folder.iterdir() if _is_data_file(p)]
        if not paths:
            raise ValueError(f"{self.folder}: no TRC data files (ConfigN_PRT_AssembA[_R])")
        parts = ("config", "assembly", "run")
        paths.sort(key=lambda p: tuple(natural_key(name_part(p.name, k)) for k in parts))
        for path in paths:
            if "steps" not in configs.get(name_part(path.name, "config"), {}):
                raise ValueError(
                    f"{path}: no step file Config{name_part(path.name, 'config')}"
                    "_PRT_amplitude_steps in the folder"
                )
        self.paths: tuple[Path, ...] = tuple(paths)
        self._configs = configs
        self._shared: dict[str, tuple[StepSchedule, Modes | None]] = {}

    @property
    def names(self) -> list[str]:
        return [p.name.split(".")[0] for p in self.paths]

    def _config_inputs(self, config: str) -> tuple[StepSchedule, Modes | None]:
        if config not in self._shared:
            files = self._configs[config]
            comma = self.decimal_comma
            modes = read_modes(files["modes"], decimal_comma=comma) if "modes" in files else None
            self._shared[config] = (read_steps(files["steps"], decimal_comma=comma), modes)
        return self._shared[config]

    def config_modes(self) -> dict[str, Modes | None]:
        """The linear modes of each configuration of the campaign (None: no modes file), read
        without reading a data file."""
        configs = {name_part(p.name, "config") for p in self.paths}
        return {config: self._config_inputs(config)[1] for config in sorted(configs)}

    def _read(self, index: int) -> Record:
        path = self.paths[index]
        steps, modes = self._config_inputs(name_part(path.name, "config"))
        return read_record(
            path, steps=steps, modes=modes, test=self.test, decimal_comma=self.decimal_comma
        )

    def __repr__(self) -> str:
        return f"<Campaign {self.folder}: {len(self)} records>"
