"""Test records in a column layout: CSV/TSV with a header, MAT (v5 and v7.3) and HDF5 files.

Labs keep a test as a few named signals: the time, a response (a displacement,
velocity or acceleration of one sensor), perhaps the excitation (a base
acceleration or velocity, or a force), perhaps the controller's frequency
channel and the commanded level. :class:`ColumnLayout` says which column is
which and what the test was; :func:`read_columns` reads one file into a
:class:`ColumnRecord`, which offers what the TRC records
(:class:`~identification.measurements.records.Record`) offer, so that the
backbones and the identification take either.

Formats (every one read by its library, nothing parsed by hand):

* **Text** (``.csv``, ``.tsv``, ``.txt``, ``.dat``): one header line of column
  names, then rows; comma, semicolon, tab or blank separated; a decimal comma
  (German-locale exports: ``0,5;1,25``) is detected when the separator is not a
  comma, or stated (``decimal_comma=True``). Comment lines (``#``, ``%``) before
  the header are skipped. Read by pandas' C parser. A last line without a line
  break (a file cut short) is left out with a one-line warning.
* **MAT v5** (scipy.io.loadmat): numeric vectors as variables, fields of a
  struct (``data.time``), or the columns of a matrix named by a cell array of
  strings (``names``, ``labels``, ``channels`` or ``columns``).
* **MAT v7.3 and HDF5** (h5py): 1-D datasets (MATLAB's n×1 arrays included),
  by their path (``group/time``) or name, and the fields of a table (compound)
  dataset.

A scalar ``fs``, ``sampling_rate``, ``sample_rate`` or ``sampling_rate_hz`` (a
variable, dataset or attribute) gives the time axis when there is no time
column. Names match case-insensitively and without a unit in brackets
(``Time [s]`` is ``time``).
"""

from __future__ import annotations

import dataclasses
import io
import math
import re
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd

from identification.measurements.quantities import (
    BASE_KINDS,
    EXCITATION_KINDS,
    QUANTITIES,
    TEST_TYPES,
    UNITS,
    check_choice,
)
from identification.measurements.records import (
    Campaign,
    RecordFiles,
    StepSchedule,
    is_trc_source,
)
from identification.measurements.signals import central_difference, trapezoid_integral

__all__ = [
    "COLUMN_EXTENSIONS",
    "ColumnCampaign",
    "ColumnLayout",
    "ColumnRecord",
    "is_backbone_table",
    "is_column_file",
    "open_records",
    "read_columns",
    "read_table",
    "write_columns",
]

TEXT_EXTENSIONS = (".csv", ".tsv", ".txt", ".dat")
HDF5_EXTENSIONS = (".h5", ".hdf5", ".he5")
#: File extensions read as column-layout records.
COLUMN_EXTENSIONS = (*TEXT_EXTENSIONS, ".mat", *HDF5_EXTENSIONS)
_RATE_NAMES = ("fs", "sampling_rate", "sample_rate", "sampling_rate_hz", "samplingrate")
_NAME_LISTS = ("names", "labels", "channels", "columns")
_COMMENT = ("#", "%")
_DECIMAL_COMMA = re.compile(r"^[+-]?\d*,\d+(?:[eE][+-]?\d+)?$")
#: Relative spread of the time steps beyond which a record is not uniformly sampled.
_UNIFORM = 1e-3


def _normal(name: str) -> str:
    """A column name without case, blanks or a unit in brackets: ``Time [s]`` → ``time``."""
    name = re.sub(r"[\[(].*?[\])]", "", str(name)).strip().lower()
    return re.sub(r"[\s.\-]+", "_", name).strip("_")


# ---------------------------------------------------------------------------
# Reading tables


