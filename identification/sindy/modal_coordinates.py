"""Modal coordinates of records for the identification of coupled modal equations.

Each record becomes ``N`` modal coordinates ``x_m(t)`` with their band-limited
kinematics (:func:`modal_kinematics`):

* **Several sensors**: the modal filter of the record's sensors
  (:func:`~identification.measurements.modal_backbones.record_modal_filter`: the
  given or TRC mode shapes, else shapes estimated from the record), each
  coordinate scaled to the mode's contribution at its reference sensor (where its
  shape is largest). This is the coordinate an N-mode model's prediction carries
  to the sensors (:mod:`pm_joint.predict`) and the two-mode rig's truth uses.
* **One sensor**: each mode's band of the sensor's spectrum
  (:func:`~identification.measurements.decay_sensor.mode_frequencies_hz` and
  :func:`~identification.measurements.decay_sensor.mode_bands_hz`), zero-phase
  band-passed; every coordinate is then its contribution to that sensor. A mode's
  own harmonics that fall in another mode's band are read as that mode's (the
  sensor cannot tell them apart); several sensors avoid this.

A free decay whose step file says when it was released or hit (the TRC layout's
level 1 → 0) starts there (:func:`decay_onset`): before it the structure is held or
at rest, and the hit itself is a force the equations do not carry.

All coordinates of all records then pass one common band-pass (the harmonics
``1..n_harmonics`` of the lowest to the highest mode,
:func:`~identification.measurements.signals.harmonic_band_hz`), so that the library's
columns can pass the same filter (one filter on both sides, :mod:`.library`). The derived
channels (velocity, acceleration of a displacement; displacement, acceleration of a velocity)
then have the difference rules' gains divided out (:mod:`.modal_derivatives`), so that the
identified frequencies carry no ``(ωh)²`` bias; the one-mode path keeps the plain rules.

The **joint coordinate** ``q = Σ_m φ_m x_m`` is read at one sensor, the joint sensor
(default the record's response sensor: the TRC centre point, the first ``--response``
column): ``φ_m`` is the mode's shape there over its shape at its reference sensor.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from identification.measurements.decay import decay_segments
from identification.measurements.decay_sensor import mode_bands_hz, mode_frequencies_hz
from identification.measurements.modal_backbones import record_modal_filter, sensor_signals
from identification.measurements.modes import Modes
from identification.measurements.record import Record
from identification.measurements.signals import Kinematics, harmonic_band_hz
from identification.measurements.trc_layout import CENTRE_POINT
from identification.sindy import padding
from identification.sindy.kinematics import DEFAULT_EDGE_PERIODS, sensor_kinematics
from identification.sindy.modal_derivatives import unbiased_kinematics

__all__ = ["ModalKinematics", "ModalSettings", "decay_onset", "modal_kinematics"]

#: Periods of the lowest mode a one-sensor decay's spectral peak needs to count as a mode.
PEAK_PERIODS = 6.0


@dataclass(frozen=True)
class ModalSettings:
    """How records become modal coordinates.

    Attributes
    ----------
    n_harmonics
        Harmonics of the highest mode the common band keeps.
    edge_periods
        Periods of the band's lower edge left out at each end of a record.
    band_hz
        The common band (Hz), else from the modes' frequencies.
    joint_sensor
        Name of the sensor the joint coordinate is read at (default: the response sensor).
    """

    n_harmonics: int = 3
    edge_periods: float = DEFAULT_EDGE_PERIODS
    band_hz: tuple[float, float] | None = None
    joint_sensor: str | None = None


@dataclass(frozen=True, eq=False)
class ModalKinematics:
    """One record's modal coordinates, band-limited, ready for regression.

    Attributes
    ----------
    label
        The record's name (for messages).
    modes
        Per mode, the kinematics of its coordinate (contribution at its reference sensor);
        ``base_acceleration`` is the record's base acceleration (zeros for a free decay).
    frequencies_hz
        ``(N,)`` the modes' linear frequencies as the filter (or spectrum) gives them.
    joint_shape
        ``(N,)`` each coordinate's contribution to the joint coordinate.
    """

    label: str
    modes: tuple[Kinematics, ...]
    frequencies_hz: np.ndarray
    joint_shape: np.ndarray

    @property
    def valid(self) -> slice:
        return self.modes[0].valid

    @property
    def sampling_rate_hz(self) -> float:
        return self.modes[0].sampling_rate_hz

    @property
    def band_hz(self) -> tuple[float, float]:
        return self.modes[0].band_hz


def decay_onset(record: Any, responses: np.ndarray) -> int:
    """First sample of a free decay whose step file marks its release (else 0).

    The onset is :func:`~identification.measurements.decay.decay_segments`'s on the
    sensor with the largest response, from the step file's off interval; records
    without steps (column files) start at their first sample.
    """
    steps = getattr(record, "steps", None)
    if record.test != "free-decay" or steps is None or not np.any(np.asarray(steps.level)):
        return 0
    t = np.asarray(record.time_s, dtype=float)
    y = np.asarray(responses, dtype=float).reshape(t.size, -1)
    strongest = y[:, int(np.argmax(np.sqrt(np.mean(y**2, axis=0))))]
    rate = (t.size - 1) / (t[-1] - t[0])
    segments = decay_segments(t, strongest, rate, steps=steps)
    return segments[0][0] if segments else 0


class _Coordinates:
    """A record's raw modal coordinates (before the common band-pass)."""

    def __init__(self, record: Any, n_modes: int, mode_shapes: Modes | None, joint: str | None):
        self.label = str(record.path or record.name)
        self.t = np.asarray(record.time_s, dtype=float)
        signals, self.quantity = sensor_signals(record)
        signals = np.asarray(signals, dtype=float).reshape(self.t.size, -1)
        start = decay_onset(record, signals)
        self.t, signals = self.t[start:], signals[start:]
        names = tuple(record.sensor_names)
        rate = (self.t.size - 1) / (self.t[-1] - self.t[0])
        driven = record.test != "free-decay" and getattr(record, "base_driven", True)
        base = np.asarray(record.excitation_velocity)[start:] if driven else None
        self.base_velocity = None if base is None else np.asarray(base, dtype=float)
        if signals.shape[1] == 1:
            self.frequencies_hz = mode_frequencies_hz(signals[:, 0], rate, n_modes, PEAK_PERIODS)
            bands = mode_bands_hz(self.frequencies_hz)
            self.values = np.column_stack(
                [padding.bandpass(signals[:, 0], rate, band) for band in bands]
            )
            self.joint_shape = np.ones(n_modes)
            return
        modal_filter = record_modal_filter(record, n_modes, mode_shapes)
        self.frequencies_hz = np.asarray(modal_filter.frequencies_hz, dtype=float)
        self.values = modal_filter.scaled_coordinates(signals)  # shapes from the whole record
        if joint is None:
            index = CENTRE_POINT - 1 if isinstance(record, Record) else 0
        elif joint in names:
            index = names.index(joint)
        else:
            raise ValueError(f"{self.label}: no sensor {joint!r} (sensors: {', '.join(names)})")
        self.joint_shape = modal_filter.shapes[index] / modal_filter.reference_shape


