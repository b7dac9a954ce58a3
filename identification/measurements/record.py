"""One phase-resonance test record in the TRC layout: the type, reading and writing it.

The files and their columns are described in
:mod:`identification.measurements.trc_layout`; the step schedule in
:mod:`identification.measurements.steps`, the modes in
:mod:`identification.measurements.modes`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from identification.artifacts import atomic_write_text
from identification.measurements.modes import Modes, read_modes
from identification.measurements.quantities import TEST_TYPES, check_choice
from identification.measurements.series import check_increasing, frozen_array
from identification.measurements.steps import StepSchedule, read_steps
from identification.measurements.text_table import format_table
from identification.measurements.trc_layout import (
    BASE,
    CENTRE_POINT,
    DATA_COLUMNS,
    N_PANEL_POINTS,
    PANEL,
    config_files,
    name_part,
    read_trc_table,
)

__all__ = ["Record", "read_record", "write_record"]


@dataclass(frozen=True, eq=False)
class Record:
    """One phase-resonance test record in the TRC layout.

    Attributes
    ----------
    data
        The (n, 20) samples in file column order (:data:`DATA_COLUMNS`), read-only.
    steps
        The step schedule of the record's configuration.
    name
        File stem ``ConfigN_PRT_AssembA[_R]``.
    modes
        Linear modes of the configuration, when a modes file exists.
    path
        The file it was read from (None for records built in memory).
    test
        The test type (:data:`~identification.measurements.quantities.TEST_TYPES`):
        ``phase-resonance`` (the holds), or ``free-decay`` for the decay segments of
        the record (where the step schedule's level is 0 after a hold).

    What every test record offers (the column layout's
    :class:`~identification.measurements.columns.ColumnRecord` too): the
    ``response`` (the centre velocity relative to the base: ``quantity``
    velocity, ``relative``), the ``excitation`` (the base velocity:
    ``excitation_kind`` base-velocity), ``frequency_hz``, ``steps`` and ``test``.
    """

    data: np.ndarray
    steps: StepSchedule
    name: str
    modes: Modes | None = None
    path: Path | None = None
    test: str = "phase-resonance"

    #: The response is the centre-point velocity relative to the base.
    quantity = "velocity"
    relative = True
    #: The excitation is the base velocity; no force, so no forcing gain.
    excitation_kind = "base-velocity"
    forcing_gain = None

    def __post_init__(self) -> None:
        where = self.path or self.name
        check_choice("test", self.test, TEST_TYPES)
        data = frozen_array(self.data)
        if data.ndim != 2 or data.shape[1] != len(DATA_COLUMNS):
            raise ValueError(
                f"{where}: found {data.shape[-1] if data.ndim == 2 else data.shape} columns, "
                f"expected {len(DATA_COLUMNS)}"
            )
        if data.shape[0] < 2:
            raise ValueError(f"{where}: needs at least two samples")
        if not np.isfinite(data).all():
            row, col = np.argwhere(~np.isfinite(data))[0]
            raise ValueError(f"{where}: non-finite value at row {row + 1}, column {col + 1}")
        check_increasing(where, data[:, 0], strict=True)
        if self.modes is not None and self.modes.shapes.shape[0] != N_PANEL_POINTS:
            raise ValueError(
                f"{where}: the modes {self.modes.source} have {self.modes.shapes.shape[0]} shape "
                f"rows; the TRC layout's are at its {N_PANEL_POINTS} panel points"
            )
        half_sample = 0.5 * (data[-1, 0] - data[0, 0]) / (data.shape[0] - 1)
        if not self.steps.covers(data[0, 0], data[-1, 0], half_sample):
            raise ValueError(
                f"{where}: step file {self.steps.source or ''} does not cover the data: "
                f"steps span {self.steps.time_s[0]:g}–{self.steps.time_s[-1]:g} s, "
                f"data span {data[0, 0]:g}–{data[-1, 0]:g} s"
            )
        object.__setattr__(self, "data", data)

    # -- identity
    @property
    def config(self) -> str | None:
        return name_part(self.name, "config")

    @property
    def assembly(self) -> str | None:
        return name_part(self.name, "assembly")

    @property
    def run(self) -> str | None:
        return name_part(self.name, "run")

    # -- channels
    @property
    def time_s(self) -> np.ndarray:
        return self.data[:, 0]

    @property
    def panel_velocity(self) -> np.ndarray:
        """(n, 15) panel-point velocities (m/s)."""
        return self.data[:, PANEL]

    @property
    def base_velocity(self) -> np.ndarray:
        """(n, 2) base-point velocities (m/s)."""
        return self.data[:, BASE]

    @property
    def frequency_hz(self) -> np.ndarray:
        return self.data[:, -2]

    @property
    def phase_deg(self) -> np.ndarray:
        return self.data[:, -1]

    @cached_property
    def excitation_velocity(self) -> np.ndarray:
        """Base velocity: mean of the two base points (m/s)."""
        return self.base_velocity.mean(axis=1)

    @cached_property
    def response_velocity(self) -> np.ndarray:
        """Centre-point velocity relative to the base (m/s)."""
        return self.panel_velocity[:, CENTRE_POINT - 1] - self.excitation_velocity

    @property
    def sensor_names(self) -> tuple[str, ...]:
        """Names of the response channels: the panel points' data columns."""
        return DATA_COLUMNS[PANEL]

    @cached_property
    def sensor_responses(self) -> np.ndarray:
        """(n, 15) panel-point velocities relative to the base (m/s); column 8 is the response."""
        return self.panel_velocity - self.excitation_velocity[:, None]

    @property
    def response(self) -> np.ndarray:
        """The response: :attr:`response_velocity`."""
        return self.response_velocity

    @property
    def excitation(self) -> np.ndarray:
        """The excitation: :attr:`excitation_velocity`."""
        return self.excitation_velocity

    @property
    def frequency_channel(self) -> np.ndarray:
        return self.frequency_hz

    @property
    def sampling_rate_hz(self) -> float:
        t = self.time_s
        return (t.size - 1) / (t[-1] - t[0])

    def __repr__(self) -> str:
        return (
            f"<Record {self.name}: {self.data.shape[0]} samples, "
            f"{self.time_s[-1] - self.time_s[0]:.3g} s at {self.sampling_rate_hz:.6g} Hz>"
        )


def read_record(
    path: str | Path,
    steps: str | Path | StepSchedule | None = None,
    modes: str | Path | Modes | None = None,
    progress: bool = False,
    test: str = "phase-resonance",
    decimal_comma: bool | None = None,
) -> Record:
    """Read a TRC data file.

    Parameters
    ----------
    path
        The data file ``ConfigN_PRT_AssembA[_R]`` (any extension).
    steps, modes
        The step schedule and modes, or their files. By default the files of the
        same configuration next to ``path`` are used; the step file is required,
        the modes file optional.
    progress
        Show a progress bar (bytes read) for long files.
    test
        The record's test type (see :class:`Record`).
    decimal_comma
        The files write ``0,5`` for 0.5; None detects it in each file.

    Notes
    -----
    A long file is read block by block on one core, with a peak memory of a
    little more than the (n, 20) float64 array it returns; ``bench/records.py``
    measures both (``bench/results/records.json``).
    """
    path = Path(path)
    config = name_part(path.name, "config")
    if steps is None or modes is None:
        found = config_files(path.parent).get(config, {}) if config else {}
        if steps is None:
            if "steps" not in found:
                raise ValueError(
                    f"{path}: no step file Config{config}_PRT_amplitude_steps next to it; "
                    "pass steps="
                )
            steps = found["steps"]
        if modes is None:
            modes = found.get("modes")
    if not isinstance(steps, StepSchedule):
        steps = read_steps(steps, decimal_comma=decimal_comma)
    if modes is not None and not isinstance(modes, Modes):
        modes = read_modes(modes, decimal_comma=decimal_comma)
    # The small files first: a missing step file is reported before a long read.
    data = read_trc_table(
        path,
        len(DATA_COLUMNS),
        "data (time, 17 velocities, frequency, phase)",
        decimal_comma=decimal_comma,
        progress=progress,
        complete_lines=True,
    )
    name = path.name.split(".")[0]
    return Record(data, steps, name, modes=modes, path=path, test=test)


def write_record(
    record: Record,
    folder: str | Path,
    comma: bool = False,
    extension: str = "",
    precision: int = 9,
) -> Path:
    """Write a record in the TRC layout: data file, step file and modes file.

    The step and modes files are shared by the records of one configuration: an
    existing one is kept when its content is the same and refused otherwise.

    Parameters
    ----------
    record
        The record; its ``name`` must follow ``ConfigN_PRT_AssembA[_R]``.
    folder
        Target folder (created when missing).
    comma
        Comma-separated instead of blank-separated columns.
    extension
        File extension with its dot (``".csv"``), or ``""`` for none.
    precision
        Digits after the decimal point (``%.{precision}e``); the time column
        keeps at least 9 so that 10 kHz stamps stay distinct in long records.

    Returns
    -------
    Path of the data file.
    """
    config = record.config
    if config is None:
        raise ValueError(f"record name {record.name!r} does not follow ConfigN_PRT_AssembA[_R]")
    folder = Path(folder)
    shared = [(f"Config{config}_PRT_amplitude_steps", record.steps.to_text(comma, precision))]
    if record.modes is not None:
        shared.append(
            (f"Config{config}_linear_complex_modes", record.modes.to_text(comma, precision))
        )
    for stem, text in shared:
        target = folder / f"{stem}{extension}"
        if target.exists() and target.read_text(encoding="utf-8") != text:
            raise ValueError(
                f"{target}: exists with different content; records of config {config} "
                "must share one step schedule and one set of modes"
            )
        atomic_write_text(target, text)
    return atomic_write_text(
        folder / f"{record.name}{extension}", format_table(record.data, comma, precision)
    )
