"""Backbones of several modes from a free decay, and the energy they exchange.

:func:`decay_backbones_by_mode` gives one :class:`~identification.measurements.backbone.Backbone`
per mode (in order of linear frequency) from a ring-down:

* **several sensors** with the modes' shapes: the modal coordinates ``q = Φ⁺ y`` by least
  squares on the shapes at the sensors (a modal filter; complex shapes made real by turning
  each to its principal phase, the normal-mode approximation, its error kept), then each
  coordinate through the one-mode decay analysis
  (:func:`identification.measurements.decay.decay_points`) in its band; the filter's
  reconstruction error is kept per sensor;
* **one sensor**: a joint local fit of every mode's damped, chirping multi-harmonic series,
  window by window, with a collision of one mode's harmonic with another mode's fundamental
  (1:2) attributed by its growth against the lower mode's amplitude
  (:mod:`identification.measurements.decay_sensor`).

Each point's frequency and power-balance damping mean what a one-mode decay point's do. A
mode's amplitude is its modal amplitude scaled to the sensor where its shape is largest (on
one sensor, the amplitude at that sensor). The energy of mode ``m`` at a point is
``E = ½ω²a²(1 + Σ_k k²|r_k|²)`` (the ``ω × action`` of a decay point, unit modal mass, modal
amplitude; on one sensor the amplitude at the sensor): its course over time between modes is
their exchange, and its time integral's share of all modes' is the mode's **energy share**.
A mode below the noise counts as no energy.

:func:`second_mode` runs the two-mode analysis on a one-mode request and says whether a second
mode carries more than :data:`SECOND_MODE_SHARE` of the energy; :func:`second_mode_warning` is
the warning's one line.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.decay import (
    DEFAULT_WINDOW_PERIODS,
    MIN_POINTS,
    DecayPoint,
    decay_points,
    decay_segments,
)
from identification.measurements.decay_sensor import (
    Attribution,
    LockAttribution,
    mode_bands_hz,
    sensor_mode_points,
)
from identification.measurements.local_fit import dominant_frequency_hz
from identification.measurements.modal_backbones import record_modal_filter, sensor_signals
from identification.measurements.modes import Modes
from identification.measurements.quantities import mean_offsets

__all__ = [
    "SECOND_MODE_SHARE",
    "ModalDecay",
    "decay_backbones_by_mode",
    "modal_decay_table",
    "record_decay_modes",
    "record_second_mode",
    "second_mode",
    "second_mode_warning",
]

#: Energy share above which a one-mode request is warned of a second mode.
SECOND_MODE_SHARE = 0.05
#: Harmonics whose participation each row of the table carries.
TABLE_HARMONICS = 3


@dataclass(frozen=True, eq=False)
class ModalDecay:
    """Several modes' backbones from one free decay (see the module notes).

    Attributes
    ----------
    backbones
        One per mode, in order of linear frequency (each with ``time_s``).
    linear_frequency_hz
        Each mode's frequency at its smallest measured amplitude (Hz).
    energy
        Per mode, the energy at each of its points (``E`` of the module notes).
    energy_share
        Per mode, its share of the time-integrated energy of all modes.
    method
        How the modes were separated: :attr:`Attribution.MODAL_FILTER` or
        :attr:`Attribution.SEPARATE` (one sensor).
    locks
        On one sensor, each harmonic collision and the rule that attributed it.
    reference_sensor
        Per mode, the sensor (index) its amplitude is scaled to.
    sensor_residual
        Modal filter: per sensor, RMS of ``y − Φq`` over RMS of ``y``; empty on one sensor.
    normal_mode_error
        Per mode, the norm of the imaginary part left after turning its shape real, over
        the shape's norm (0 for real shapes and on one sensor).
    stop_reasons
        Per mode, why its last point was the last.
    """

    backbones: tuple[Backbone, ...]
    linear_frequency_hz: np.ndarray
    energy: tuple[np.ndarray, ...]
    energy_share: np.ndarray
    method: Attribution
    locks: tuple[LockAttribution, ...]
    reference_sensor: tuple[int, ...]
    sensor_residual: np.ndarray
    normal_mode_error: np.ndarray
    stop_reasons: tuple[str, ...]

    @property
    def n_modes(self) -> int:
        """Number of modes."""
        return len(self.backbones)

    def share_at(self, time_s: np.ndarray) -> np.ndarray:
        """``(n_times, n_modes)``: each mode's share of the energy at those times
        (each mode's energy interpolated in its log over its points, 0 outside them)."""
        t = np.asarray(time_s, dtype=float)
        energies = np.zeros((t.size, self.n_modes))
        for m, (b, e) in enumerate(zip(self.backbones, self.energy, strict=True)):
            inside = (t >= b.time_s[0]) & (t <= b.time_s[-1])
            energies[inside, m] = np.exp(np.interp(t[inside], b.time_s, np.log(e)))
        total = energies.sum(axis=1, keepdims=True)
        return energies / np.where(total > 0, total, 1.0)

    def summary(self) -> list[str]:
        """Lines for the command line: each mode's points, then :meth:`rules` indented."""
        source = self.backbones[0].source or self.backbones[0].label
        modes = ", ".join(
            f"mode {m + 1}: {len(b)} points, {f:.2f} Hz, {100 * share:.0f} % of the energy"
            for m, (b, f, share) in enumerate(
                zip(self.backbones, self.linear_frequency_hz, self.energy_share, strict=True)
            )
        )
        return [f"{source}: {modes}", *(f"  {line}" for line in self.rules())]

    def rules(self) -> list[str]:
        """What separated the modes and what each collision was attributed to, one per line."""
        lines = [f"modes separated by {self.method.value}"]
        lines += [lock.describe(self.linear_frequency_hz) for lock in self.locks]
        return lines


def _real_shapes(shapes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shapes turned real (each column by its principal phase) and the imaginary part left."""
    phi = np.asarray(shapes, dtype=complex)
    if phi.ndim == 1:
        phi = phi[:, None]
    # The phase that maximises ‖Re(φ e^{−iθ})‖: half the angle of Σ φ².
    theta = 0.5 * np.angle(np.sum(phi**2, axis=0))
    turned = phi * np.exp(-1j * theta)
    error = np.linalg.norm(turned.imag, axis=0) / np.linalg.norm(turned, axis=0)
    return turned.real, error


def _energy(points: Sequence[DecayPoint]) -> np.ndarray:
    """``½ω²a²(1 + Σ k²|r_k|²)`` at each point."""
    out = []
    for p in points:
        k = np.arange(2, 2 + p.harmonics.size)
        action = 1 + np.sum(k**2 * np.abs(p.harmonics) ** 2)
        out.append(0.5 * (2 * math.pi * p.frequency_hz * p.amplitude_m) ** 2 * action)
    return np.array(out)


def _backbone(points: Sequence[DecayPoint], scale: float, label: str, source: str) -> Backbone:
    """A mode's backbone from its points, amplitudes times ``scale`` (the reference sensor's
    shape entry)."""
    amplitude = np.array([p.amplitude_m for p in points])
    mean = np.array([p.mean_m for p in points])
    higher = points[0].harmonics.size > 0
    return Backbone(
        amplitude_m=scale * amplitude,
        frequency_hz=[p.frequency_hz for p in points],
        damping_ratio=[p.damping_ratio for p in points],
        label=label,
        source=source,
        harmonics=[p.harmonics for p in points] if higher else None,
        harmonic_standard_error=[p.harmonic_standard_error for p in points] if higher else None,
        mean_offset_m=None if np.isnan(mean).all() else scale * mean_offsets(amplitude, mean),
        time_s=[p.time_s for p in points],
    )


def _modal_filter_points(t, y, shapes, quantity, rate, frequencies_hz, options, where):
    """Points per mode through the modal filter (several sensors)."""
    phi, error = _real_shapes(shapes)
    if phi.shape[0] != y.shape[1] or phi.shape[0] < phi.shape[1]:
        raise ValueError(
            f"{y.shape[1]} sensor(s) and shapes of shape {phi.shape}: the modal filter needs "
            "one shape row per sensor and at least as many sensors as modes"
        )
    q = np.linalg.lstsq(phi, y.T, rcond=None)[0]
    residual = np.sqrt(np.mean((y - (phi @ q).T) ** 2, axis=0) / np.mean(y**2, axis=0))
    f = (np.array([dominant_frequency_hz(qm, rate) for qm in q])
         if frequencies_hz is None else np.asarray(frequencies_hz, dtype=float))  # fmt: skip
    order = np.argsort(f)
    points, reasons, scales, reference = [], [], [], []
    for m, band in zip(order, mode_bands_hz(f[order]), strict=True):
        segments = decay_segments(t, q[m], rate, band_hz=band, **where)
        if not segments:
            raise ValueError(f"mode {len(points) + 1} ({f[m]:.5g} Hz): no free decay found")
        found, reason = decay_points(t, q[m], quantity, segments[0], rate, band_hz=band,
                                     **options)  # fmt: skip
        points.append(found)
        reasons.append(reason)
        reference.append(int(np.argmax(np.abs(phi[:, m]))))
        scales.append(abs(float(phi[reference[-1], m])))
    return points, reasons, scales, reference, residual, error[order]


def decay_backbones_by_mode(
    time_s: np.ndarray,
    signals: np.ndarray,
    *,
    n_modes: int,
    quantity: str,
    shapes: np.ndarray | None = None,
    frequencies_hz: Sequence[float] | None = None,
    window_periods: float = DEFAULT_WINDOW_PERIODS,
    harmonics: int = 3,
    edge_periods: float = 0.0,
    label: str = "decay",
    source: str = "",
    excitation: np.ndarray | None = None,
    steps: Any = None,
) -> ModalDecay:
    """Each mode's backbone from a free decay (see the module notes).

    Parameters
    ----------
    time_s
        Uniform sample times (s).
    signals
        ``(n,)`` one sensor or ``(n, n_sensors)``.
    n_modes
        Modes sought (≥ 1).
    quantity
        ``displacement``, ``velocity`` or ``acceleration``: what every sensor reads.
    shapes
        ``(n_sensors, n_modes)`` mode shapes at the sensors (real or complex); required with
        several sensors.
    frequencies_hz
        The modes' linear frequencies where known (one sensor: else the spectrum's peaks;
        several: else each modal coordinate's).
    window_periods, harmonics, edge_periods
        As for the one-mode decay analysis (:func:`~.decay.decay_points`).
    label, source
        Curve label (each mode's is ``"{label} mode {m}"``) and source.
    excitation, steps
        The record's excitation channel and step schedule where it has them: the decay
        is the first of :func:`~.decay.decay_segments`.

    Raises
    ------
    ValueError
        No decay, modes that cannot be separated, or a mode with fewer than
        :data:`~.decay.MIN_POINTS` points above the noise (naming the rule that found
        no mode there).
    """
    t = np.asarray(time_s, dtype=float)
    y = np.asarray(signals, dtype=float)
    if n_modes < 1:
        raise ValueError(f"n_modes must be >= 1, got {n_modes}")
    rate = (t.size - 1) / (t[-1] - t[0])
    options = {"window_periods": window_periods, "harmonics": harmonics,
               "edge_periods": edge_periods}  # fmt: skip
    where = {"excitation": excitation, "steps": steps}
    if y.ndim == 2 and y.shape[1] > 1:
        if shapes is None:
            raise ValueError(f"{y.shape[1]} sensors need the mode shapes at the sensors")
        phi = np.asarray(shapes)
        phi = phi.reshape(-1, 1) if phi.ndim == 1 else phi
        if phi.shape[1] != n_modes:
            raise ValueError(f"{n_modes} mode(s) asked for, shapes of {phi.shape[1]} given")
        points, reasons, scales, reference, residual, error = _modal_filter_points(
            t, y, phi, quantity, rate, frequencies_hz, options, where
        )
        method, locks, frequencies = Attribution.MODAL_FILTER, (), None
    else:
        found = sensor_mode_points(
            t, y.reshape(-1), quantity, rate, n_modes,
            frequencies_hz=None if frequencies_hz is None else np.asarray(frequencies_hz),
            **options, **where,
        )  # fmt: skip
        points, reasons, locks = found.points, found.stop_reasons, found.locks
        scales, reference = [1.0] * n_modes, [0] * n_modes
        residual, error = np.zeros(0), np.zeros(n_modes)
        method, frequencies = Attribution.SEPARATE, found.frequencies_hz
    for m, (mode_points, reason) in enumerate(zip(points, reasons, strict=True)):
        if len(mode_points) >= MIN_POINTS:
            continue
        harmonic = [lock for lock in locks
                    if lock.lock.upper == m and lock.rule is Attribution.HARMONIC]  # fmt: skip
        if harmonic:
            raise ValueError(f"{source or label}: no mode {m + 1} found: "
                             f"{harmonic[0].describe(frequencies)}")  # fmt: skip
        raise ValueError(
            f"{source or label}: mode {m + 1} gave {len(mode_points)} backbone point(s) "
            f"above the noise before {reason}"
        )
    backbones = tuple(
        _backbone(p, s, f"{label} mode {m + 1}", source)
        for m, (p, s) in enumerate(zip(points, scales, strict=True))
    )
    energy = tuple(_energy(p) for p in points)
    integrals = np.array([
        np.trapezoid(e, b.time_s) if e.size > 1 else 0.0
        for e, b in zip(energy, backbones, strict=True)
    ])  # fmt: skip
    linear = np.array([b.frequency_hz[np.argmin(b.amplitude_m)] for b in backbones])
    return ModalDecay(
        backbones=backbones,
        linear_frequency_hz=linear,
        energy=energy,
        energy_share=integrals / integrals.sum(),
        method=method,
        locks=tuple(locks),
        reference_sensor=tuple(reference),
        sensor_residual=residual,
        normal_mode_error=np.asarray(error, dtype=float),
        stop_reasons=tuple(reasons),
    )


def _record_inputs(record: Any, options: dict[str, Any]) -> dict[str, Any]:
    """The keywords of :func:`decay_backbones_by_mode` for a record (one sensor) and the
    decay options of the command line (its ``band_hz`` is not used: each mode has its own)."""
    kept = {k: v for k, v in options.items() if k in ("window_periods", "edge_periods")}
    return {"quantity": record.quantity, "excitation": getattr(record, "excitation", None),
            "steps": record.steps, **kept}  # fmt: skip


def record_decay_modes(
    record: Any, n_modes: int, mode_shapes: Modes | None = None, **options: Any
) -> ModalDecay:
    """:func:`decay_backbones_by_mode` of a record, its file named in any error.

    A record of several sensors (the TRC panel points, ``--response a,b,c``) is read through
    the modal filter of its sensors, with the shapes of ``mode_shapes`` (a ``--mode-shapes``
    file), else of the record's modes file, else estimated from the record
    (:func:`~identification.measurements.modal_backbones.record_modal_filter`); a record of
    one sensor by the joint local fit of the modes' bands. ``options``: the command line's
    decay options.
    """
    where = str(record.path or record.name)
    inputs = _record_inputs(record, options)
    signals = record.response
    try:
        if len(getattr(record, "sensor_names", ())) > 1:
            modal_filter = record_modal_filter(record, n_modes, mode_shapes)
            signals, inputs["quantity"] = sensor_signals(record)
            inputs |= {"shapes": modal_filter.shapes,
                       "frequencies_hz": modal_filter.frequencies_hz}  # fmt: skip
        return decay_backbones_by_mode(record.time_s, signals, n_modes=n_modes,
                                       label=record.name, source=where, **inputs)  # fmt: skip
    except ValueError as exc:
        message = str(exc)
        raise ValueError(message if message.startswith(where) else f"{where}: {message}") from None


def record_second_mode(record: Any, mode_shapes: Modes | None = None, **options: Any) -> str | None:
    """The warning line for a record read as one mode that carries a second (or None).

    A record of several sensors is looked at through all of them, by the modal filter of two
    modes (shapes of ``mode_shapes``, else of its modes file, else estimated from the record:
    :func:`~identification.measurements.modal_backbones.record_modal_filter`): one sensor may
    sit on a mode's node line (the TRC panel's centre point on the torsion's). Where that
    filter cannot be built, and on one sensor, the record's response is looked at.
    """
    inputs = _record_inputs(record, options)
    signals = record.response
    if len(getattr(record, "sensor_names", ())) > 1:
        try:
            modal_filter = record_modal_filter(record, 2, mode_shapes)
        except ValueError:
            modal_filter = None
        if modal_filter is not None:
            signals, inputs["quantity"] = sensor_signals(record)
            inputs |= {"shapes": modal_filter.shapes,
                       "frequencies_hz": modal_filter.frequencies_hz}  # fmt: skip
    found = second_mode(record.time_s, signals, **inputs)
    return None if found is None else second_mode_warning(*found, where=record.path or record.name)


def second_mode(
    time_s: np.ndarray,
    signals: np.ndarray,
    *,
    quantity: str,
    share: float = SECOND_MODE_SHARE,
    **options: Any,
) -> tuple[float, float] | None:
    """``(linear frequency in Hz, energy share)`` of a second mode carrying more than
    ``share`` of a decay's energy, or None.

    The two-mode analysis (:func:`decay_backbones_by_mode`) is run; a record in which it
    finds no second mode (only one peak, or content attributed to the first mode's
    harmonic, or a second component with fewer points above the noise than a backbone
    needs) carries none.
    """
    try:
        found = decay_backbones_by_mode(time_s, signals, n_modes=2, quantity=quantity, **options)
    except ValueError:
        return None
    energies = found.energy_share
    strongest = int(np.argmax(energies))
    other = 1 - strongest
    if energies[other] <= share:
        return None
    return float(found.linear_frequency_hz[other]), float(energies[other])


def second_mode_warning(frequency_hz: float, share: float, where: Any = None) -> str:
    """The one warning line of a one-mode request on a record that carries a second mode."""
    record = "the record" if where is None else f"the record {where}"
    return (
        f"warning: {record} carries a second mode near {frequency_hz:.1f} Hz "
        f"({100 * share:.0f} % of the energy); --modes 2 gives its backbone"
    )


def modal_decay_table(decays: Sequence[ModalDecay]) -> pd.DataFrame:
    """One table of several decays' modes: the backbone table's columns (curves
    ``"{label} mode {m}"``), then ``mode`` (1, 2, … in order of linear frequency),
    ``reference_sensor`` and, per mode ``j`` of the same decay at the row's time, its
    participation ``mode{j}_h{k}_amplitude_mm`` (``k = 1..3``, the amplitude at its
    reference sensor times its harmonic's fraction), ``mode{j}_h{k}_phase_deg`` (harmonic
    ``k`` against ``k`` times mode ``j``'s fundamental; 0 for ``k = 1`` of the row's own
    mode, NaN for another mode's: in a free decay their phases drift) and
    ``mode{j}_energy_share``.
    """
    frames = []
    n_modes = max((d.n_modes for d in decays), default=0)
    for decay in decays:
        table = BackboneSet(list(decay.backbones)).to_table()
        rows = np.concatenate([np.full(len(b), m + 1) for m, b in enumerate(decay.backbones)])
        times = np.concatenate([b.time_s for b in decay.backbones])
        table["mode"] = rows
        table["reference_sensor"] = [decay.reference_sensor[m - 1] for m in rows]
        shares = decay.share_at(times)
        for j in range(n_modes):
            for k in range(1, TABLE_HARMONICS + 1):
                amplitude, phase = np.full(times.size, np.nan), np.full(times.size, np.nan)
                if j < decay.n_modes:
                    amplitude, phase = _participation(decay.backbones[j], k, times)
                    if k == 1:
                        phase = np.where(rows == j + 1, 0.0, np.nan)
                table[f"mode{j + 1}_h{k}_amplitude_mm"] = 1e3 * amplitude
                table[f"mode{j + 1}_h{k}_phase_deg"] = phase
            table[f"mode{j + 1}_energy_share"] = shares[:, j] if j < decay.n_modes else np.nan
        frames.append(table)
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _participation(backbone: Backbone, order: int, times: np.ndarray):
    """Amplitude (m) and phase (deg) of a mode's harmonic ``order`` at ``times`` (NaN
    outside its points)."""
    t = backbone.time_s
    inside = (times >= t[0]) & (times <= t[-1])
    amplitude = np.full(times.size, np.nan)
    phase = np.full(times.size, np.nan)
    a = np.exp(np.interp(times[inside], t, np.log(backbone.amplitude_m)))
    if order == 1:
        amplitude[inside] = a
        return amplitude, phase
    h = backbone.harmonics
    if h is None or h.shape[1] < order - 1:
        return amplitude, phase
    r = h[:, order - 2]
    ratio = np.interp(times[inside], t, r.real) + 1j * np.interp(times[inside], t, r.imag)
    amplitude[inside] = a * np.abs(ratio)
    phase[inside] = np.degrees(np.angle(ratio))
    return amplitude, phase