def _text_table(path: Path, decimal_comma: bool | None) -> dict[str, np.ndarray]:
    raw = path.read_bytes()
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    if raw and not raw.endswith(b"\n"):
        cut = raw.rfind(b"\n") + 1
        if raw[cut:].strip():
            warnings.warn(
                f"{path}: the last line has no line break (the file was cut short?); "
                "that line is left out",
                stacklevel=4,
            )
        raw = raw[:cut]
    text = raw.decode("utf-8", errors="replace")
    lines = text.splitlines(keepends=True)
    skip = 0
    while skip < len(lines) and (
        not lines[skip].strip() or lines[skip].lstrip().startswith(_COMMENT)
    ):
        skip += 1
    if skip + 1 >= len(lines):
        raise ValueError(f"{path}: needs a header line of column names and rows of numbers")
    header, first = lines[skip], lines[skip + 1]
    for sep in (";", "\t", ","):
        if sep in header:
            break
    else:
        sep = r"\s+"
    if decimal_comma is None:
        fields = re.split(sep, first.strip()) if sep == r"\s+" else first.strip().split(sep)
        decimal_comma = sep != "," and any(_DECIMAL_COMMA.match(f.strip()) for f in fields)
    if decimal_comma and sep == ",":
        raise ValueError(f"{path}: a decimal comma cannot go with comma-separated columns")
    body = "".join(lines[skip:])
    options = dict(sep=sep, engine="c", skipinitialspace=True, na_filter=False)
    try:
        frame = pd.read_csv(io.StringIO(body), decimal="," if decimal_comma else ".",
                            dtype=float, **options)  # fmt: skip
    except (ValueError, pd.errors.ParserError) as exc:
        # Name the first bad cell: read again as text (only on this error path).
        try:
            text_frame = pd.read_csv(io.StringIO(body), dtype=str, **options)
        except (ValueError, pd.errors.ParserError):
            raise ValueError(f"{path}: not a readable table ({str(exc).splitlines()[0]})") from None
        raise ValueError(f"{path}: {_first_bad_cell(text_frame, skip, decimal_comma)}") from None
    columns = {}
    for name in frame.columns:
        values = frame[name].to_numpy(dtype=float)
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            row = int(bad[0])
            raise ValueError(
                f"{path}: row {row + 1} (line {skip + row + 2}), column {name!r}: not finite"
            )
        columns[str(name)] = values
    return columns


def _first_bad_cell(frame: pd.DataFrame, skip: int, decimal_comma: bool) -> str:
    """Where the first cell of a text table is not a number, and what it holds."""
    for name in frame.columns:
        cells = frame[name].str.strip()
        numbers = cells.str.replace(",", ".", regex=False) if decimal_comma else cells
        bad = np.flatnonzero(pd.to_numeric(numbers, errors="coerce").isna().to_numpy())
        if bad.size:
            row, cell = int(bad[0]), cells.iloc[int(bad[0])]
            hint = " (a decimal comma? pass --decimal-comma)" if "," in cell else ""
            return (f"row {row + 1} (line {skip + row + 2}), column {name!r}: not a number: "
                    f"{cell!r}{hint}")  # fmt: skip
    return "rows of unequal length"


def _mat_table(path: Path) -> dict[str, np.ndarray]:
    from scipy.io import loadmat

    data = loadmat(path, squeeze_me=True, struct_as_record=False)
    columns: dict[str, np.ndarray] = {}
    names = next(
        ([str(n) for n in np.atleast_1d(data[k])] for k in data if k.lower() in _NAME_LISTS), None
    )

    def add(prefix: str, value) -> None:
        if hasattr(value, "_fieldnames"):  # a MATLAB struct
            for name in value._fieldnames:
                add(f"{prefix}/{name}", getattr(value, name))
            return
        array = np.asarray(value)
        if array.dtype.kind not in "fiub":
            return
        array = array.astype(float)
        if array.ndim <= 1:
            columns[prefix] = array
        elif array.ndim == 2 and names is not None and len(names) in array.shape:
            table = array if array.shape[1] == len(names) else array.T
            for j, name in enumerate(names):
                columns[name] = table[:, j]

    for key, value in data.items():
        if not key.startswith("__"):
            add(key, value)
    return columns


