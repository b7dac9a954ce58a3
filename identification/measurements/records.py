"""TRC phase-resonance test records: read, write, and find them in a folder.

The layout is the Tribomechadynamics Research Challenge (TRC) one, so measured
data and the virtual rig (:mod:`identification.rig`) go through the same path.

Files of one test configuration ``N`` (any extension, or none)::

    ConfigN_PRT_AssembA[_R]        data, one per assembly A (and run R)
    ConfigN_PRT_amplitude_steps    step schedule shared by the data files of config N
    ConfigN_linear_complex_modes   optional linear modes

Data file columns (whitespace or comma separated, no header needed)::

    1       time (s), strictly increasing
    2-16    velocities (m/s) of the 15 panel points of the 5 × 3 grid
    17-18   velocities (m/s) of the 2 base points
    19      instantaneous frequency of the excitation (Hz)
    20      instantaneous phase of the excitation oscillator (deg)

Panel points are numbered row by row over 5 positions along the panel length
and 3 across its width, so point 8 is the centre (either way the grid is read).

Step file: two columns, time (s) and level (shaker voltage, V). The rows are the
breakpoints of a piecewise-linear level schedule; a *hold phase* is a run of
consecutive rows with the same level, spanning from the first to the last of
them, and the segments between different levels are ramps. A sampled level
signal (one row per sample) therefore works as well. Equal consecutive time
stamps are allowed and write an instantaneous jump.

Modes file: 16 rows; rows 1-15 the mode shapes at the panel points (one column
per mode, column 1 the first bending mode), row 16 the natural frequencies (Hz).
Entries are real numbers or complex numbers written ``a+bj`` or ``a+bi`` (the
MATLAB form; no blanks inside a number); with ``pairs=True`` each mode is
instead a pair of columns, real part then imaginary part.

Every file may start with comment lines (``#`` or ``%``) and one header line
of non-numeric labels; both are skipped. A data file whose last line has no
line break is taken for a file cut short (its last number may be cut too): that
line is left out, with a warning. Anything else that is not a table of finite
numbers (a missing or extra column, a non-numeric, NaN or infinite cell, time
stamps that repeat or go back) is a ValueError naming the file, row and line.

Reading is block by block (pandas' C parser, about 16 MB of text at a time)
into one array, so a long record needs little memory beyond its samples;
``read_record(..., progress=True)`` shows a progress bar.
"""

from __future__ import annotations

import io
import re
import warnings
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import BinaryIO

import numpy as np
import pandas as pd

from identification.artifacts import atomic_write_text
from identification.measurements.quantities import TEST_TYPES, check_choice

__all__ = [
    "CENTRE_POINT",
    "DATA_COLUMNS",
    "N_PANEL_POINTS",
    "Campaign",
    "Hold",
    "Modes",
    "Record",
    "RecordFiles",
    "StepSchedule",
    "is_trc_source",
    "read_modes",
    "read_record",
    "read_steps",
    "record_name",
    "write_record",
]

N_PANEL_POINTS = 15
N_BASE_POINTS = 2
#: 1-based number of the panel centre point on the 5 × 3 grid.
CENTRE_POINT = 8
#: Column names of a data file, in file order.
DATA_COLUMNS: tuple[str, ...] = (
    "time_s",
    *(f"panel{p:02d}_m_s" for p in range(1, N_PANEL_POINTS + 1)),
    *(f"base{p}_m_s" for p in range(1, N_BASE_POINTS + 1)),
    "frequency_hz",
    "phase_deg",
)
_PANEL = slice(1, 1 + N_PANEL_POINTS)
_BASE = slice(_PANEL.stop, _PANEL.stop + N_BASE_POINTS)

_ID = r"[A-Za-z0-9-]+"
_EXT = r"(?:\.[^.]*)?"
_DATA_RE = re.compile(
    rf"^Config(?P<config>{_ID})_PRT_Assemb(?P<assembly>{_ID})(?:_(?P<run>{_ID}))?{_EXT}$"
)
_STEPS_RE = re.compile(rf"^Config(?P<config>{_ID})_PRT_amplitude_steps{_EXT}$")
_MODES_RE = re.compile(rf"^Config(?P<config>{_ID})_linear_complex_modes{_EXT}$")
_COMMENT = ("#", "%")
_BOM = b"\xef\xbb\xbf"
#: Text handed to the C parser at a time: large next to a call's overhead, small
#: next to a long record.
_BLOCK_BYTES = 1 << 24


