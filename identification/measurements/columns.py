"""Test records in a column layout: CSV/TSV with a header, MAT (v5 and v7.3) and HDF5 files.

Labs keep a test as a few named signals: the time, a response (a displacement,
velocity or acceleration of one sensor), perhaps the excitation (a base
acceleration or velocity, or a force), perhaps the controller's frequency
channel and the commanded level. :class:`ColumnLayout` says which column is
which and what the test was; :func:`read_columns` reads one file into a
:class:`ColumnRecord`, which offers what the TRC records
(:class:`~identification.measurements.records.Record`) offer, so that the
backbones and the identification take either.

Formats: CSV/TSV/text with a header (through the text-table reader the TRC
files share), MAT v5 and v7.3, and HDF5; see
:mod:`identification.measurements.column_formats`.

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

from identification.measurements.column_formats import (
    COLUMN_EXTENSIONS,
    HDF5_EXTENSIONS,
    read_table,
)
from identification.measurements.discovery import Campaign, RecordFiles, is_trc_source, natural_key
from identification.measurements.quantities import (
    BASE_KINDS,
    EXCITATION_KINDS,
    QUANTITIES,
    TEST_TYPES,
    UNITS,
    check_choice,
)
from identification.measurements.series import frozen_array, regular_time
from identification.measurements.signals import central_difference, trapezoid_integral
from identification.measurements.steps import StepSchedule
from identification.measurements.trc_layout import config_files

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

_RATE_NAMES = ("fs", "sampling_rate", "sample_rate", "sampling_rate_hz", "samplingrate")


def _normal(name: str) -> str:
    """A column name without case, blanks or a unit in brackets: ``Time [s]`` → ``time``."""
    name = re.sub(r"[\[(].*?[\])]", "", str(name)).strip().lower()
    return re.sub(r"[\s.\-]+", "_", name).strip("_")


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
        Response column; default the one column no other role takes. Several,
        comma-separated (``a,b,c``), are the sensors of a multi-point record: the
        first is the response of a one-mode reading, all of them go into the
        modal filter of a reading of several modes
        (:mod:`identification.measurements.modal_filter`).
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
        Sample times (s), strictly increasing and uniformly sampled; time stamps
        rounded when written are replaced by the uniform grid of their mean rate
        (:func:`~identification.measurements.series.regular_time`).
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
    extra_responses, extra_response_names
        The other sensors' responses (same quantity and reference as ``response``)
        and their column names, for several modes; empty for one sensor.
    time_jitter
        Largest step deviation of the time stamps from their mean step (fraction
        of it) where they were replaced by the uniform grid, else 0.

    Raises
    ------
    ValueError
        Arrays of different lengths, non-finite samples, time that is not
        strictly increasing, or not uniform beyond what rounded stamps explain
        (a gap, a jump, a change of rate), and the records that cannot be
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
    extra_responses: tuple[np.ndarray, ...] = ()
    extra_response_names: tuple[str, ...] = ()
    time_jitter: float = field(default=0.0, init=False)

    def __post_init__(self) -> None:
        where = self.path or self.name
        check_choice("test", self.test, TEST_TYPES)
        check_choice("quantity", self.quantity, QUANTITIES)
        time = frozen_array(self.time_s)
        arrays = {"time": time, self.response_name: frozen_array(self.response)}
        if self.excitation is not None:
            check_choice("excitation kind", self.excitation_kind or "", EXCITATION_KINDS)
            arrays[self.excitation_name or "excitation"] = frozen_array(self.excitation)
        if self.frequency_channel is not None:
            arrays["frequency"] = frozen_array(self.frequency_channel)
        extra_names = tuple(self.extra_response_names)
        if len(extra_names) != len(self.extra_responses):
            raise ValueError(f"{where}: one name per extra response, got {extra_names}")
        for name, values in zip(extra_names, self.extra_responses, strict=True):
            arrays[name] = frozen_array(values)
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
        regular = regular_time(time, where)
        object.__setattr__(self, "time_s", regular.time_s)
        object.__setattr__(self, "time_jitter", regular.jitter)
        object.__setattr__(self, "response", arrays[self.response_name])
        if self.excitation is not None:
            object.__setattr__(self, "excitation", arrays[self.excitation_name or "excitation"])
        if self.frequency_channel is not None:
            object.__setattr__(self, "frequency_channel", arrays["frequency"])
        object.__setattr__(self, "extra_responses", tuple(arrays[n] for n in extra_names))
        object.__setattr__(self, "extra_response_names", extra_names)
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
        return self._relative_velocity(self.response)

    def _relative_velocity(self, response: np.ndarray) -> np.ndarray:
        rate = self.sampling_rate_hz
        if self.quantity == "displacement":
            velocity = central_difference(response, rate)
        elif self.quantity == "acceleration":
            velocity = _detrended_integral(response, rate)
        else:
            velocity = response
        if self.base_driven and not self.relative:
            velocity = velocity - self.excitation_velocity
        return velocity

    @property
    def sensor_names(self) -> tuple[str, ...]:
        """Names of the response columns: the response's, then the other sensors'."""
        return (self.response_name, *self.extra_response_names)

    @property
    def sensor_responses(self) -> np.ndarray:
        """``(n, S)`` every sensor's response as measured (first column: :attr:`response`)."""
        return np.column_stack([self.response, *self.extra_responses])

    @cached_property
    def sensor_velocity(self) -> np.ndarray:
        """``(n, S)`` every sensor's velocity relative to the base, as :attr:`response_velocity`."""
        return np.column_stack([self._relative_velocity(r) for r in self.sensor_responses.T])

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
        columns = [self.time_s, self.response, *self.extra_responses]
        columns += [c for c in (self.excitation, self.frequency_channel) if c is not None]
        return np.column_stack(columns)

    def __repr__(self) -> str:
        return (
            f"<ColumnRecord {self.name}: {self.test}, {self.quantity} {self.response_name!r}, "
            f"{self.time_s.size} samples at {self.sampling_rate_hz:.6g} Hz>"
        )


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

    Warns
    -----
    UserWarning
        One line when the time stamps were rounded when written: the record is
        read on the uniform grid of their mean rate.
    """
    record = _read_columns(path, layout)
    if record.time_jitter:
        warnings.warn(_rounded_stamps(record), stacklevel=2)
    return record


def _rounded_stamps(record: ColumnRecord) -> str:
    """The one line that says a record's rounded time stamps were put on a uniform grid."""
    return (
        f"{record.path or record.name}: time stamps jitter by up to "
        f"{100 * record.time_jitter:.2g} % of a step (rounded when written?); read on the "
        f"uniform grid of their mean rate, {record.sampling_rate_hz:.7g} Hz"
    )


