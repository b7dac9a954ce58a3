"""Backbones per mode from multi-point phase-resonance records (PLL holds).

A record's sensors (:attr:`sensor_responses`: the TRC layout's 15 panel points,
or the ``--response a,b,c`` columns of a column file) go through the modal
filter of its mode shapes (:mod:`identification.measurements.modal_filter`):
each mode's coordinate, scaled to its reference sensor (the sensor where its
shape is largest), is a signal of its own, and every hold is read on it as the
one-mode path reads the record's response
(:func:`~identification.measurements.extraction.hold_points`, the same window,
fit, conversions and checks):

* the **locked mode** (the mode whose coordinate carries the most energy over
  the record's holds: the PLL holds its phase resonance) gives the backbone
  point: its amplitude, the hold's frequency and the damping ratio from the power
  balance of that mode (the one-mode path's, on its coordinate: the reference
  sensor's response of a mode whose base participation there is 1);
* every mode gives its **participation** at every hold: the amplitude (m) of
  harmonics k = 1–3 of its scaled coordinate's displacement, their phase against
  k × the locked mode's fundamental (deg; harmonic k of mode m is
  ``|P| cos(kθ + φ)``, reported ``φ − k φ_locked,1``, the convention of
  :attr:`identification.multimode.pll.ModalPLLResult.participation_phase_deg`),
  and its energy share (:mod:`~identification.measurements.modal_filter`).

Shapes come from ``--mode-shapes FILE``, else the record's modes file (TRC), else
they are estimated from the record
(:func:`~identification.measurements.modal_filter.estimate_shapes`);
:class:`ModalCurve` says which, with the error of making complex shapes real and
the filter's reconstruction error per sensor.

The table (:meth:`ModalBackboneSet.to_table`) is the one-mode backbone table
(:data:`~identification.measurements.backbone.TABLE_COLUMNS`) with an integer
``mode`` column (1, 2, … in order of linear frequency) and a ``hold`` column
(1, 2, … within the curve) after ``curve``, one row per hold and mode, and per
mode ``mode{m}_h{k}_amplitude_mm``, ``mode{m}_h{k}_phase_deg`` (k = 1–3) and
``mode{m}_energy_share`` of the hold on every row of it. The locked mode's rows
carry its frequency, damping ratio and phase error; the other modes' rows carry
their amplitude and participation only (frequency, damping, phase error and the
own-frame harmonics empty). Which sensor each mode's amplitude is at, and
where the shapes came from, are in the sidecar JSON (:meth:`ModalBackboneSet.sidecar`).
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from identification.artifacts import atomic_write_text
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import hold_point, hold_points, record_holds
from identification.measurements.modal_filter import (
    SECOND_MODE_SHARE,
    ModalFilter,
    estimate_shapes,
    second_mode_warning,
)
from identification.measurements.modes import Modes
from identification.measurements.quantities import mean_offsets

__all__ = [
    "PARTICIPATION_ORDERS",
    "ModalBackboneSet",
    "ModalCurve",
    "ModalHold",
    "extract_modal_backbones",
    "modal_curve",
    "mode_backbones",
    "record_modal_filter",
    "second_mode_warnings",
    "sidecar_path",
]

#: Harmonic orders of every mode's participation.
PARTICIPATION_ORDERS = (1, 2, 3)
#: Columns of the one-mode table that a mode's row carries only where the mode was locked.
_LOCKED_ONLY = ("frequency_hz", "damping_ratio", "phase_error_deg")


@dataclass(frozen=True)
class ModalHold:
    """What one hold says about every mode.

    Attributes
    ----------
    participation
        ``(N, 3)`` complex displacement amplitudes (m) of harmonics 1–3 of every
        mode's scaled coordinate, turned by ``−k × arg`` of the locked mode's
        fundamental (see the module notes).
    energy_share
        ``(N,)`` every mode's share of the hold's energy.
    """

    participation: np.ndarray
    energy_share: np.ndarray


@dataclass(frozen=True, eq=False)
class ModalCurve:
    """One record read mode by mode.

    Attributes
    ----------
    label, source
        The record's name and file.
    modal_filter
        The shapes it was read with (their source, alignment error, reference sensors).
    locked_mode
        The mode the PLL held (from 1).
    backbones
        ``N`` curves, one per mode, a point per hold: the locked mode's is its
        backbone; the others' frequencies and damping are those of the hold read
        on their coordinate, not their own (left out of the table).
    holds
        Every hold's participation and energy shares.
    reconstruction_error
        ``(S,)`` what the modes leave unexplained at each sensor over the record
        (:meth:`~identification.measurements.modal_filter.ModalFilter.reconstruction_error`).
    """

    label: str
    source: str
    modal_filter: ModalFilter
    locked_mode: int
    backbones: tuple[Backbone, ...]
    holds: tuple[ModalHold, ...]
    reconstruction_error: np.ndarray

    @property
    def backbone(self) -> Backbone:
        """The locked mode's backbone."""
        return self.backbones[self.locked_mode - 1]

    def largest_other_share(self) -> tuple[int, float]:
        """The mode (from 1) other than the locked one with the largest energy share at any
        hold, and that share."""
        shares = np.array([h.energy_share for h in self.holds])
        shares[:, self.locked_mode - 1] = -np.inf
        hold, mode = np.unravel_index(np.argmax(shares), shares.shape)
        return int(mode) + 1, float(shares[hold, mode])