# ---------------------------------------------------------------------------
# Plain-text tables


@dataclass(frozen=True)
class _Layout:
    """Where the numbers of a text table start and how they are separated."""

    skip: int  # leading comment / header / blank lines
    offset: int  # byte at which the first data line starts
    comma: bool
    columns: int  # fields of the first data line
    sep: str  # separator the C parser tries first (see _separator)


def _split(line: str, comma: bool) -> list[str]:
    return [f.strip() for f in line.split(",")] if comma else line.split()


def _is_number(token: str) -> bool:
    try:
        _parse_complex(token)  # real numbers parse too
    except ValueError:
        return False
    return True


def _separator(line: str, comma: bool) -> str:
    """One delimiter character when the first data line has exactly one between fields.

    pandas' C parser splits on one character about a third faster than on runs
    of blanks (``\\s+``); a block where that fails is read again with ``\\s+``.
    """
    if comma:
        return ","
    text = line.rstrip("\r\n")
    blanks = set(re.findall(r"\s", text))
    if len(blanks) == 1 and text == text.strip() and 2 * min(blanks) not in text:
        return min(blanks)
    return r"\s+"


def _sniff(path: Path) -> _Layout:
    """Find the first data line: separator, field count, lines and bytes to skip."""
    header_seen = False
    offset = 0
    with open(path, "rb") as fh:
        for skip, raw in enumerate(fh):
            if skip == 0 and raw.startswith(_BOM):
                raw = raw[len(_BOM) :]
                offset = len(_BOM)
            line = raw.decode("utf-8", errors="replace")
            text = line.strip()
            if text and not text.startswith(_COMMENT):
                comma = "," in text
                fields = _split(text, comma)
                if header_seen or any(_is_number(f) for f in fields):
                    return _Layout(skip, offset, comma, len(fields), _separator(line, comma))
                header_seen = True  # one line of column labels
            offset += len(raw)
    raise ValueError(f"{path}: no numeric data found (the file is empty or only has headers)")


def _text_blocks(fh: BinaryIO, stop: int) -> Iterator[bytes]:
    """Blocks of about ``_BLOCK_BYTES`` of whole lines, from ``fh``'s position to ``stop``."""
    while chunk := fh.read(min(_BLOCK_BYTES, stop - fh.tell())):
        cut = chunk.rfind(b"\n") + 1
        while cut == 0 and (more := fh.read(min(_BLOCK_BYTES, stop - fh.tell()))):
            chunk += more  # a line longer than a block
            cut = chunk.rfind(b"\n") + 1
        if 0 < cut < len(chunk):
            fh.seek(cut - len(chunk), io.SEEK_CUR)  # the partial last line starts the next block
            chunk = chunk[:cut]
        yield chunk


def _complete_lines_end(fh: BinaryIO, size: int) -> int:
    """Byte after the file's last line break (0 when it has none)."""
    end = size
    while end > 0:
        step = min(end, 1 << 16)
        fh.seek(end - step)
        cut = fh.read(step).rfind(b"\n")
        if cut >= 0:
            return end - step + cut + 1
        end -= step
    return 0


def _parse_block(text: bytes, layout: _Layout, columns: int) -> np.ndarray | None:
    """The rows of a block of lines, or None when they are not ``columns`` finite numbers."""
    for sep in dict.fromkeys((layout.sep, "," if layout.comma else r"\s+")):
        try:
            block = pd.read_csv(
                io.BytesIO(text),
                sep=sep,
                header=None,
                dtype=np.float64,
                engine="c",
                na_filter=False,  # "nan" and empty cells are errors, not missing values
                skipinitialspace=layout.comma,
                skip_blank_lines=True,
            ).to_numpy()
        except pd.errors.EmptyDataError:  # blank lines only
            return np.empty((0, columns))
        except (ValueError, pd.errors.ParserError):
            continue
        if block.shape[1] == columns and np.isfinite(block).all():
            return block
    return None