def modal_kinematics(
    records: Sequence[Any],
    n_modes: int,
    *,
    mode_shapes: Modes | None = None,
    settings: ModalSettings | None = None,
) -> list[ModalKinematics]:
    """Modal coordinates of every record, band-passed by one common band (module notes).

    Parameters
    ----------
    records
        TRC :class:`Record` or column records, one sampling rate for all.
    n_modes
        Modes ``N`` (≥ 1) read per record.
    mode_shapes
        Mode shapes at the sensors (``--mode-shapes``); default the record's, else estimated.
    settings
        Band, edges, joint sensor.

    Raises
    ------
    ValueError
        A force-driven record (no driving-point shapes), records with different sampling
        rates, or whatever the modal filter refuses (naming the record).
    """
    settings = settings or ModalSettings()
    raw = []
    for record in records:
        if getattr(record, "excitation_kind", None) == "force" and record.test != "free-decay":
            raise ValueError(
                f"{record.path or record.name}: a force-driven record needs the driving point's "
                "mode shapes, which an N-mode identification does not have; use a free decay "
                "or a base-driven record"
            )
        try:
            raw.append(_Coordinates(record, n_modes, mode_shapes, settings.joint_sensor))
        except ValueError as exc:
            where = str(record.path or record.name)
            raise ValueError(exc if str(exc).startswith(where) else f"{where}: {exc}") from None
    rates = [(c.t.size - 1) / (c.t[-1] - c.t[0]) for c in raw]
    if max(rates) - min(rates) > 1e-6 * max(rates):
        raise ValueError("records have different sampling rates; resample first")
    band = settings.band_hz
    if band is None:
        frequencies = np.concatenate([c.frequencies_hz for c in raw])
        band = harmonic_band_hz(frequencies, rates[0], settings.n_harmonics)
    out = []
    for c in raw:
        # The derived channels without the difference rules' frequency bias
        # (:mod:`.modal_derivatives`): the modal equations carry it into a phase drift.
        modes = tuple(
            unbiased_kinematics(
                sensor_kinematics(c.t, c.values[:, m], c.quantity, base_velocity=c.base_velocity,
                                  band_hz=band, edge_periods=settings.edge_periods),
                c.quantity)
            for m in range(n_modes)
        )  # fmt: skip
        out.append(ModalKinematics(c.label, modes, c.frequencies_hz, c.joint_shape))
    return out
