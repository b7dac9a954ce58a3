"""Backbones from free decays: sliding local fits along a ring-down.

A free decay (a ring-down after a release, after the excitation of a test is
switched off, or the decay segment at the end of a PLL record) passes through
every amplitude from its start down to the noise, and each stretch of a few
periods is a backbone point: the signal is fitted window by window with a
decaying, chirping multi-harmonic series
(:func:`identification.measurements.local_fit.fit_window`), windows of
``window_periods`` periods, each starting half a window after the previous one.
A window gives, with ``p`` the derivative order of the sensor's quantity
(:mod:`identification.measurements.quantities`) and ``ω``, ``β = ω̇``, ``σ`` its
fitted frequency, drift and decay rate:

* the relative displacement's harmonics ``X_k = S_k / λ_k^p`` from the signal's
  ``S_k``, with ``λ_k = k(−σ_x + iω)`` the rates of a displacement whose
  amplitude decays at ``σ_x = σ + pβ/ω`` (a velocity's amplitude ``ωa`` decays
  more slowly than ``a`` while ``ω`` rises); the amplitude is ``|X₁|``, the
  harmonics are kept in the frame of the fundamental as the hold fits keep them;
* the frequency ``ω / 2π`` at the window's centre;
* the damping ratio of the power balance, so that it means what a
  phase-resonance point's does (:mod:`identification.measurements.extraction`):
  the power the excitation supplies there, ``P = Dω³a²``, is what the structure
  dissipates on that orbit, and in a decay the energy ``E`` falls by it; a
  conservative oscillator's energy changes with its action
  ``J = (ω/2) Σ_k k²|X_k|² = (ωa²/2) S`` as ``dE/dJ = ω``, so
  ``D = −J̇ / (ω²a²) = S (σ_x/ω − ω̇/(2ω²)) + (σ_x/ω) Σ_{k≥2} k²(k−1) r_k²`` with
  ``r_k = |X_k|/a`` (harmonic ``k`` decaying at ``kσ_x``). For viscous damping
  ``c`` this is the ``c ⟨ẋ²⟩ / (ω³a²)`` harmonic balance gives; without the
  harmonics' share of the action (``S = 1``) it would read 4 % low where the
  2nd harmonic is 7 % of the fundamental;
* for a displacement sensor, the mean ``m₀`` of the window, from which the mean
  offset about the equilibrium follows (:func:`.quantities.mean_offsets`).

The decay ends where the fits sink into the noise: the first window whose
fundamental's relative standard error exceeds :data:`NOISE_LIMIT` ends it.

Where the decay is (:func:`decay_segments`): after the excitation is switched
off (a level of 0 in the step schedule after a nonzero one, else an excitation
channel whose envelope drops below :data:`OFF_FRACTION` of its peak), or, with
no excitation at all (none, or a channel of zeros), from where the response's
oscillation sets in to the end.
``edge_periods`` periods after that start are left out (a release transient).
"""

from __future__ import annotations

import itertools
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.ndimage import uniform_filter1d

from identification.measurements.backbone import Backbone
from identification.measurements.local_fit import LocalFit, dominant_frequency_hz, fit_window
from identification.measurements.quantities import derivative_order, mean_offsets

__all__ = [
    "DEFAULT_WINDOW_PERIODS",
    "MIN_DECAY_RATIO",
    "NOISE_LIMIT",
    "OFF_FRACTION",
    "DecayPoint",
    "decay_points",
    "decay_segments",
    "extract_decay_backbone",
]

#: Periods per window: long enough to resolve the 3rd harmonic and the decay rate, short
#: enough that the frequency moves nearly linearly across it.
DEFAULT_WINDOW_PERIODS = 6.0
#: Relative standard error of the fundamental's amplitude beyond which a window is noise.
NOISE_LIMIT = 0.01
#: Fraction of its peak envelope below which an excitation channel counts as switched off.
OFF_FRACTION = 0.01
#: Ratio of the first to the last amplitude a decay must reach: a response that loses less
#: than a sixth of its amplitude over the record is a steady response, not a decay.
MIN_DECAY_RATIO = 1.2
#: Fewest backbone points a decay must give.
MIN_POINTS = 3