def _plain_float(token: str) -> float:
    # Python's float() also takes "1_000" and non-ASCII digits, which the C parser
    # refuses; refusing them here too keeps the diagnosis in step with the parser.
    if "_" in token or not token.isascii():
        raise ValueError(token)
    return float(token)


def _diagnose(path: Path, start: int, row: int, layout: _Layout, columns: int) -> str:
    """Name the first bad row from byte ``start`` on (a slow scan, only on the error path).

    ``row`` is the number of data rows before ``start``.
    """
    with open(path, "rb") as fh:
        fh.seek(layout.offset)
        line = layout.skip + 1
        while fh.tell() < start:
            line += fh.read(min(start - fh.tell(), _BLOCK_BYTES)).count(b"\n")
        for number, raw in enumerate(fh, start=line):
            fields = _split(raw.decode("utf-8", errors="replace").strip(), layout.comma)
            if fields in ([], [""]):
                continue
            row += 1
            where = f"row {row} (line {number})"
            if len(fields) != columns:
                return f"{where} has {len(fields)} columns, expected {columns}"
            for col, token in enumerate(fields, start=1):
                try:
                    value = _plain_float(token)
                except ValueError:
                    return f"{where}, column {col}: non-numeric value {token!r}"
                if not np.isfinite(value):
                    return f"{where}, column {col}: non-finite value {token!r}"
    return f"unreadable content after line {line}"


def _read_table(
    path: Path, columns: int, what: str, progress: bool = False, complete_lines: bool = False
) -> np.ndarray:
    """Read a numeric table of ``columns`` columns, block by block, into one array.

    pandas' C parser reads each block of about 16 MB of text; the rows go into
    one array grown in place, so the peak memory is the table plus one block's
    worth, whatever the file's size. A block that fails is scanned line by line
    to name the offending row, so errors stay precise without slowing the
    normal path. With ``complete_lines``, a last line without a line break (a
    file cut short mid-line, whose last number may be cut too) is left out
    with a warning.
    """
    if not path.is_file():
        raise ValueError(f"{path}: {what} file not found")
    layout = _sniff(path)
    if layout.columns != columns:
        raise ValueError(
            f"{path}: found {layout.columns} columns, expected {columns} ({what} layout)"
        )
    size = path.stat().st_size
    table = np.empty((0, columns))  # owns its memory: resized in place, never copied
    rows = 0
    with open(path, "rb") as fh, _progress_bar(path, size, layout.offset, progress) as bar:
        stop = size
        if complete_lines:
            stop = max(_complete_lines_end(fh, size), layout.offset)
            fh.seek(stop)
            if fh.read(1 << 20).strip():
                warnings.warn(
                    f"{path}: the last line has no line break, so the file may have been cut "
                    "short mid-line; that line is left out",
                    stacklevel=3,
                )
        fh.seek(layout.offset)
        start = layout.offset
        for text in _text_blocks(fh, stop):
            block = _parse_block(text, layout, columns)
            if block is None:
                raise ValueError(f"{path}: {_diagnose(path, start, rows, layout, columns)}")
            if rows + len(block) > len(table):
                # The rows still to come at this block's bytes per row, and a little more.
                estimate = 1.02 * (stop - fh.tell()) * len(block) / len(text)
                shape = (rows + len(block) + int(estimate) + 1, columns)
                if rows:
                    table.resize(shape, refcheck=False)
                else:  # np.empty: resize would first fill it with zeros
                    table = np.empty(shape)
            table[rows : rows + len(block)] = block
            rows += len(block)
            start += len(text)
            bar.update(len(text))
    if rows == 0:
        raise ValueError(f"{path}: no complete line of numeric data")
    table.resize((rows, columns), refcheck=False)
    table.setflags(write=False)  # owned by nobody else: records keep it without a copy
    return table


def _progress_bar(path: Path, size: int, done: int, show: bool):
    """A tqdm bar over the file's bytes (disabled unless ``show``)."""
    from tqdm.auto import tqdm  # optional at import time

    return tqdm(
        total=size, initial=done, unit="B", unit_scale=True, desc=path.name, disable=not show
    )