class _ModeSignal:
    """A record seen through one mode: its response is that mode's scaled coordinate."""

    relative = True

    def __init__(self, record: Any, response: np.ndarray, quantity: str) -> None:
        self._record = record
        self.response = response
        self.quantity = quantity

    def __getattr__(self, name: str) -> Any:
        return getattr(self._record, name)


def _sensor_signals(record: Any) -> tuple[np.ndarray, str]:
    """``(n, S)`` sensor responses relative to the base, and their quantity.

    As measured where they are relative already (or nothing moves the base); an
    absolute response of a base-driven column record is turned into the relative
    velocity as its one-mode response is (:attr:`ColumnRecord.sensor_velocity`).
    """
    if getattr(record, "base_driven", False) and not record.relative:
        return record.sensor_velocity, "velocity"
    return record.sensor_responses, record.quantity


def record_modal_filter(record: Any, n_modes: int, mode_shapes: Modes | None = None) -> ModalFilter:
    """The modal filter of ``n_modes`` modes for a record's sensors.

    Shapes from ``mode_shapes`` (a ``--mode-shapes`` file, one row per sensor),
    else the record's modes file (TRC), else estimated from the record (also
    where the modes file has fewer modes than asked for, which the source says).
    """
    names = record.sensor_names
    where = record.path or record.name
    given = mode_shapes if mode_shapes is not None else getattr(record, "modes", None)
    note = ""
    if given is not None and given.shapes.shape[0] != len(names):
        raise ValueError(
            f"{where}: the mode shapes {given.source} have {given.shapes.shape[0]} row(s), the "
            f"record {len(names)} sensor(s) ({', '.join(names)})"
        )
    if given is not None and given.shapes.shape[1] >= n_modes:
        source = given.source or "given"
        return ModalFilter.from_complex(
            given.shapes, given.frequencies_hz, names, source=source, n_modes=n_modes
        )
    if given is not None:
        note = f" (the modes file {given.source} has {given.shapes.shape[1]} mode(s))"
    signals, _ = _sensor_signals(record)
    try:
        estimated = estimate_shapes(record.time_s, signals, n_modes, names)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    return ModalFilter(
        estimated.shapes, estimated.frequencies_hz, names, estimated.source + note,
        estimated.alignment_error,
    )  # fmt: skip


