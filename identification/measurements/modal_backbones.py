"""Backbones per mode from multi-point phase-resonance records (PLL holds).

A record's sensors (:attr:`sensor_responses`: the TRC layout's 15 panel points,
or the ``--response a,b,c`` columns of a column file) go through the modal
filter of its mode shapes (:mod:`identification.measurements.modal_filter`):
each mode's coordinate, scaled to its reference sensor (the sensor where its
shape is largest), is a signal of its own, and every hold is read on it as the
one-mode path reads the record's response
(:func:`~identification.measurements.extraction.extract_backbone`, the same window,
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
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from identification.artifacts import atomic_write_text
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import extract_backbone, hold_point, record_holds
from identification.measurements.hold_fit import ShortHoldError
from identification.measurements.modal_filter import (
    SECOND_MODE_SHARE,
    ModalFilter,
    estimate_shapes,
    second_mode_warning,
)
from identification.measurements.modes import Modes

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
    "sensor_signals",
    "sidecar_path",
]

#: Harmonic orders of every mode's participation.
PARTICIPATION_ORDERS = (1, 2, 3)
#: Columns of the one-mode table that a mode's row carries only where the mode was locked.
_LOCKED_ONLY = ("frequency_hz", "damping_ratio", "phase_error_deg", "mean_offset_mm")


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
    backbone
        The locked mode's backbone, a point per hold.
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
    backbone: Backbone
    holds: tuple[ModalHold, ...]
    reconstruction_error: np.ndarray

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


def sensor_signals(record: Any) -> tuple[np.ndarray, str]:
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
    signals, _ = sensor_signals(record)
    try:
        estimated = estimate_shapes(record.time_s, signals, n_modes, names)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    return ModalFilter(
        estimated.shapes, estimated.frequencies_hz, names, estimated.source + note,
        estimated.alignment_error,
    )  # fmt: skip


class _Reading(NamedTuple):
    """What a hold fit says of one mode's coordinate: the fundamental's amplitude (m) and
    phase error (deg, against the excitation), the harmonics ``2..`` in its own frame."""

    amplitude_m: float
    phase_error_deg: float
    harmonics: np.ndarray


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
        As :func:`~identification.measurements.extraction.extract_backbone` on the
        locked mode's coordinate (naming the record and hold), and for a free decay
        (read per mode by the decay readers).
    """
    where = record.path or record.name
    if record.test == "free-decay":
        raise ValueError(f"{where}: a free decay is not read by the PLL holds' modal reader")
    signals, quantity = sensor_signals(record)
    scaled = modal_filter.scaled_coordinates(signals)
    holds = record_holds(record)
    t = record.time_s
    spans = [slice(np.searchsorted(t, h.start_s, "left"), np.searchsorted(t, h.end_s, "right"))
             for h in holds]  # fmt: skip
    energy = sum(np.sum(scaled[rows] ** 2, axis=0) for rows in spans)
    locked = int(np.argmax(energy))
    backbone = extract_backbone(
        _ModeSignal(record, scaled[:, locked], quantity), n_periods, harmonics, strict
    )
    own = np.zeros((len(backbone), 0)) if backbone.harmonics is None else backbone.harmonics
    readings = [[_Reading(a, e, h) for a, e, h in zip(backbone.amplitude_m,
                 backbone.phase_error_deg, own, strict=True)]]  # fmt: skip
    gain = record.forcing_gain if record.excitation_kind == "force" else 1.0
    options = dict(
        harmonics=harmonics, excitation_kind=record.excitation_kind, response_quantity=quantity,
        relative=True, forcing_gain=gain, test=record.test,
    )  # fmt: skip
    others = [m for m in range(modal_filter.n_modes) if m != locked]
    for m in others:
        mode_readings = []
        for rows in spans:
            args = (t[rows], record.excitation[rows], scaled[rows, m], record.frequency_hz[rows])
            try:
                point = hold_point(*args, n_periods=n_periods, **options)
            except ShortHoldError as exc:  # the locked mode's reading said so, or refused
                point = hold_point(*args, n_periods=int(exc.periods), **options)
            mode_readings.append(
                _Reading(point.amplitude_m, point.phase_error_deg, point.harmonics)
            )
        readings.append(mode_readings)
    order = np.argsort([locked, *others])
    omega_modes = 2 * np.pi * modal_filter.frequencies_hz
    modal_holds = tuple(
        _modal_hold([readings[i][j] for i in order], locked, omega_modes, backbone.frequency_hz[j])
        for j in range(len(holds))
    )
    fundamental = np.array([np.abs(h.participation[:, 0]) for h in modal_holds])
    moved = np.flatnonzero(np.argmax(fundamental, axis=1) != locked)
    if moved.size:
        warnings.warn(
            f"{where}: at {moved.size} of {len(holds)} hold(s) another mode's fundamental is "
            f"larger than that of mode {locked + 1}, read as the locked mode of every hold",
            stacklevel=2,
        )
    return ModalCurve(
        label=record.name, source=str(where), modal_filter=modal_filter, locked_mode=locked + 1,
        backbone=backbone, holds=modal_holds,
        reconstruction_error=modal_filter.reconstruction_error(signals),
    )  # fmt: skip


def _modal_hold(
    readings: Sequence[_Reading], locked: int, omega_modes: np.ndarray, frequency_hz: float
) -> ModalHold:
    """Participation and energy shares of one hold from every mode's reading (module notes)."""
    from identification.multimode.solve import energy_shares

    n_orders = len(PARTICIPATION_ORDERS)
    participation = np.zeros((len(readings), n_orders), dtype=complex)
    for m, reading in enumerate(readings):
        # the fundamental's phase against the excitation's, the harmonics in its frame
        angle = math.radians(reading.phase_error_deg - 180.0)
        own = np.concatenate(([1.0], reading.harmonics))[:n_orders]
        k = np.arange(1, own.size + 1)
        participation[m, : own.size] = reading.amplitude_m * own * np.exp(1j * k * angle)
    k = np.array(PARTICIPATION_ORDERS)
    participation *= np.exp(-1j * k * np.angle(participation[locked, 0]))
    coefficients = np.zeros((len(readings), 1 + 2 * n_orders))
    coefficients[:, 1::2] = participation.real
    coefficients[:, 2::2] = -participation.imag
    omega = np.array(2 * np.pi * frequency_hz)
    return ModalHold(participation, energy_shares(coefficients, omega, omega_modes))


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
            locked = BackboneSet([curve.backbone]).to_table()
            own = [c for c in locked.columns if c.startswith("harmonic")]
            for m in range(self.n_modes):
                table = locked.copy()
                if m + 1 != curve.locked_mode:
                    # the hold's window and excitation; the fit's own figures are the locked
                    # mode's, so this mode's row keeps only its amplitude
                    table[[*_LOCKED_ONLY, *own]] = np.nan
                    table[["settled", "dropped_samples"]] = None
                    table["amplitude_mm"] = 1e3 * np.abs(participation[:, m, 0])
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
        where = str(record.path or record.name)
        try:
            modal_filter = record_modal_filter(record, n_modes, given)
            with warnings.catch_warnings():  # the one-mode reading said what its holds say
                warnings.simplefilter("ignore")
                curve = modal_curve(record, modal_filter, n_periods, strict=False)
        except ValueError as exc:  # the one-mode reading stands without the check
            lines.append(f"{where}: not checked for a second mode: {exc}")
            continue
        mode, share = curve.largest_other_share()
        line = second_mode_warning(where, modal_filter.frequencies_hz[mode - 1], share, threshold)
        if line is not None:
            lines.append(line)
    return lines