def _format_table(table: np.ndarray, comma: bool, precision: int) -> str:
    # Time keeps at least 10 digits so that 10 kHz stamps stay distinct in long records.
    formats = [f"%.{max(precision, 9)}e"] + [f"%.{precision}e"] * (table.shape[1] - 1)
    buffer = io.StringIO()
    np.savetxt(buffer, table, fmt=formats, delimiter="," if comma else " ")
    return buffer.getvalue()


def _check_increasing(where: str | Path, time: np.ndarray, strict: bool) -> None:
    step = np.diff(time)
    bad = np.flatnonzero(step <= 0 if strict else step < 0)
    if bad.size:
        i = bad[0]
        kind = "not increasing" if step[i] < 0 else "duplicated"
        raise ValueError(
            f"{where}: time stamps {kind} at row {i + 2} "
            f"({time[i]:.10g} s then {time[i + 1]:.10g} s)"
        )


# ---------------------------------------------------------------------------
# Step schedule


@dataclass(frozen=True)
class Hold:
    """One hold phase: a constant excitation level from ``start_s`` to ``end_s``."""

    level: float
    start_s: float
    end_s: float

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


@dataclass(frozen=True, eq=False)
class StepSchedule:
    """Breakpoints ``(time_s, level)`` of a piecewise-linear excitation schedule."""

    time_s: np.ndarray
    level: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "step schedule"
        time = _frozen_array(self.time_s)
        level = _frozen_array(self.level)
        if time.ndim != 1 or time.shape != level.shape or time.size < 2:
            raise ValueError(f"{where}: needs at least two (time, level) rows of equal length")
        if not (np.isfinite(time).all() and np.isfinite(level).all()):
            raise ValueError(f"{where}: non-finite time or level")
        _check_increasing(where, time, strict=False)
        object.__setattr__(self, "time_s", time)
        object.__setattr__(self, "level", level)

    def holds(self) -> list[Hold]:
        """Hold phases in time order: runs of equal level with a positive duration."""
        change = np.flatnonzero(np.diff(self.level) != 0) + 1
        starts = np.concatenate(([0], change))
        ends = np.concatenate((change, [self.level.size])) - 1
        return [
            Hold(float(self.level[a]), float(self.time_s[a]), float(self.time_s[b]))
            for a, b in zip(starts, ends, strict=True)
            if self.time_s[b] > self.time_s[a]
        ]

    def level_at(self, time_s: np.ndarray) -> np.ndarray:
        """Level at the given times (linear along ramps)."""
        return np.interp(time_s, self.time_s, self.level)

    def covers(self, start_s: float, end_s: float, tolerance_s: float = 0.0) -> bool:
        """True when the schedule spans ``[start_s, end_s]`` (within ``tolerance_s``)."""
        return self.time_s[0] <= start_s + tolerance_s and self.time_s[-1] >= end_s - tolerance_s

    def to_text(self, comma: bool = False, precision: int = 9) -> str:
        return _format_table(np.column_stack([self.time_s, self.level]), comma, precision)


def read_steps(path: str | Path) -> StepSchedule:
    """Read a step file ``ConfigN_PRT_amplitude_steps`` (time s, level)."""
    path = Path(path)
    table = _read_table(path, 2, "step (time, level)")
    return StepSchedule(table[:, 0], table[:, 1], source=str(path))


# ---------------------------------------------------------------------------
# Modes