@dataclass(frozen=True)
class DecayPoint:
    """Backbone point of one window of a decay (see the module notes).

    ``harmonics`` and ``harmonic_standard_error`` hold orders ``2..H`` as fractions of
    the fundamental; ``mean_m`` is the window's mean (displacement sensors; NaN
    otherwise), not yet referred to the equilibrium.
    """

    time_s: float
    amplitude_m: float
    frequency_hz: float
    damping_ratio: float
    harmonics: np.ndarray
    harmonic_standard_error: np.ndarray
    mean_m: float


def _point(fit: LocalFit, quantity: str) -> DecayPoint:
    p = derivative_order(quantity)
    omega = fit.omega
    beta = 2 * math.pi * fit.chirp_hz_s
    sigma_x = fit.decay_rate_1_s + p * beta / omega
    k = np.arange(1, fit.phasors.size + 1)
    rate = k * (-sigma_x + 1j * omega)
    # The p-th derivative of X e^{k(−σ_x τ + iωτ + iβτ²/2)} at τ = 0 (the drift adds ikβ
    # to the second).
    factor = np.ones_like(rate) if p == 0 else rate if p == 1 else rate**2 + 1j * k * beta
    displacement = fit.phasors / factor
    amplitude = abs(displacement[0])
    rotated = displacement * np.exp(-1j * k * np.angle(displacement[0]))
    # The action J = (ω/2) Σ k²|X_k|² = (ω a²/2) S, with harmonic k decaying at kσ_x.
    ratio_squared = np.abs(rotated[1:] / amplitude) ** 2
    action = 1 + np.sum(k[1:] ** 2 * ratio_squared)
    action_rate = np.sum(k[1:] ** 2 * (k[1:] - 1) * ratio_squared)  # −Ṡ / (2σ_x)
    damping = action * (sigma_x / omega - beta / (2 * omega**2)) + sigma_x / omega * action_rate
    return DecayPoint(
        time_s=fit.centre_s,
        amplitude_m=float(amplitude),
        frequency_hz=fit.frequency_hz,
        damping_ratio=float(damping),
        harmonics=rotated[1:] / amplitude,
        harmonic_standard_error=fit.phasor_standard_error[1:] / np.abs(factor[1:]) / amplitude,
        mean_m=fit.mean if p == 0 else math.nan,
    )


def _envelope(values: np.ndarray, samples_per_period: int) -> np.ndarray:
    """Amplitude of an oscillation: √2 × its RMS over a period about its own mean."""
    values = np.asarray(values, dtype=float)
    size = max(samples_per_period, 1)
    centred = values - uniform_filter1d(values, size, mode="nearest")
    return np.sqrt(2 * uniform_filter1d(centred**2, size, mode="nearest"))


def _off_intervals_from_steps(steps: Any) -> list[tuple[float, float]]:
    """Times the step schedule's level is 0 after having been nonzero."""
    level, time = np.asarray(steps.level), np.asarray(steps.time_s)
    intervals = []
    i = 1
    while i < level.size:
        if level[i] == 0 and level[i - 1] != 0:
            j = i
            while j + 1 < level.size and level[j + 1] == 0:
                j += 1
            intervals.append((float(time[i]), float(time[j]) if j + 1 < level.size else math.inf))
            i = j + 1
        else:
            i += 1
    return intervals