def modal_curve(
    record: Any,
    modal_filter: ModalFilter,
    n_periods: int = 70,
    harmonics: int = 3,
    strict: bool = True,
) -> ModalCurve:
    """A driven record's holds read mode by mode (see the module notes).

    Raises
    ------
    ValueError
        As :func:`~identification.measurements.extraction.hold_points` on the locked
        mode's coordinate (naming the record and hold), and for a free decay (read
        per mode by the decay readers).
    """
    where = record.path or record.name
    if record.test == "free-decay":
        raise ValueError(f"{where}: a free decay is not read by the PLL holds' modal reader")
    signals, quantity = _sensor_signals(record)
    scaled = modal_filter.scaled_coordinates(signals)
    holds = record_holds(record)
    inside = np.zeros(record.time_s.size, dtype=bool)
    for hold in holds:
        inside |= (record.time_s >= hold.start_s) & (record.time_s <= hold.end_s)
    locked = int(np.argmax(np.mean(scaled[inside] ** 2, axis=0)))
    gain = record.forcing_gain if record.excitation_kind == "force" else 1.0
    views = [_ModeSignal(record, scaled[:, m], quantity) for m in range(modal_filter.n_modes)]
    points, holds = hold_points(views[locked], n_periods, harmonics, strict, forcing_gain=gain)
    options = dict(
        excitation_kind=record.excitation_kind, response_quantity=quantity, relative=True,
        forcing_gain=gain, test=record.test,
    )  # fmt: skip
    per_mode = []
    for m in range(modal_filter.n_modes):
        if m == locked:
            per_mode.append(points)
            continue
        mode_points = []
        for hold, own in zip(holds, points, strict=True):
            t = record.time_s
            rows = slice(
                np.searchsorted(t, hold.start_s, "left"), np.searchsorted(t, hold.end_s, "right")
            )
            mode_points.append(
                hold_point(
                    record.time_s[rows], record.excitation[rows], scaled[rows, m],
                    record.frequency_hz[rows], n_periods=own.periods, harmonics=harmonics,
                    **options,
                )
            )  # fmt: skip
        per_mode.append(mode_points)
    omega_modes = 2 * np.pi * modal_filter.frequencies_hz
    modal_holds = tuple(
        _modal_hold([mode[j] for mode in per_mode], locked, omega_modes) for j in range(len(holds))
    )
    levels = [h.level for h in holds]
    backbones = tuple(
        _backbone(record, mode_points, levels, harmonics > 1) for mode_points in per_mode
    )
    curve = ModalCurve(
        label=record.name, source=str(where), modal_filter=modal_filter, locked_mode=locked + 1,
        backbones=backbones, holds=modal_holds,
        reconstruction_error=modal_filter.reconstruction_error(signals),
    )  # fmt: skip
    fundamental = np.array([[abs(p[0]) ** 2 for p in h.participation] for h in modal_holds])
    moved = np.flatnonzero(np.argmax(fundamental, axis=1) != locked)
    if moved.size:
        warnings.warn(
            f"{where}: at {moved.size} of {len(holds)} hold(s) another mode's fundamental is "
            f"larger than that of mode {locked + 1}, read as the locked mode of every hold",
            stacklevel=2,
        )
    return curve


def _modal_hold(points: Sequence, locked: int, omega_modes: np.ndarray) -> ModalHold:
    """Participation and energy shares of one hold from every mode's point (module notes)."""
    from identification.multimode.solve import energy_shares

    n_orders = len(PARTICIPATION_ORDERS)
    participation = np.zeros((len(points), n_orders), dtype=complex)
    for m, point in enumerate(points):
        # the fundamental's phase against the excitation's, the harmonics in its frame
        angle = math.radians(point.phase_error_deg - 180.0)
        own = np.concatenate(([1.0], point.harmonics))[:n_orders]
        k = np.arange(1, own.size + 1)
        participation[m, : own.size] = point.amplitude_m * own * np.exp(1j * k * angle)
    k = np.array(PARTICIPATION_ORDERS)
    reference = np.angle(participation[locked, 0])
    participation *= np.exp(-1j * k * reference)
    coefficients = np.zeros((len(points), 1 + 2 * n_orders))
    coefficients[:, 1::2] = participation.real
    coefficients[:, 2::2] = -participation.imag
    omega = 2 * np.pi * points[locked].frequency_hz
    return ModalHold(participation, energy_shares(coefficients, np.array(omega), omega_modes))


