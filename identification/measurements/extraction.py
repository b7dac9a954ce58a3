"""Backbone points from phase-resonance records: one least-squares fit per hold phase.

A backbone point comes from one hold phase of a record (:mod:`identification.measurements.records`):
the last ``N`` excitation periods are fitted with a Fourier series against a reference
phase that follows the PLL's frequency without its ripple and is cross-checked on the
base motion's own fundamental, without the samples a vibrometer dropout spiked
(:func:`identification.measurements.hold_fit.fit_hold`). With ``V_b`` and ``V`` the
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

A point also says how it was measured: the time of its window's centre, the
samples dropped as spikes, and whether the amplitude had settled (its relative
change over the window within
:data:`~identification.measurements.hold_fit.SETTLE_TOLERANCE`, or not
significantly beyond it). Points off phase resonance (:data:`PHASE_ERROR_TOLERANCE_DEG`) or not
settled are kept and flagged; :func:`extraction_summary` counts them. The power balance of a
hold that had not settled is corrected for the energy the growing (or decaying) response
stores over the window (:func:`stored_energy_damping`) beyond the settling tolerance:
without it, a hold that ends inside its step's transient reads the stored power as damping
(a slow lock's lowest level, which starts from rest, reads like friction). Settled points
are not touched; every point is left with at most the tolerance's bias.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import numpy as np

from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.decay import DEFAULT_WINDOW_PERIODS, extract_decay_backbone
from identification.measurements.hold_fit import (
    SETTLE_TOLERANCE,
    ShortHoldError,
    fit_hold,
    is_settled,
)
from identification.measurements.quantities import (
    BASE_KINDS,
    derivative_order,
    equivalent_base_velocity,
    mean_offsets,
    to_velocity,
)
from identification.measurements.records import Hold, Record

__all__ = [
    "PHASE_ERROR_TOLERANCE_DEG",
    "REFERENCE_TOLERANCE",
    "HoldPoint",
    "extract_backbone",
    "extract_backbones",
    "extraction_summary",
    "hold_point",
    "hold_points",
    "record_holds",
    "stored_energy_damping",
]

#: Largest relative difference between the frequency channel and the base motion's own
#: fundamental frequency that passes without a warning: 1e-4 (0.01 Hz at 100 Hz, half the
#: frequency noise floor of the fits) walks the channel's phase 0.04 rad off the base
#: motion over 70 periods.
REFERENCE_TOLERANCE = 1e-4
#: Phase errors (deg) beyond which a point is not at phase resonance: the frequency is
#: then off the backbone by about ζ·tan(error) of itself.
PHASE_ERROR_TOLERANCE_DEG = 5.0


@dataclass(frozen=True)
class HoldPoint:
    """Backbone point of one hold phase (see the module notes for the definitions).

    ``harmonics``, ``harmonic_standard_error`` and ``excitation_harmonics`` have one
    entry per order ``2..harmonics`` of the fit (fractions of the fundamental, in
    the convention of :class:`~identification.measurements.backbone.Backbone`).
    ``time_s`` is the window's centre on the clock of the samples given,
    ``amplitude_change`` the relative change of the displacement amplitude over the
    window, ``reference_offset_hz`` the base motion's own frequency minus the channel's.
    """

    amplitude_m: float
    frequency_hz: float
    damping_ratio: float
    phase_error_deg: float
    periods: int
    harmonics: np.ndarray
    harmonic_standard_error: np.ndarray
    excitation_harmonics: np.ndarray
    time_s: float
    dropped_samples: int
    amplitude_change: float
    settled: bool
    reference_offset_hz: float
    mean_offset_m: float = math.nan  # velocity sensors do not observe it


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
    fit = fit_hold(
        time_s, excitation_velocity, response_velocity, frequency_hz, n_periods, harmonics
    )
    omega = 2 * np.pi * fit.frequency_hz
    k = np.arange(1, harmonics + 1)
    order = derivative_order(response_quantity)
    velocity = np.column_stack([fit.excitation, fit.response])
    kinds = (excitation_kind, response_quantity, relative, forcing_gain)
    if kinds != ("base-velocity", "velocity", True, 1.0):
        velocity = _velocities(velocity, 1j * k * omega, *kinds)
    base, relative_velocity = velocity[0]
    if relative_velocity == 0 or base == 0:
        raise ValueError("no measurable response (zero fundamental)")
    phase_error = np.degrees(np.angle(relative_velocity / base * 1j))  # arg(V/V_b) + 90°, wrapped
    damping = np.real(-1j * base * np.conj(relative_velocity)) / (2 * abs(relative_velocity) ** 2)
    frequency = omega
    if test == "stepped-sine":
        frequency, damping = _equivalent_linear(base / relative_velocity, omega)
    displacement = velocity[:, 1] / (1j * k * omega)
    # Over whole periods the sine coefficients' standard errors differ from the
    # cosine ones' by O(1 / samples); the signal's turned into the velocity's.
    se_velocity = fit.response_standard_error * (k * omega) ** (1 - order)
    # The response signal's amplitude is |X|·ω^order: the displacement's changes by
    # the frequency's change `order` times less.
    change = fit.amplitude_change - order * fit.frequency_change
    settled = is_settled(change, fit.amplitude_change_standard_error)
    if not settled and test == "phase-resonance":
        # The change beyond the settling tolerance only: continuous where a hold crosses
        # it, and a settled hold keeps its reading (and its bias, at most the tolerance's).
        excess = change - np.clip(change, -SETTLE_TOLERANCE, SETTLE_TOLERANCE)
        damping -= stored_energy_damping(excess, fit.duration_s, omega)
    return HoldPoint(
        amplitude_m=abs(relative_velocity) / omega,
        frequency_hz=frequency / (2 * np.pi),
        damping_ratio=float(damping),
        phase_error_deg=float(phase_error),
        periods=fit.periods,
        harmonics=_in_own_frame(displacement),
        harmonic_standard_error=se_velocity[1:] / (k[1:] * omega * abs(displacement[0])),
        excitation_harmonics=_in_own_frame(1j * k * omega * velocity[:, 0]),
        time_s=fit.time_s,
        dropped_samples=fit.dropped_samples,
        amplitude_change=change,
        settled=settled,
        reference_offset_hz=fit.reference_offset_hz,
        mean_offset_m=fit.response_mean if response_quantity == "displacement" else math.nan,
    )


def stored_energy_damping(amplitude_change: float, duration_s: float, omega: float) -> float:
    """The damping ratio a power balance reads from a response still growing: ``ȧ / (a ω)``.

    The power supplied over a window feeds the damping and the energy stored in the
    motion, ``E ∝ a²``: ``P = 2ζω E + Ė``, so a power balance that takes ``P`` for the
    damping alone reads ``ζ + Ė / (2ωE) = ζ + ȧ / (a ω)`` (first order in the window's
    relative change ``amplitude_change`` over ``duration_s``; negative while the response
    decays). A hold that ends before the transient of its step has died out (a slow lock,
    a short hold) reads high, most at the lowest level, which starts from rest: a damping
    falling with amplitude, the signature of friction.
    """
    return amplitude_change / duration_s / omega


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
        if abs(point.reference_offset_hz) > REFERENCE_TOLERANCE * point.frequency_hz:
            warnings.warn(
                f"{context}: the frequency channel is {-point.reference_offset_hz:+.4g} Hz off "
                f"the excitation's own fundamental (tolerance {REFERENCE_TOLERANCE:g} of "
                "the frequency); the excitation's was used",
                stacklevel=3,
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

    Warns
    -----
    UserWarning
        One line naming the file and level of each hold whose frequency channel
        disagrees with the base motion's own fundamental by more than
        :data:`REFERENCE_TOLERANCE` (the base motion's is used).
    """
    if record.test == "free-decay":
        return extract_decay_backbone(record, window_periods=window_periods, harmonics=harmonics,
                                      edge_periods=edge_periods, band_hz=band_hz)  # fmt: skip
    gain = record.forcing_gain if record.excitation_kind == "force" else 1.0
    points, holds = hold_points(record, n_periods, harmonics, strict, forcing_gain=gain)
    where = record.path or record.name
    higher = harmonics > 1
    hold_levels = [h.level for h in holds]  # the step schedule's: shaker V in the TRC layout
    amplitude = np.array([p.amplitude_m for p in points])
    return Backbone(
        amplitude_m=amplitude,
        frequency_hz=[p.frequency_hz for p in points],
        damping_ratio=[p.damping_ratio for p in points],
        excitation_level=None if np.isnan(hold_levels).any() else hold_levels,
        phase_error_deg=[p.phase_error_deg for p in points],
        label=record.name,
        source=str(where),
        harmonics=[p.harmonics for p in points] if higher else None,
        harmonic_standard_error=[p.harmonic_standard_error for p in points] if higher else None,
        excitation_harmonics=[p.excitation_harmonics for p in points] if higher else None,
        mean_offset_m=mean_offsets(amplitude, [p.mean_offset_m for p in points]),
        time_s=[p.time_s - record.time_s[0] for p in points],
        settled=[p.settled for p in points],
        dropped_samples=[p.dropped_samples for p in points],
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


def extraction_summary(
    backbones: BackboneSet, phase_tolerance_deg: float = PHASE_ERROR_TOLERANCE_DEG
) -> str:
    """What the hold fits of extracted backbones flag, in one line per kind.

    Counts the points off phase resonance (beyond ``phase_tolerance_deg``), the
    points whose amplitude had not settled (:data:`SETTLE_TOLERANCE`) and the
    samples dropped as spikes; curves that do not carry a flag (model curves,
    tables written before the flags existed) are counted as unknown.
    """
    n_points = sum(len(b) for b in backbones)
    lines = [f"{n_points} point(s) in {len(backbones)} curve(s)"]
    phase = [b.phase_error_deg for b in backbones if b.phase_error_deg is not None]
    if phase:
        off = np.abs(np.concatenate(phase)) > phase_tolerance_deg
        lines.append(
            f"{off.sum()} of {off.size} point(s) more than ±{phase_tolerance_deg:g}° from phase "
            "resonance (kept; their frequency is off the backbone)"
        )
    settled = [b.settled for b in backbones if b.settled is not None]
    if settled:
        moving = ~np.concatenate(settled)
        lines.append(
            f"{moving.sum()} of {moving.size} point(s) not settled (amplitude still moving by "
            f"more than {100 * SETTLE_TOLERANCE:g} % over the window; kept)"
        )
    dropped = [b.dropped_samples for b in backbones if b.dropped_samples is not None]
    if dropped:
        counts = np.concatenate(dropped)
        lines.append(
            f"{counts.sum()} sample(s) dropped as spikes, in {np.count_nonzero(counts)} of "
            f"{counts.size} hold(s) (at most {counts.max()} in one)"
        )
    return "\n".join(lines)