def _table(path: Path, decimal_comma: bool | None) -> dict[str, np.ndarray]:
    """:func:`read_table`, with a file its format's library cannot open (a truncated MAT
    file, an HDF5 file without its signature) refused as bad input naming the file."""
    from scipy.io.matlab import MatReadError

    try:
        return read_table(path, decimal_comma)
    except (OSError, MatReadError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"{path}: not readable as a {path.suffix} file ({reason})") from None


def _read_columns(path: str | Path, layout: ColumnLayout | None) -> ColumnRecord:
    path = Path(path)
    layout = layout or ColumnLayout()
    columns = _table(path, layout.decimal_comma)
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
    named = [n.strip() for n in (layout.response or "").split(",") if n.strip()]
    response_key = role(named[0] if named else None, "response")
    extra_keys = [role(name, "response") for name in named[1:]]
    sensors = [response_key, *extra_keys]
    twice = sorted({k for k in sensors if sensors.count(k) > 1})
    if twice:
        raise ValueError(f"{path}: response column(s) {twice} named twice in --response")
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
        extra_responses=tuple(vectors[k] for k in extra_keys),
        extra_response_names=tuple(k.rsplit("/", 1)[-1] for k in extra_keys),
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
    for name, values in zip(record.extra_response_names, record.extra_responses, strict=True):
        columns[name] = (values, UNITS[record.quantity], record.quantity)
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
    ``*_backbones.csv``). Time stamps rounded when written are said once for
    the campaign, at the first record that has them.
    """

    source: Path
    layout: ColumnLayout = field(default_factory=ColumnLayout)
    paths: tuple[Path, ...] = ()
    #: Whether a record's rounded time stamps were announced: once per campaign.
    _told_rounding: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
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
        paths.sort(key=lambda p: natural_key(p.name))
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
        record = _read_columns(self.paths[index], self.layout)
        if record.time_jitter and not self._told_rounding:
            self._told_rounding = True
            once = "" if self.source.is_file() else f"; said once for the records of {self.source}"
            warnings.warn(_rounded_stamps(record) + once, stacklevel=3)
        return record

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
    ``layout``: one record per file, each file one assembly, labelled by its
    file name without the extension.

    Raises
    ------
    ValueError
        A folder that holds both TRC data files and column-layout files (which
        are the campaign is not for the reader to guess), and every error of the
        two campaigns (no record file, two files of one record).
    """
    source = Path(source)
    layout = layout or ColumnLayout()
    if is_trc_source(source):
        if source.is_dir():
            _refuse_mixed(source)
        return Campaign(source, test=layout.test, decimal_comma=layout.decimal_comma)
    return ColumnCampaign(source, layout)


def _refuse_mixed(folder: Path) -> None:
    """ValueError when a TRC folder also holds column-layout record files (its own step and
    modes files, in any extension, are not such files)."""
    trc_files = {p for files in config_files(folder).values() for p in files.values()}
    foreign = sorted(
        (p.name for p in folder.iterdir()
         if is_column_file(p) and p not in trc_files and not is_trc_source(p)),
        key=natural_key,
    )  # fmt: skip
    if foreign:
        more = len(foreign) - 3
        shown = ", ".join(foreign[:3]) + (f" and {more} more" if more > 0 else "")
        raise ValueError(
            f"{folder}: mixed folder: TRC data files (ConfigN_PRT_AssembA[_R]) and column-layout "
            f"files ({shown}); a campaign is one or the other: move one kind to its own folder"
        )