def _backbone(record: Any, points: Sequence, levels: Sequence[float], higher: bool) -> Backbone:
    """One mode's curve of hold points, as the one-mode path builds a record's."""
    amplitude = np.array([p.amplitude_m for p in points])
    return Backbone(
        amplitude_m=amplitude,
        frequency_hz=[p.frequency_hz for p in points],
        damping_ratio=[p.damping_ratio for p in points],
        excitation_level=None if np.isnan(levels).any() else levels,
        phase_error_deg=[p.phase_error_deg for p in points],
        label=record.name,
        source=str(record.path or record.name),
        harmonics=[p.harmonics for p in points] if higher else None,
        harmonic_standard_error=[p.harmonic_standard_error for p in points] if higher else None,
        excitation_harmonics=[p.excitation_harmonics for p in points] if higher else None,
        mean_offset_m=mean_offsets(amplitude, [p.mean_offset_m for p in points]),
        time_s=[p.time_s - record.time_s[0] for p in points],
        settled=[p.settled for p in points],
        dropped_samples=[p.dropped_samples for p in points],
    )


class ModalBackboneSet(Sequence[ModalCurve]):
    """The records of a campaign read mode by mode (one :class:`ModalCurve` each)."""

    def __init__(self, curves: Iterable[ModalCurve], n_modes: int) -> None:
        self._curves = tuple(curves)
        self.n_modes = int(n_modes)
        labels = [c.label for c in self._curves]
        twice = sorted({x for x in labels if labels.count(x) > 1})
        if twice:
            raise ValueError(f"ModalBackboneSet: duplicated curve labels {twice}")
        for curve in self._curves:
            if curve.modal_filter.n_modes != self.n_modes:
                raise ValueError(
                    f"{curve.label}: read with {curve.modal_filter.n_modes} modes, not {n_modes}"
                )

    def __len__(self) -> int:
        return len(self._curves)

    def __getitem__(self, index):
        return self._curves[index]

    def __iter__(self) -> Iterator[ModalCurve]:
        return iter(self._curves)

    def mode_backbones(self, mode: int) -> BackboneSet:
        """The backbones of ``mode`` (from 1): the curves of the records that locked it."""
        return BackboneSet(c.backbone for c in self._curves if c.locked_mode == mode)

    def to_table(self) -> pd.DataFrame:
        """One row per hold and mode (see the module notes)."""
        frames = []
        orders = PARTICIPATION_ORDERS
        for curve in self._curves:
            n_holds = len(curve.holds)
            extra: dict[str, Any] = {}
            participation = np.array([h.participation for h in curve.holds])  # (holds, N, K)
            shares = np.array([h.energy_share for h in curve.holds])
            for m in range(self.n_modes):
                for i, k in enumerate(orders):
                    extra[f"mode{m + 1}_h{k}_amplitude_mm"] = 1e3 * np.abs(participation[:, m, i])
                    extra[f"mode{m + 1}_h{k}_phase_deg"] = np.degrees(
                        np.angle(participation[:, m, i])
                    )
                extra[f"mode{m + 1}_energy_share"] = shares[:, m]
            for m, backbone in enumerate(curve.backbones):
                table = BackboneSet([backbone]).to_table()
                if m + 1 != curve.locked_mode:
                    own = [c for c in table.columns if c.startswith("harmonic")]
                    table[[*_LOCKED_ONLY, *own]] = np.nan
                table.insert(1, "mode", m + 1)
                table.insert(2, "hold", np.arange(1, n_holds + 1))
                for name, values in extra.items():
                    table[name] = values
                frames.append(table)
        if not frames:
            return pd.DataFrame(columns=["curve", "mode", "hold"])
        table = pd.concat(frames, ignore_index=True)
        # Rows of one hold together, modes in order.
        order = {c.label: i for i, c in enumerate(self._curves)}
        table["_curve"] = table["curve"].map(order)
        table = table.sort_values(["_curve", "hold", "mode"], kind="stable")
        return table.drop(columns="_curve").reset_index(drop=True)

    def sidecar(self) -> dict[str, Any]:
        """What the table's header cannot say: per curve, the shapes' source, the reference
        sensor of each mode, the alignment error and the reconstruction error per sensor."""
        curves = []
        for c in self._curves:
            f = c.modal_filter
            curves.append(
                {
                    "curve": c.label,
                    "source": c.source,
                    "locked_mode": c.locked_mode,
                    "shapes_source": f.source,
                    "linear_frequencies_hz": f.frequencies_hz.tolist(),
                    "reference_sensor": [f.sensor_names[s] for s in f.reference_sensor],
                    "alignment_error": f.alignment_error.tolist(),
                    "reconstruction_error": dict(
                        zip(f.sensor_names, c.reconstruction_error.tolist(), strict=True)
                    ),
                }
            )
        return {
            "format": "pm-joint/modal-backbones",
            "version": 1,
            "modes": self.n_modes,
            "amplitude": "each mode's amplitude_mm is its modal amplitude at its reference sensor",
            "curves": curves,
        }

    def to_csv(self, path: str | Path) -> Path:
        """Write the table as CSV and the sidecar JSON beside it (:func:`sidecar_path`)."""
        path = Path(path)
        atomic_write_text(sidecar_path(path), json.dumps(self.sidecar(), indent=1) + "\n")
        return atomic_write_text(path, self.to_table().to_csv(index=False))


