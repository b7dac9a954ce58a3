"""Backbone points from phase-resonance records: one least-squares fit per hold phase.

A backbone point comes from one hold phase of a record (:mod:`identification.measurements.records`):
the last ``N`` excitation periods are fitted with a Fourier series whose phase
``φ(t) = 2π ∫ f(t) dt`` is the integral of the record's instantaneous-frequency
channel, so a slowly drifting PLL frequency is followed exactly and no
convention of the phase channel is assumed. With ``V_b`` and ``V`` the
fundamental-harmonic complex amplitudes of the base velocity and of the
centre-point velocity relative to the base (``v = Re(V e^{iφ})``), and
``ω = 2π f`` the mean frequency over the window:

* amplitude: ``|Q| = |V| / ω``, the relative-displacement fundamental (m);
* phase error: ``arg(V / V_b) + 90°``, zero at phase resonance, where the
  relative velocity lags the base velocity by 90°;
* damping ratio from the power balance of base excitation: the active power
  supplied per unit mass, ``½ Re(−iω V_b · conj(V))``, equals that of an
  equivalent viscous damper, ``½ · 2Dω · |V|²``, so
  ``D = |Q_b| cos(phase error) / (2 |Q|)`` — i.e. ``|Q_b| / (2|Q|)`` at
  phase resonance, with ``Q_b = V_b / (iω)`` the base-displacement fundamental.

The same fit measures the higher harmonics the point keeps
(:class:`~identification.measurements.backbone.Backbone`): the relative
displacement's ``Q_h = V_h / (ihω)`` and the base acceleration's
``A_h = ihω V_{b,h}``, each rotated into the frame where its own fundamental is
real and divided by its magnitude, with the standard errors of the response's
harmonics from the fit residual. Velocity sensors do not observe the mean
displacement, so a point's mean offset is NaN.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.integrate import cumulative_trapezoid

from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.decay import DEFAULT_WINDOW_PERIODS, extract_decay_backbone
from identification.measurements.quantities import (
    BASE_KINDS,
    derivative_order,
    equivalent_base_velocity,
    mean_offsets,
    to_velocity,
)
from identification.measurements.records import Hold, Record

__all__ = [
    "HoldPoint",
    "ShortHoldError",
    "extract_backbone",
    "extract_backbones",
    "fourier_basis",
    "hold_point",
    "hold_points",
    "hold_window",
    "record_holds",
]


class ShortHoldError(ValueError):
    """A hold phase has fewer periods than asked for."""

    def __init__(self, periods: float, n_periods: int) -> None:
        super().__init__(f"holds {periods:.1f} periods, fewer than n_periods = {n_periods}")
        self.periods = periods


@dataclass(frozen=True)
class HoldPoint:
    """Backbone point of one hold phase (see the module notes for the definitions).

    ``harmonics``, ``harmonic_standard_error`` and ``excitation_harmonics`` have one
    entry per order ``2..harmonics`` of the fit (fractions of the fundamental, in
    the convention of :class:`~identification.measurements.backbone.Backbone`).
    """

    amplitude_m: float
    frequency_hz: float
    damping_ratio: float
    phase_error_deg: float
    periods: int
    harmonics: np.ndarray
    harmonic_standard_error: np.ndarray
    excitation_harmonics: np.ndarray
    mean_offset_m: float = math.nan  # velocity sensors do not observe it


def hold_window(
    time_s: np.ndarray, frequency_hz: np.ndarray, n_periods: int
) -> tuple[int, np.ndarray, float]:
    """The last ``n_periods`` periods of a hold: first sample, phase from 0, mean ω.

    The phase is ``2π ∫ f dt`` of the instantaneous-frequency channel, so the
    window spans whole periods of the excitation even while the PLL moves.

    Raises
    ------
    ValueError
        If the frequency channel is not positive; :class:`ShortHoldError` if the
        hold has fewer than ``n_periods`` periods.
    """
    if (frequency_hz <= 0).any():
        raise ValueError("the frequency channel is not positive")
    phase = 2 * np.pi * cumulative_trapezoid(frequency_hz, time_s, initial=0.0)
    periods = (phase[-1] - phase[0]) / (2 * np.pi)
    if periods < n_periods:
        raise ShortHoldError(periods, n_periods)
    start = int(np.searchsorted(phase, phase[-1] - 2 * np.pi * n_periods, side="right") - 1)
    phi = phase[start:] - phase[start]
    return start, phi, float(phi[-1] / (time_s[-1] - time_s[start]))


def fourier_basis(phi: np.ndarray, harmonics: int) -> np.ndarray:
    """Columns ``[1, cos kφ…, sin kφ…]`` for ``k = 1..harmonics``."""
    k = np.arange(1, harmonics + 1)
    return np.column_stack([np.ones_like(phi), np.cos(np.outer(phi, k)), np.sin(np.outer(phi, k))])


def _in_own_frame(phasors: np.ndarray) -> np.ndarray:
    """Orders ``2..`` of ``Re Σ_k P_k e^{ikφ}`` where the fundamental is ``|P_1| cos θ``,
    as fractions of ``|P_1|``: ``P_k e^{−ik arg P_1} / |P_1|``."""
    k = np.arange(1, phasors.size + 1)
    rotated = phasors * np.exp(-1j * k * np.angle(phasors[0]))
    return rotated[1:] / abs(phasors[0])


def hold_point(
    time_s: np.ndarray,
    excitation_velocity: np.ndarray,
    response_velocity: np.ndarray,
    frequency_hz: np.ndarray,
    n_periods: int = 70,
    harmonics: int = 3,
    *,
    excitation_kind: str = "base-velocity",
    response_quantity: str = "velocity",
    relative: bool = True,
    forcing_gain: float = 1.0,
    test: str = "phase-resonance",
) -> HoldPoint:
    """Backbone point from the last ``n_periods`` periods of one hold phase.

    Parameters
    ----------
    time_s, excitation_velocity, response_velocity, frequency_hz
        Samples of the hold phase: time, excitation, response, instantaneous
        excitation frequency. With the defaults (a TRC record) the excitation is
        the base velocity and the response the centre velocity relative to the base.
    n_periods
        Whole periods used, counted back from the end of the hold.
    harmonics
        Harmonics fitted along with the fundamental (and a constant): orders
        ``2..harmonics`` are kept, and their leakage through a window of a
        non-integer number of samples per period does not bias the fundamental.
    excitation_kind, response_quantity
        What the two signals are (:mod:`identification.measurements.quantities`):
        their phasors are turned into those of the equivalent base velocity
        and of the relative velocity before anything is read off them.
    relative
        Whether the response is relative to the base (else the base's motion is
        taken off its phasors; only for base excitation).
    forcing_gain
        Modal forcing gain ``g`` (1/kg) of a force excitation.
    test
        ``"phase-resonance"``: the point is the hold's frequency, with the
        power-balance damping. ``"stepped-sine"``: a hold anywhere near the
        resonance, read by equivalent linearisation of the fundamental balance,
        ``ω_b² = ω² (1 + Re W)`` and ``D = ω Im W / (2 ω_b)`` with ``W = V_b / V``
        (equal to the phase-resonance reading where the phase error is zero).

    Raises
    ------
    ValueError
        If the frequency channel is not positive or the hold holds fewer than
        ``n_periods`` periods.
    """
    start, phi, omega = hold_window(time_s, frequency_hz, n_periods)
    basis = fourier_basis(phi, harmonics)
    signals = np.column_stack([excitation_velocity[start:], response_velocity[start:]])
    coef = np.linalg.lstsq(basis, signals, rcond=None)[0]
    # v = a cos kφ + b sin kφ = Re((a − ib) e^{ikφ}), per order k and signal
    velocity = coef[1 : 1 + harmonics] - 1j * coef[1 + harmonics :]
    k = np.arange(1, harmonics + 1)
    kinds = (excitation_kind, response_quantity, relative, forcing_gain)
    as_trc = kinds == ("base-velocity", "velocity", True, 1.0)
    if not as_trc:
        velocity = _velocities(velocity, 1j * k * omega, *kinds)
    base, relative_velocity = velocity[0]
    if relative_velocity == 0 or base == 0:
        raise ValueError("no measurable response (zero fundamental)")
    ratio = relative_velocity / base
    phase_error = np.degrees(np.angle(ratio * 1j))  # arg(V/V_b) + 90°, wrapped
    damping = np.real(-1j * base * np.conj(relative_velocity)) / (2 * abs(relative_velocity) ** 2)
    frequency = omega
    if test == "stepped-sine":
        frequency, damping = _equivalent_linear(base / relative_velocity, omega)
    # The response's harmonics from a solve of its own: LAPACK rounds a one-column
    # solve differently from the two-column one above, and some candidate fits of
    # the criticism (Stribeck, microslip, exp) move by up to 20 in ΔBIC when the
    # harmonics move by one rounding; this keeps them bit for bit as they were.
    response, *_ = np.linalg.lstsq(basis, response_velocity[start:], rcond=None)
    phasors = response[1 : 1 + harmonics] - 1j * response[1 + harmonics :]
    if not as_trc:
        phasors = _velocities(np.column_stack([velocity[:, 0], phasors]), 1j * k * omega,
                              "base-velocity", *kinds[1:3], 1.0)[:, 1]  # fmt: skip
    displacement = phasors / (1j * k * omega)
    # Standard errors of the response's cosine coefficients from the residual; over
    # whole periods the sine coefficients' differ by O(1 / samples).
    dof = max(phi.size - basis.shape[1], 1)
    variance = np.sum((response_velocity[start:] - basis @ response) ** 2) / dof
    se_signal = np.sqrt(variance * np.diag(np.linalg.inv(basis.T @ basis)))[1 : 1 + harmonics]
    se_velocity = se_signal * (k * omega) ** (1 - derivative_order(response_quantity))
    return HoldPoint(
        amplitude_m=abs(relative_velocity) / omega,
        frequency_hz=frequency / (2 * np.pi),
        damping_ratio=float(damping),
        phase_error_deg=float(phase_error),
        periods=n_periods,
        harmonics=_in_own_frame(displacement),
        harmonic_standard_error=se_velocity[1:] / (k[1:] * omega * abs(displacement[0])),
        excitation_harmonics=_in_own_frame(1j * k * omega * velocity[:, 0]),
        mean_offset_m=float(response[0]) if response_quantity == "displacement" else math.nan,
    )


def _velocities(
    phasors: np.ndarray, rate: np.ndarray, kind: str, quantity: str, relative: bool, gain: float
) -> np.ndarray:
    """Columns (excitation, response) of signal phasors → (equivalent base velocity, relative
    velocity) phasors (:mod:`identification.measurements.quantities`)."""
    base = equivalent_base_velocity(phasors[:, 0], rate, kind, gain)
    response = to_velocity(phasors[:, 1], rate, quantity)
    if not relative and kind in BASE_KINDS:
        response = response - base
    return np.column_stack([base, response])


def _equivalent_linear(ratio: complex, omega: float) -> tuple[float, float]:
    """Backbone frequency (rad/s) and damping of a hold off resonance, ``W = V_b / V``."""
    squared = omega**2 * (1 + ratio.real)
    if squared <= 0:
        raise ValueError(
            f"the hold at {omega / (2 * np.pi):.5g} Hz is too far above the resonance to "
            "read a backbone point from it"
        )
    backbone = math.sqrt(squared)
    return backbone, float(omega * ratio.imag / (2 * backbone))


def _hold_samples(record: Record, hold: Hold) -> slice:
    t = record.time_s
    return slice(np.searchsorted(t, hold.start_s, "left"), np.searchsorted(t, hold.end_s, "right"))


def _frequency_steps(time_s: np.ndarray, frequency_hz: np.ndarray) -> list[Hold]:
    """Holds of a stepped sine from its frequency channel: runs of one frequency (level NaN)."""
    change = np.flatnonzero(np.abs(np.diff(frequency_hz)) > 1e-9 * np.abs(frequency_hz[1:])) + 1
    bounds = np.concatenate(([0], change, [time_s.size]))
    return [
        Hold(math.nan, float(time_s[a]), float(time_s[b - 1]))
        for a, b in itertools.pairwise(bounds)
        if b - a > 1
    ]


def record_holds(record) -> list[Hold]:
    """The hold phases of a driven record: its step schedule's, without those at level 0.

    A level of 0 is the excitation switched off (a decay, read with
    ``test="free-decay"``), not a backbone point. A stepped-sine record without a
    step schedule takes its holds from the runs of one frequency of its frequency
    channel (their level is NaN: unknown).

    Raises
    ------
    ValueError
        Naming the record: no step schedule (and no frequency steps), or no hold.
    """
    where = record.path or record.name
    steps = record.steps
    if steps is not None:
        holds = [h for h in steps.holds() if h.level != 0]
        if not holds:
            raise ValueError(
                f"{where}: the step schedule {steps.source} has no hold phase at a nonzero "
                "level (no two consecutive rows with the same level)"
            )
        return holds
    channel = getattr(record, "frequency_channel", None)
    if record.test == "stepped-sine" and channel is not None:
        holds = _frequency_steps(record.time_s, channel)
        if holds:
            return holds
    stepped = " or the steps of a frequency channel (--frequency NAME)"
    raise ValueError(
        f"{where}: no step schedule: the holds of a {record.test} record come from a level "
        "column (--level NAME)" + (stepped if record.test == "stepped-sine" else "")
    )


def hold_points(
    record,
    n_periods: int = 70,
    harmonics: int = 3,
    strict: bool = True,
    forcing_gain: float = 1.0,
    test: str | None = None,
) -> tuple[list[HoldPoint], list[Hold]]:
    """One point per hold phase of a driven record (see :func:`extract_backbone`), and the holds.

    ``forcing_gain`` (1/kg) turns a force into the equivalent base acceleration;
    ``test`` overrides the record's (how the points are read).
    """
    for name, value in (("n_periods", n_periods), ("harmonics", harmonics)):
        if not isinstance(value, int | np.integer) or value < 1:
            raise ValueError(f"{name} must be an integer ≥ 1, got {value!r}")
    where = record.path or record.name
    holds = record_holds(record)
    if not np.any(record.excitation):
        raise ValueError(
            f"{where}: the excitation ({record.excitation_kind}) is zero throughout: nothing "
            "drives this record, so no hold has a power balance; a ring-down is read with "
            "--test free-decay"
        )
    options = dict(
        excitation_kind=record.excitation_kind, response_quantity=record.quantity,
        relative=record.relative, forcing_gain=forcing_gain, test=test or record.test,
    )  # fmt: skip
    points = []
    for hold in holds:
        rows = _hold_samples(record, hold)
        context = f"{where}: hold phase at level {hold.level:g} ({hold.start_s:g}–{hold.end_s:g} s)"
        if rows.stop - rows.start < 4 * (2 * harmonics + 1):
            raise ValueError(f"{context} has too few samples ({rows.stop - rows.start})")
        args = (
            record.time_s[rows],
            record.excitation[rows],
            record.response[rows],
            record.frequency_hz[rows],
        )
        try:
            point = hold_point(*args, n_periods=n_periods, harmonics=harmonics, **options)
        except ShortHoldError as exc:
            whole = int(exc.periods)
            if strict or whole < 1:
                raise ValueError(f"{context} {exc}") from None
            warnings.warn(f"{context} {exc}; using its {whole} whole periods", stacklevel=2)
            point = hold_point(*args, n_periods=whole, harmonics=harmonics, **options)
        except ValueError as exc:
            raise ValueError(f"{context}: {exc}") from None
        if not (np.isfinite(point.damping_ratio) and point.amplitude_m > 0):
            raise ValueError(f"{context}: no measurable response (zero fundamental)")
        if abs(point.phase_error_deg) > 90:
            raise ValueError(
                f"{context}: response is {point.phase_error_deg:+.1f}° from phase resonance "
                "(negative power input): check the signs of the response and excitation channels"
            )
        points.append(point)
    return points, holds


def extract_backbone(
    record: Record,
    n_periods: int = 70,
    harmonics: int = 3,
    strict: bool = True,
    *,
    window_periods: float = DEFAULT_WINDOW_PERIODS,
    edge_periods: float = 0.0,
    band_hz: tuple[float, float] | None = None,
) -> Backbone:
    """Backbone of a record: one point per hold phase, or per window of its free decays.

    Parameters
    ----------
    record
        A test record (:class:`~identification.measurements.records.Record`,
        :class:`~identification.measurements.columns.ColumnRecord`). Its test type
        decides: holds for ``phase-resonance`` and ``stepped-sine``
        (:func:`hold_point`), sliding windows of the decays for ``free-decay``
        (:func:`identification.measurements.decay.extract_decay_backbone`).
    n_periods
        Periods at the end of each hold phase used for its point (NLtest uses 70).
    harmonics
        Harmonics fitted besides the fundamental (see :func:`hold_point`); the
        backbone keeps orders ``2..harmonics`` (none when 1).
    strict
        Hold phases shorter than ``n_periods`` periods raise a ValueError; when
        False they use their whole periods instead, with a warning.
    window_periods, edge_periods, band_hz
        Free decays: periods per window, periods left out after the start of a
        decay, and where the fundamental is looked for.

    Raises
    ------
    ValueError
        Naming the record file and the level of a hold phase that is too short,
        has no data, a non-positive frequency channel, or a response that is not
        near phase quadrature with the excitation (|phase error| > 90°, i.e.
        negative power input: check the channel signs); an excitation that is
        zero throughout; and what :func:`~identification.measurements.decay.extract_decay_backbone`
        refuses.
    """
    if record.test == "free-decay":
        return extract_decay_backbone(record, window_periods=window_periods, harmonics=harmonics,
                                      edge_periods=edge_periods, band_hz=band_hz)  # fmt: skip
    gain = record.forcing_gain if record.excitation_kind == "force" else 1.0
    points, holds = hold_points(record, n_periods, harmonics, strict, forcing_gain=gain)
    where = record.path or record.name
    higher = harmonics > 1
    levels = [h.level for h in holds]
    amplitude = np.array([p.amplitude_m for p in points])
    return Backbone(
        amplitude_m=amplitude,
        frequency_hz=[p.frequency_hz for p in points],
        damping_ratio=[p.damping_ratio for p in points],
        excitation_level=None if np.isnan(levels).any() else levels,
        phase_error_deg=[p.phase_error_deg for p in points],
        label=record.name,
        source=str(where),
        harmonics=[p.harmonics for p in points] if higher else None,
        harmonic_standard_error=[p.harmonic_standard_error for p in points] if higher else None,
        excitation_harmonics=[p.excitation_harmonics for p in points] if higher else None,
        mean_offset_m=mean_offsets(amplitude, [p.mean_offset_m for p in points]),
    )


def extract_backbones(
    records: Iterable[Record],
    n_periods: int = 70,
    harmonics: int = 3,
    strict: bool = True,
    progress: bool = False,
    **decay_options: Any,
) -> BackboneSet:
    """Backbones of every record of a campaign (see :func:`extract_backbone`)."""
    if progress:
        from tqdm.auto import tqdm

        records = tqdm(records, desc="backbones", unit="record")
    return BackboneSet(
        extract_backbone(
            r, n_periods=n_periods, harmonics=harmonics, strict=strict, **decay_options
        )
        for r in records
    )