def _hdf5_table(path: Path) -> dict[str, np.ndarray]:
    import h5py

    columns: dict[str, np.ndarray] = {}
    with h5py.File(path, "r") as fh:
        for key, value in fh.attrs.items():
            if np.ndim(value) == 0 and np.asarray(value).dtype.kind in "fiu":
                columns[key] = np.asarray(value, dtype=float)

        def visit(name: str, node) -> None:
            if not isinstance(node, h5py.Dataset) or name.startswith("#"):
                return
            if node.dtype.names:  # a table: one column per field
                for field_name in node.dtype.names:
                    columns[f"{name}/{field_name}"] = np.asarray(node[field_name], float).ravel()
            elif node.dtype.kind in "fiu" and (node.ndim <= 1 or min(node.shape) == 1):
                columns[name] = np.asarray(node[()], dtype=float).ravel() if node.ndim else (
                    np.asarray(node[()], dtype=float))  # fmt: skip

        fh.visititems(visit)
    return columns


def read_table(path: str | Path, decimal_comma: bool | None = None) -> dict[str, np.ndarray]:
    """Every numeric column (and scalar) of a column-layout file, by name (see the module notes).

    Raises
    ------
    ValueError
        A missing file, an unknown extension, or content that is not a table of
        finite numbers (naming the row and column).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: file not found")
    suffix = path.suffix.lower()
    if suffix in TEXT_EXTENSIONS:
        return _text_table(path, decimal_comma)
    if suffix == ".mat":
        import h5py

        return _hdf5_table(path) if h5py.is_hdf5(path) else _mat_table(path)  # v7.3 is HDF5
    if suffix in HDF5_EXTENSIONS:
        return _hdf5_table(path)
    raise ValueError(
        f"{path}: unknown file type {suffix!r}; column layouts are {', '.join(COLUMN_EXTENSIONS)}"
    )


# ---------------------------------------------------------------------------
# Layout and record


@dataclass(frozen=True)
class ColumnLayout:
    """Which column is which, and what the test was.

    Attributes
    ----------
    test
        ``phase-resonance``, ``stepped-sine`` or ``free-decay``.
    time
        Time column (s); default a column named ``time`` or ``t``, else a scalar
        sampling rate.
    response
        Response column; default the one column no other role takes.
    quantity
        ``displacement``, ``velocity`` or ``acceleration`` of the response (SI);
        default from the response's name when it says (``disp…``, ``vel…``, ``acc…``).
    excitation
        Excitation column; default the one column whose name says it is one
        (``excitation…``, ``force…``, ``base…acc…``, ``base…vel…``), else none
        (a free decay needs none).
    excitation_kind
        ``base-acceleration``, ``base-velocity`` or ``force``; default from the
        excitation's name when it says (``force…``, ``base…acc…``, ``base…vel…``).
    excitation_gain
        SI units of the kind per unit of the column (N/V for a force read as a voltage).
    frequency
        Controller frequency column (Hz); default a column named ``frequency…``.
    level
        Commanded level column (its runs of equal value are the holds); default a
        column named ``level…``.
    decimal_comma
        Text files: None detects it.
    relative
        The response is measured relative to the base (else it is absolute and
        the base motion is taken off); no effect without base excitation.
    forcing_gain
        Modal forcing gain of a force-driven test (1/kg), when known; else it is
        estimated from the record's decay (:mod:`identification.measurements.forcing`).
    """

    test: str = "phase-resonance"
    time: str | None = None
    response: str | None = None
    quantity: str | None = None
    excitation: str | None = None
    excitation_kind: str | None = None
    excitation_gain: float = 1.0
    frequency: str | None = None
    level: str | None = None
    decimal_comma: bool | None = None
    relative: bool = False
    forcing_gain: float | None = None

    def __post_init__(self) -> None:
        check_choice("test", self.test, TEST_TYPES)
        if self.quantity is not None:
            check_choice("quantity", self.quantity, QUANTITIES)
        if self.excitation_kind is not None:
            check_choice("excitation kind", self.excitation_kind, EXCITATION_KINDS)
        for name in ("excitation_gain", "forcing_gain"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be finite and > 0, got {value}")


def _guess(name: str, rules: Sequence[tuple[Sequence[str], str]]) -> str | None:
    normal = _normal(name)
    for words, value in rules:
        if all(w in normal for w in words):
            return value
    return None


_QUANTITY_RULES = (
    (("disp",), "displacement"), (("vel",), "velocity"), (("acc",), "acceleration"),
)  # fmt: skip
_KIND_RULES = (
    (("force",), "force"), (("base", "acc"), "base-acceleration"),
    (("base", "vel"), "base-velocity"),
)  # fmt: skip


@dataclass(frozen=True, eq=False)
class ColumnRecord:
    """One test record of the column layout (see the module notes).

    Offers what :class:`~identification.measurements.records.Record` offers
    (``time_s``, ``response_velocity``, ``excitation_velocity``, ``frequency_hz``,
    ``steps``, ``name``, ``path``), so that extraction and identification take both.

    Attributes
    ----------
    time_s
        Sample times (s), strictly increasing and uniformly sampled.
    response
        The response as measured (SI units of ``quantity``).
    quantity
        ``displacement``, ``velocity`` or ``acceleration``.
    name
        Record name (the file stem).
    test
        ``phase-resonance``, ``stepped-sine`` or ``free-decay``.
    response_name
        The response column's name.
    excitation, excitation_kind, excitation_name
        The excitation (SI units of its kind) and its kind and column, or None.
    frequency_channel
        The controller's frequency (Hz), or None.
    steps
        Step schedule (from a level column), or None.
    relative
        Whether the response is relative to the base.
    stated_forcing_gain
        Modal forcing gain (1/kg) of a force-driven test when known.
    path
        The file it was read from.

    Raises
    ------
    ValueError
        Arrays of different lengths, non-finite samples, time that is not
        strictly increasing and uniform, and the records that cannot be
        identified: a driven test (phase-resonance, stepped-sine) without an
        excitation channel, or with one that is zero throughout.
    """

    time_s: np.ndarray
    response: np.ndarray
    quantity: str
    name: str
    test: str = "phase-resonance"
    response_name: str = "response"
    excitation: np.ndarray | None = None
    excitation_kind: str | None = None
    excitation_name: str | None = None
    frequency_channel: np.ndarray | None = None
    steps: StepSchedule | None = None
    relative: bool = False
    stated_forcing_gain: float | None = None
    path: Path | None = None

    def __post_init__(self) -> None:
        where = self.path or self.name
        check_choice("test", self.test, TEST_TYPES)
        check_choice("quantity", self.quantity, QUANTITIES)
        time = _frozen(self.time_s)
        arrays = {"time": time, self.response_name: _frozen(self.response)}
        if self.excitation is not None:
            check_choice("excitation kind", self.excitation_kind or "", EXCITATION_KINDS)
            arrays[self.excitation_name or "excitation"] = _frozen(self.excitation)
        if self.frequency_channel is not None:
            arrays["frequency"] = _frozen(self.frequency_channel)
        for name, values in arrays.items():
            if values.ndim != 1 or values.size != time.size:
                raise ValueError(
                    f"{where}: column {name!r} has {values.size} samples, the time {time.size}"
                )
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise ValueError(f"{where}: column {name!r}, row {bad[0] + 1}: not finite")
        if time.size < 3:
            raise ValueError(f"{where}: needs at least three samples")
        steps = np.diff(time)
        if np.any(steps <= 0):
            i = int(np.argmax(steps <= 0))
            raise ValueError(f"{where}: time is not strictly increasing at row {i + 2}")
        rate = (time.size - 1) / (time[-1] - time[0])
        if np.max(np.abs(steps * rate - 1)) > _UNIFORM:
            raise ValueError(
                f"{where}: time is not uniformly sampled (steps {steps.min():.6g} to "
                f"{steps.max():.6g} s); resample first"
            )
        object.__setattr__(self, "time_s", time)
        object.__setattr__(self, "response", arrays[self.response_name])
        if self.excitation is not None:
            object.__setattr__(self, "excitation", arrays[self.excitation_name or "excitation"])
        if self.frequency_channel is not None:
            object.__setattr__(self, "frequency_channel", arrays["frequency"])
        if np.all(self.response == self.response[0]):
            raise ValueError(f"{where}: the response {self.response_name!r} is constant")
        if self.test != "free-decay":
            self._check_driven(where)

    def _check_driven(self, where) -> None:
        if self.excitation is None:
            raise ValueError(
                f"{where}: a {self.test} test needs its excitation measured and there is no "
                "excitation channel: with the response alone, a steady response at one "
                "frequency gives that frequency as the 'natural' one whatever the structure; "
                "name the excitation (--excitation NAME --excitation-kind KIND), or read a "
                "ring-down with --test free-decay"
            )
        if not np.any(self.excitation):
            raise ValueError(
                f"{where}: the excitation channel {self.excitation_name!r} "
                f"({self.excitation_kind}) is zero throughout: nothing drives this record; "
                "a ring-down is read with --test free-decay"
            )

    # -- what a TRC record offers
    @property
    def sampling_rate_hz(self) -> float:
        t = self.time_s
        return (t.size - 1) / (t[-1] - t[0])

    @property
    def base_driven(self) -> bool:
        return self.excitation_kind in BASE_KINDS

    @cached_property
    def frequency_hz(self) -> np.ndarray:
        """The frequency channel, else a track from local fits of the excitation (or, without
        one, of the response) (:func:`identification.measurements.tracking.frequency_track`)."""
        if self.frequency_channel is not None:
            return self.frequency_channel
        from identification.measurements.tracking import frequency_track

        signal = self.excitation if self.excitation is not None else self.response
        try:
            return frequency_track(self.time_s, signal)
        except ValueError as exc:
            raise ValueError(f"{self.path or self.name}: {exc}") from None

    @cached_property
    def excitation_velocity(self) -> np.ndarray:
        """Base velocity (m/s) that drives the model as the excitation does (zeros without one).

        A base acceleration is integrated (trapezoidal rule, then its linear
        trend taken off: the integration constant and a sensor bias); a force
        ``F`` becomes the integral of the equivalent base acceleration ``−g·F``
        (:mod:`identification.measurements.quantities`), with ``g`` the stated or
        estimated forcing gain (:attr:`forcing_gain`).
        """
        if self.excitation is None:
            return np.zeros_like(self.time_s)
        if self.excitation_kind == "base-velocity":
            return self.excitation
        acceleration = self.excitation
        if self.excitation_kind == "force":
            acceleration = -self.forcing_gain * self.excitation
        return _detrended_integral(acceleration, self.sampling_rate_hz)

    @cached_property
    def response_velocity(self) -> np.ndarray:
        """Velocity (m/s) of the response relative to the base, from the measured quantity.

        A displacement is differentiated (central differences), an acceleration
        integrated (trapezoidal rule, linear trend off); an absolute response of a
        base-driven test has the base velocity taken off.
        """
        rate = self.sampling_rate_hz
        if self.quantity == "displacement":
            velocity = central_difference(self.response, rate)
        elif self.quantity == "acceleration":
            velocity = _detrended_integral(self.response, rate)
        else:
            velocity = self.response
        if self.base_driven and not self.relative:
            velocity = velocity - self.excitation_velocity
        return velocity

    @cached_property
    def forcing_gain(self) -> float | None:
        """Modal forcing gain (1/kg) of a force-driven record: stated, else estimated from its
        decay (:func:`identification.measurements.forcing.record_forcing_gain`); None otherwise."""
        if self.excitation_kind != "force":
            return None
        if self.stated_forcing_gain is not None:
            return self.stated_forcing_gain
        from identification.measurements.forcing import record_forcing_gain

        return record_forcing_gain(self).gain

    def with_forcing_gain(self, gain: float) -> ColumnRecord:
        """The same record with a stated forcing gain (1/kg)."""
        return dataclasses.replace(self, stated_forcing_gain=float(gain))

    @property
    def data(self) -> np.ndarray:
        """The samples as one array (time, response[, excitation][, frequency]), for sizes."""
        columns = [self.time_s, self.response]
        columns += [c for c in (self.excitation, self.frequency_channel) if c is not None]
        return np.column_stack(columns)

    def __repr__(self) -> str:
        return (
            f"<ColumnRecord {self.name}: {self.test}, {self.quantity} {self.response_name!r}, "
            f"{self.time_s.size} samples at {self.sampling_rate_hz:.6g} Hz>"
        )


def _frozen(values) -> np.ndarray:
    array = np.array(values, dtype=float)
    array.setflags(write=False)
    return array


def _detrended_integral(values: np.ndarray, sampling_rate_hz: float) -> np.ndarray:
    from scipy.signal import detrend

    return detrend(trapezoid_integral(values, sampling_rate_hz))


def _find(columns: Mapping[str, np.ndarray], name: str, where: Path, role: str) -> str:
    """The key of ``columns`` that ``name`` stands for (exact, path tail, or normalised)."""
    if name in columns:
        return name
    for matches in (
        [k for k in columns if k.rsplit("/", 1)[-1] == name],
        [k for k in columns if _normal(k.rsplit("/", 1)[-1]) == _normal(name)],
    ):
        if len(matches) == 1:
            return matches[0]
        if len(matches) > 1:
            raise ValueError(f"{where}: {role} {name!r} is ambiguous: {matches}")
    raise ValueError(f"{where}: no {role} column {name!r}; the file has {_listing(columns)}")


def _listing(columns: Mapping[str, np.ndarray]) -> str:
    return ", ".join(k for k, v in columns.items() if np.ndim(v) == 1) or "no columns"


def _auto(columns: Mapping[str, np.ndarray], names: Sequence[str], starts: Sequence[str],
          taken: set[str]) -> str | None:  # fmt: skip
    """The one column not yet taken whose normalised name is in ``names`` or starts with one
    of ``starts`` (None when there is none or more than one)."""
    found = []
    for key, values in columns.items():
        normal = _normal(key.rsplit("/", 1)[-1])
        if (
            np.ndim(values) == 1
            and key not in taken
            and (normal in names or any(normal.startswith(s) for s in starts))
        ):
            found.append(key)
    return found[0] if len(found) == 1 else None


def read_columns(path: str | Path, layout: ColumnLayout | None = None) -> ColumnRecord:
    """Read a column-layout file into a :class:`ColumnRecord` (see the module notes).

    Raises
    ------
    ValueError
        Naming the file: columns not found or ambiguous, a quantity or excitation
        kind neither given nor said by the column's name, and every check of
        :class:`ColumnRecord`.
    """
    path = Path(path)
    layout = layout or ColumnLayout()
    columns = read_table(path, layout.decimal_comma)
    vectors = {k: v for k, v in columns.items() if np.ndim(v) == 1}
    taken: set[str] = set()

    def role(name: str | None, what: str, names=(), starts=()) -> str | None:
        key = _find(vectors, name, path, what) if name else _auto(vectors, names, starts, taken)
        if key is not None:
            taken.add(key)
        return key

    time_key = role(layout.time, "time", ("t", "zeit"), ("time",))
    excitation_key = role(layout.excitation, "excitation")
    if excitation_key is None:  # a column whose name says it is an excitation, when only one
        said = [
            k
            for k in vectors
            if k not in taken
            and (_guess(k.rsplit("/", 1)[-1], _KIND_RULES) or _normal(k).startswith("excitation"))
        ]
        if len(said) == 1:
            excitation_key = said[0]
            taken.add(excitation_key)
    frequency_key = role(layout.frequency, "frequency", (), ("freq",))
    level_key = role(layout.level, "level", (), ("level",))
    response_key = role(layout.response, "response")
    if response_key is None:
        left = [k for k in vectors if k not in taken]
        if len(left) != 1:
            raise ValueError(
                f"{path}: which column is the response? "
                + (f"candidates: {', '.join(left)}" if left else "no column is left")
                + " (--response NAME)"
            )
        response_key = left[0]
    if time_key is not None:
        time = vectors[time_key]
    else:
        rate_key = next((k for k in columns if _normal(k.rsplit("/", 1)[-1]) in _RATE_NAMES
                         and np.ndim(columns[k]) == 0), None)  # fmt: skip
        if rate_key is None:
            raise ValueError(
                f"{path}: no time column (--time NAME) and no sampling rate (fs); "
                f"the file has {_listing(vectors)}"
            )
        time = np.arange(vectors[response_key].size) / float(columns[rate_key])
    response_name = response_key.rsplit("/", 1)[-1]
    quantity = layout.quantity or _guess(response_name, _QUANTITY_RULES)
    if quantity is None:
        raise ValueError(
            f"{path}: is the response {response_name!r} a displacement, velocity or "
            "acceleration? (--quantity)"
        )
    kind = excitation = None
    if excitation_key is not None:
        excitation_name = excitation_key.rsplit("/", 1)[-1]
        kind = layout.excitation_kind or _guess(excitation_name, _KIND_RULES)
        if kind is None:
            raise ValueError(
                f"{path}: is the excitation {excitation_name!r} a base acceleration, base "
                "velocity or force? (--excitation-kind)"
            )
        excitation = layout.excitation_gain * vectors[excitation_key]
    steps = None
    if level_key is not None:
        steps = StepSchedule(time, vectors[level_key], source=f"{path}: column {level_key!r}")
    return ColumnRecord(
        time_s=time,
        response=vectors[response_key],
        quantity=quantity,
        name=path.stem,
        test=layout.test,
        response_name=response_name,
        excitation=excitation,
        excitation_kind=kind,
        excitation_name=None if excitation_key is None else excitation_key.rsplit("/", 1)[-1],
        frequency_channel=None if frequency_key is None else vectors[frequency_key],
        steps=steps,
        relative=layout.relative,
        stated_forcing_gain=layout.forcing_gain,
        path=path,
    )


def write_columns(record: ColumnRecord, path: str | Path, level: np.ndarray | None = None) -> Path:
    """Write a record as HDF5 (``.h5``/``.hdf5``) or CSV with a header (``.csv``), atomically.

    Columns ``time``, the response (its name), the excitation (its name), ``frequency``
    and ``level`` (the step schedule sampled at the times) where the record has them;
    HDF5 datasets carry their unit and role as attributes.
    """
    from identification.artifacts import atomic_write_bytes

    path = Path(path)
    response = (record.response, UNITS[record.quantity], record.quantity)
    columns = {"time": (record.time_s, "s", "time"), record.response_name: response}
    if record.excitation is not None:
        columns[record.excitation_name or "excitation"] = (
            record.excitation, UNITS[record.excitation_kind], record.excitation_kind)  # fmt: skip
    if record.frequency_channel is not None:
        columns["frequency"] = (record.frequency_channel, "Hz", "controller frequency")
    if level is None and record.steps is not None:
        level = record.steps.level_at(record.time_s)
    if level is not None:
        columns["level"] = (np.asarray(level, dtype=float), "", "commanded level")
    suffix = path.suffix.lower()
    if suffix in HDF5_EXTENSIONS:
        import h5py

        buffer = io.BytesIO()
        with h5py.File(buffer, "w") as fh:
            for name, (values, unit, role) in columns.items():
                dataset = fh.create_dataset(name, data=values)
                dataset.attrs["unit"], dataset.attrs["role"] = unit, role
            fh.attrs["test"] = record.test
        return atomic_write_bytes(path, buffer.getvalue())
    if suffix == ".csv":
        frame = pd.DataFrame({name: values for name, (values, _, _) in columns.items()})
        return atomic_write_bytes(path, frame.to_csv(index=False, float_format="%.10g").encode())
    raise ValueError(f"{path}: write_columns writes .h5, .hdf5 or .csv")


# ---------------------------------------------------------------------------
# Campaigns


@dataclass(eq=False)
class ColumnCampaign(RecordFiles):
    """The column-layout records of a folder (or one file), read lazily one at a time.

    Files with the extensions of :data:`COLUMN_EXTENSIONS` are records, in
    natural order of their names, except backbone tables (``backbones.csv``,
    ``*_backbones.csv``).
    """

    source: Path
    layout: ColumnLayout = field(default_factory=ColumnLayout)
    paths: tuple[Path, ...] = ()

    def __post_init__(self) -> None:
        from identification.measurements.records import _natural_key

        self.source = Path(self.source)
        if self.source.is_file():
            paths = [self.source]
        elif self.source.is_dir():
            paths = [p for p in self.source.iterdir() if is_column_file(p)]
        else:
            raise ValueError(f"{self.source}: campaign folder not found")
        if not paths:
            raise ValueError(
                f"{self.source}: no TRC data files (ConfigN_PRT_AssembA[_R]) and no "
                f"column-layout files ({', '.join(COLUMN_EXTENSIONS)})"
            )
        paths.sort(key=lambda p: _natural_key(p.name))
        stems = [p.stem for p in paths]
        twice = sorted({s for s in stems if stems.count(s) > 1})
        if twice:
            raise ValueError(f"{self.source}: two files for record(s) {twice}; keep one of each")
        self.paths = tuple(paths)

    @property
    def names(self) -> list[str]:
        return [p.stem for p in self.paths]

    @property
    def folder(self) -> Path:
        return self.source

    def _read(self, index: int) -> ColumnRecord:
        return read_columns(self.paths[index], self.layout)

    def __repr__(self) -> str:
        return f"<ColumnCampaign {self.source}: {len(self)} records>"


def is_column_file(path: Path) -> bool:
    """Whether ``path`` is a column-layout record file (not a backbone table)."""
    name = path.name.lower()
    return (
        path.is_file()
        and path.suffix.lower() in COLUMN_EXTENSIONS
        and not (name == "backbones.csv" or name.endswith("_backbones.csv"))
    )


def is_backbone_table(path: Path) -> bool:
    """Whether ``path`` is a backbone table (a CSV with ``curve`` and ``amplitude_mm`` columns)."""
    if not (path.is_file() and path.suffix.lower() == ".csv"):
        return False
    with open(path, encoding="utf-8", errors="replace") as fh:
        header = {_normal(c) for c in fh.readline().strip().split(",")}
    return {"curve", "amplitude_mm"} <= header


def open_records(
    source: str | Path, layout: ColumnLayout | None = None
) -> Campaign | ColumnCampaign:
    """The records of a folder or file, whatever their layout.

    A folder with TRC data files, or one TRC data file, is a TRC
    :class:`~identification.measurements.records.Campaign` (of the layout's test
    type); any other folder or file is a :class:`ColumnCampaign` read with
    ``layout``.
    """
    source = Path(source)
    layout = layout or ColumnLayout()
    if is_trc_source(source):
        return Campaign(source, test=layout.test)
    return ColumnCampaign(source, layout)