@dataclass(frozen=True, eq=False)
class Modes:
    """Linear modes at the 15 panel points: ``shapes`` (15, m) and ``frequencies_hz`` (m,)."""

    shapes: np.ndarray
    frequencies_hz: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "modes"
        shapes = _frozen_array(self.shapes, dtype=complex)
        freqs = _frozen_array(self.frequencies_hz)
        if shapes.ndim == 1:
            shapes = _frozen_array(shapes[:, None], dtype=complex)
        if shapes.shape[0] != N_PANEL_POINTS or freqs.shape != (shapes.shape[1],):
            raise ValueError(
                f"{where}: expected {N_PANEL_POINTS} shape rows and one frequency per mode, "
                f"got shapes {shapes.shape} and frequencies {freqs.shape}"
            )
        if not (np.isfinite(shapes).all() and np.isfinite(freqs).all()) or (freqs <= 0).any():
            raise ValueError(f"{where}: mode shapes must be finite and frequencies > 0")
        object.__setattr__(self, "shapes", shapes)
        object.__setattr__(self, "frequencies_hz", freqs)

    @property
    def first_bending(self) -> np.ndarray:
        """Shape of the first bending mode (column 1)."""
        return self.shapes[:, 0]

    def to_text(self, comma: bool = False, precision: int = 9) -> str:
        sep = "," if comma else " "
        rows = [
            sep.join(f"{z.real:.{precision}e}{z.imag:+.{precision}e}j" for z in row)
            for row in self.shapes
        ]
        rows.append(sep.join(f"{f:.{precision}e}" for f in self.frequencies_hz))
        return "\n".join(rows) + "\n"


def _parse_complex(token: str) -> complex:
    # MATLAB writes the imaginary unit as i, Python as j.
    return complex(token[:-1] + "j" if token.endswith("i") else token)


def read_modes(path: str | Path, pairs: bool = False) -> Modes:
    """Read a modes file ``ConfigN_linear_complex_modes`` (see the module notes).

    Parameters
    ----------
    path
        The file.
    pairs
        Columns are (real, imaginary) pairs instead of one complex number each.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: modes file not found")
    layout = _sniff(path)
    rows: list[list[complex]] = []
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for number, line in enumerate(fh, start=1):
            if number <= layout.skip or not line.strip():
                continue
            fields = _split(line.strip(), layout.comma)
            if len(fields) != layout.columns:
                raise ValueError(
                    f"{path}: line {number} has {len(fields)} columns, expected {layout.columns}"
                )
            try:
                rows.append([_parse_complex(f) for f in fields])
            except ValueError:
                raise ValueError(f"{path}: line {number}: non-numeric value in {fields}") from None
    if len(rows) != N_PANEL_POINTS + 1:
        raise ValueError(
            f"{path}: found {len(rows)} rows, expected {N_PANEL_POINTS + 1} "
            f"({N_PANEL_POINTS} mode-shape rows and one frequency row)"
        )
    table = np.array(rows)
    if pairs:
        if table.shape[1] % 2 or np.any(table.imag):
            raise ValueError(f"{path}: pairs=True needs an even number of real columns")
        table = table.real[:, 0::2] + 1j * table.real[:, 1::2]
    freqs = table[-1]
    if np.any(freqs.imag):
        raise ValueError(f"{path}: frequency row (row {N_PANEL_POINTS + 1}) must be real")
    return Modes(table[:-1], freqs.real, source=str(path))


# ---------------------------------------------------------------------------
# Records


def record_name(config: str | int, assembly: str | int, run: str | int | None = None) -> str:
    """The TRC file stem ``Config{config}_PRT_Assemb{assembly}[_{run}]``."""
    name = f"Config{config}_PRT_Assemb{assembly}" + (f"_{run}" if run is not None else "")
    if not _DATA_RE.match(name):
        raise ValueError(f"not a valid TRC record name: {name!r} (use letters, digits and -)")
    return name


def _name_part(name: str, part: str) -> str | None:
    match = _DATA_RE.match(name)
    return match[part] if match else None


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
        data = _frozen_array(self.data)
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
        _check_increasing(where, data[:, 0], strict=True)
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
        return _name_part(self.name, "config")

    @property
    def assembly(self) -> str | None:
        return _name_part(self.name, "assembly")

    @property
    def run(self) -> str | None:
        return _name_part(self.name, "run")

    # -- channels
    @property
    def time_s(self) -> np.ndarray:
        return self.data[:, 0]

    @property
    def panel_velocity(self) -> np.ndarray:
        """(n, 15) panel-point velocities (m/s)."""
        return self.data[:, _PANEL]

    @property
    def base_velocity(self) -> np.ndarray:
        """(n, 2) base-point velocities (m/s)."""
        return self.data[:, _BASE]

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

    Notes
    -----
    A long file is read block by block on one core, at about 200 MB of text
    per second, with a peak memory of about 1.3 times the (n, 20) float64
    array it returns (``bench/records.py``, 500 MB of text).
    """
    path = Path(path)
    config = _name_part(path.name, "config")
    if steps is None or modes is None:
        found = _config_files(path.parent).get(config, {}) if config else {}
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
        steps = read_steps(steps)
    if modes is not None and not isinstance(modes, Modes):
        modes = read_modes(modes)
    # The small files first: a missing step file is reported before a long read.
    data = _read_table(
        path,
        len(DATA_COLUMNS),
        "data (time, 17 velocities, frequency, phase)",
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
        folder / f"{record.name}{extension}", _format_table(record.data, comma, precision)
    )