def decay_segments(
    time_s: np.ndarray,
    response: np.ndarray,
    sampling_rate_hz: float,
    *,
    excitation: np.ndarray | None = None,
    steps: Any = None,
    band_hz: tuple[float, float] | None = None,
) -> list[tuple[int, int]]:
    """Sample ranges ``(start, stop)`` of the free decays of a record (see the module notes).

    Each range starts where the response's oscillation sets in after the
    excitation went off (at once, for a decay after a hold), found on its
    envelope over the first quarter of the stretch.
    """
    t = np.asarray(time_s, dtype=float)
    frequency = dominant_frequency_hz(response, sampling_rate_hz, band_hz)
    period = max(round(sampling_rate_hz / frequency), 1)
    if excitation is not None and not np.any(excitation):
        excitation = steps = None  # nothing drives the record: it is all decay
    intervals = [] if steps is None else _off_intervals_from_steps(steps)
    if not intervals and excitation is not None:
        on = _envelope(excitation, period)
        off = on < OFF_FRACTION * on.max()
        # off stretches that follow an on stretch
        change = np.flatnonzero(np.diff(off.astype(np.int8)) != 0) + 1
        bounds = np.concatenate(([0], change, [t.size]))
        intervals = [
            (float(t[a]), float(t[b - 1]) if b < t.size else math.inf)
            for a, b in itertools.pairwise(bounds)
            if off[a] and a > 0
        ]
    elif not intervals:
        intervals = [(float(t[0]), math.inf)]
    envelope = _envelope(response, period)
    segments = []
    for start_s, stop_s in intervals:
        a = int(np.searchsorted(t, start_s, "left"))
        b = int(np.searchsorted(t, stop_s, "right")) if math.isfinite(stop_s) else t.size
        if b - a < 2 * period:
            continue
        # The envelope (a centred one-period RMS) reaches 1/√2 of the amplitude where the
        # oscillation sets in (a release); its peak is sought early in the stretch, as a
        # later rise would be a new excitation.
        head = envelope[a : min(b, a + max((b - a) // 4, 4 * period))]
        onset = a + int(np.argmax(head >= head.max() / math.sqrt(2)))
        segments.append((onset, b))
    return segments


def decay_points(
    time_s: np.ndarray,
    values: np.ndarray,
    quantity: str,
    segment: tuple[int, int],
    sampling_rate_hz: float,
    *,
    window_periods: float = DEFAULT_WINDOW_PERIODS,
    harmonics: int = 3,
    edge_periods: float = 0.0,
    band_hz: tuple[float, float] | None = None,
) -> tuple[list[DecayPoint], str]:
    """Backbone points along one decay segment, and why the last window was the last.

    Raises
    ------
    ValueError
        If the segment holds fewer periods than ``edge_periods`` plus one window.
    """
    t = np.asarray(time_s, dtype=float)
    y = np.asarray(values, dtype=float)
    start, stop = segment
    duration = t[stop - 1] - t[start]
    # The frequency near the start (its first second at most) starts the first fit.
    head = slice(start, min(stop, start + int(sampling_rate_hz)))
    frequency = dominant_frequency_hz(y[head], sampling_rate_hz, band_hz)
    periods = duration * frequency
    if periods < edge_periods + window_periods:
        raise ValueError(
            f"too few periods: the decay holds {periods:.1f} periods at {frequency:.4g} Hz, "
            f"a backbone point needs {window_periods:g} (plus {edge_periods:g} edge periods)"
        )
    centre = t[start] + (edge_periods + 0.5 * window_periods) / frequency
    omega, beta, sigma = 2 * math.pi * frequency, 0.0, 0.0
    points, reason = [], "the decay's end"
    while True:
        half = 0.5 * window_periods * 2 * math.pi / omega
        a = int(np.searchsorted(t, centre - half, "left"))
        b = int(np.searchsorted(t, centre + half, "right"))
        if a < start or centre + half > t[stop - 1]:
            break
        try:
            fit = fit_window(t[a:b], y[a:b], centre, omega, beta=beta, sigma=sigma,
                             harmonics=harmonics)  # fmt: skip
        except ValueError as exc:
            reason = f"a window fit failed at {centre:.4g} s ({exc})"
            break
        low, high = band_hz if band_hz is not None else (0.5 * frequency, 2.0 * frequency)
        if not (fit.converged and low <= fit.frequency_hz <= high):
            reason = f"the window fit at {centre:.4g} s did not converge inside the band"
            break
        if fit.relative_amplitude_error > NOISE_LIMIT:
            reason = f"the noise floor at {centre:.4g} s"
            break
        points.append(_point(fit, quantity))
        omega, beta, sigma = fit.omega, 2 * math.pi * fit.chirp_hz_s, fit.decay_rate_1_s
        centre += half  # half a window on
        omega += beta * half
    return points, reason


def extract_decay_backbone(
    record: Any,
    *,
    window_periods: float = DEFAULT_WINDOW_PERIODS,
    harmonics: int = 3,
    edge_periods: float = 0.0,
    band_hz: tuple[float, float] | None = None,
) -> Backbone:
    """Backbone of the free decays of a record (see the module notes).

    Parameters
    ----------
    record
        A test record (:class:`~identification.measurements.records.Record` or
        :class:`~identification.measurements.columns.ColumnRecord`): its response
        and quantity, and its step schedule or excitation where it has them.
    window_periods
        Periods per window.
    harmonics
        Harmonics fitted with the fundamental; the backbone keeps orders ``2..H``.
    edge_periods
        Periods left out at the start of each decay.
    band_hz
        Where the fundamental is looked for (default: the strongest peak).

    Raises
    ------
    ValueError
        Naming the file: no decay, too few periods, a response that does not
        decay (a steady response at one frequency), or fewer than
        :data:`MIN_POINTS` points above the noise.
    """
    where = record.path or record.name
    rate = record.sampling_rate_hz
    excitation = getattr(record, "excitation", None)
    try:
        segments = decay_segments(record.time_s, record.response, rate, excitation=excitation,
                                  steps=record.steps, band_hz=band_hz)  # fmt: skip
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    if not segments:
        raise ValueError(
            f"{where}: no free decay found (the excitation is never switched off "
            "after being on); a driven record is read with --test phase-resonance or stepped-sine"
        )
    points: list[DecayPoint] = []
    for segment in segments:
        try:
            found, reason = decay_points(
                record.time_s, record.response, record.quantity, segment, rate,
                window_periods=window_periods, harmonics=harmonics, edge_periods=edge_periods,
                band_hz=band_hz,
            )  # fmt: skip
        except ValueError as exc:
            raise ValueError(f"{where}: {exc}") from None
        if len(found) < MIN_POINTS:
            raise ValueError(
                f"{where}: too few periods above the noise: the decay from "
                f"{record.time_s[segment[0]]:.4g} s gave {len(found)} backbone point(s) "
                f"(windows of {window_periods:g} periods) before {reason}"
            )
        amplitude = np.array([p.amplitude_m for p in found])
        if amplitude.max() < MIN_DECAY_RATIO * amplitude.min():
            f = np.median([p.frequency_hz for p in found])
            raise ValueError(
                f"{where}: the response does not decay ({1e3 * amplitude.max():.4g} to "
                f"{1e3 * amplitude.min():.4g} mm over {found[-1].time_s - found[0].time_s:.3g} s "
                f"at {f:.5g} Hz): a steady response at one frequency cannot be identified "
                "without its excitation; give the excitation channel (--excitation NAME) "
                "and the test type it was (--test phase-resonance or stepped-sine)"
            )
        if reason != "the decay's end" and not reason.startswith("the noise floor"):
            warnings.warn(f"{where}: decay from {record.time_s[segment[0]]:.4g} s ends at "
                          f"{reason}; {len(found)} points kept", stacklevel=2)  # fmt: skip
        points += found
    amplitude = np.array([p.amplitude_m for p in points])
    mean = np.array([p.mean_m for p in points])
    higher = harmonics > 1
    return Backbone(
        amplitude_m=amplitude,
        frequency_hz=[p.frequency_hz for p in points],
        damping_ratio=[p.damping_ratio for p in points],
        label=record.name,
        source=str(where),
        harmonics=[p.harmonics for p in points] if higher else None,
        harmonic_standard_error=[p.harmonic_standard_error for p in points] if higher else None,
        mean_offset_m=None if np.isnan(mean).all() else mean_offsets(amplitude, mean),
    )