def sidecar_path(csv: str | Path) -> Path:
    """The sidecar JSON of a modal backbone table: ``backbones.csv`` → ``backbones_modes.json``."""
    csv = Path(csv)
    return csv.with_name(f"{csv.stem}_modes.json")


def mode_backbones(table: pd.DataFrame, mode: int, source: str = "table") -> BackboneSet:
    """The locked rows of ``mode`` (from 1) of a modal backbone table, as one-mode backbones."""
    rows = table[(table["mode"] == mode) & table["frequency_hz"].notna()]
    return BackboneSet.from_table(rows.drop(columns=["mode", "hold"]), source=source)


def extract_modal_backbones(
    records: Iterable[Any],
    n_modes: int,
    *,
    mode_shapes: Modes | None = None,
    n_periods: int = 70,
    harmonics: int = 3,
    strict: bool = True,
) -> ModalBackboneSet:
    """Every record read mode by mode (:func:`record_modal_filter`, :func:`modal_curve`)."""
    if not isinstance(n_modes, int) or n_modes < 2:
        raise ValueError(
            f"n_modes must be an integer ≥ 2 (one mode is the one-mode path): {n_modes}"
        )
    curves = []
    for record in records:
        modal_filter = record_modal_filter(record, n_modes, mode_shapes)
        curves.append(modal_curve(record, modal_filter, n_periods, harmonics, strict))
    return ModalBackboneSet(curves, n_modes)


def second_mode_warnings(
    records: Iterable[Any],
    *,
    mode_shapes: Modes | None = None,
    n_periods: int = 70,
    threshold: float = SECOND_MODE_SHARE,
) -> list[str]:
    """The warnings of a one-mode reading of driven records whose given shapes show another
    mode above ``threshold`` of the energy (:func:`~identification.measurements.modal_filter.
    second_mode_warning`), one line per record.

    Only records with at least two sensors and two given shapes (a modes file, or
    ``mode_shapes``) are looked at: without shapes a one-mode reading estimates none.
    """
    lines = []
    for record in records:
        given = mode_shapes if mode_shapes is not None else getattr(record, "modes", None)
        n_sensors = len(record.sensor_names)
        if record.test == "free-decay" or given is None or n_sensors < 2:
            continue
        n_modes = min(given.shapes.shape[1], n_sensors)
        if n_modes < 2:
            continue
        modal_filter = record_modal_filter(record, n_modes, given)
        with warnings.catch_warnings():  # the one-mode reading said what its holds say
            warnings.simplefilter("ignore")
            curve = modal_curve(record, modal_filter, n_periods, strict=False)
        mode, share = curve.largest_other_share()
        line = second_mode_warning(
            str(record.path or record.name), modal_filter.frequencies_hz[mode - 1], share, threshold
        )
        if line is not None:
            lines.append(line)
    return lines