# ---------------------------------------------------------------------------
# Campaigns


def _natural_key(text: str | None) -> tuple:
    parts = re.split(r"(\d+)", text or "")
    return tuple((0, int(p), "") if p.isdigit() else (1, 0, p) for p in parts)


#: Extensions of binary files, which are never TRC text tables.
_BINARY = (".mat", ".h5", ".hdf5", ".he5", ".nc", ".npz", ".zarr")


def _is_data_file(path: Path) -> bool:
    return (
        path.is_file()
        and _DATA_RE.match(path.name) is not None
        and path.suffix.lower() not in _BINARY
    )


def is_trc_source(source: str | Path) -> bool:
    """Whether ``source`` is a TRC data file or a folder holding one (a binary file, such as
    the HDF5 records of the force-driven rig, is never one, whatever its name)."""
    source = Path(source)
    if source.is_dir():
        return any(_is_data_file(p) for p in source.iterdir())
    return _is_data_file(source)


def _config_files(folder: Path) -> dict[str, dict[str, Path]]:
    """Step and modes files of each configuration in ``folder``."""
    found: dict[str, dict[str, Path]] = {}
    for path in sorted(folder.iterdir()):
        for kind, pattern in (("steps", _STEPS_RE), ("modes", _MODES_RE)):
            match = pattern.match(path.name)
            if match and path.is_file():
                entry = found.setdefault(match["config"], {})
                if kind in entry:
                    raise ValueError(
                        f"{folder}: two {kind} files for config {match['config']}: "
                        f"{entry[kind].name} and {path.name}"
                    )
                entry[kind] = path
    return found


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
    and modes files beside it). Every record gets the test type ``test``.

    Examples
    --------
    >>> campaign = Campaign("campaign_folder")  # doctest: +SKIP
    >>> for record in campaign: ...             # doctest: +SKIP
    """

    def __init__(self, folder: str | Path, test: str = "phase-resonance") -> None:
        source = Path(folder)
        self.test = check_choice("test", test, TEST_TYPES)
        single = _is_data_file(source)
        self.folder = source.parent if single else source
        if not self.folder.is_dir():
            raise ValueError(f"{self.folder}: campaign folder not found")
        configs = _config_files(self.folder)
        paths = [source] if single else [p for p in self.folder.iterdir() if _is_data_file(p)]
        if not paths:
            raise ValueError(f"{self.folder}: no TRC data files (ConfigN_PRT_AssembA[_R])")
        parts = ("config", "assembly", "run")
        paths.sort(key=lambda p: tuple(_natural_key(_name_part(p.name, k)) for k in parts))
        for path in paths:
            if "steps" not in configs.get(_name_part(path.name, "config"), {}):
                raise ValueError(
                    f"{path}: no step file Config{_name_part(path.name, 'config')}"
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
            modes = read_modes(files["modes"]) if "modes" in files else None
            self._shared[config] = (read_steps(files["steps"]), modes)
        return self._shared[config]

    def _read(self, index: int) -> Record:
        path = self.paths[index]
        steps, modes = self._config_inputs(_name_part(path.name, "config"))
        return read_record(path, steps=steps, modes=modes, test=self.test)

    def __repr__(self) -> str:
        return f"<Campaign {self.folder}: {len(self)} records>"


def _frozen_array(values, dtype=float) -> np.ndarray:
    """A read-only array; writable inputs are copied so the caller's array stays theirs."""
    if isinstance(values, np.ndarray) and values.dtype == dtype and not values.flags.writeable:
        return values
    array = np.array(values, dtype=dtype)
    array.setflags(write=False)
    return array
