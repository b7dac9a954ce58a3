"""Signal preprocessing for identification: band-pass, differentiation, integration, scaling.

The paper (section 4.1.1) identifies from the centre-point velocity alone: a
Butterworth band-pass keeping the first three harmonics, acceleration by
central differences (its Eq. 1), displacement by the trapezoidal rule (its
Eq. 2), every signal divided by its maximum. These are the small pure pieces of
that chain; :func:`kinematics` strings them together for one record.

Filtering is zero-phase (``scipy.signal.sosfiltfilt``): a phase lag between
displacement, velocity and acceleration would read as spurious damping.
Zero-phase filtering squares the magnitude response, so the band edges are
placed where that squared gain loses only ``tolerance`` at the kept harmonics
(see :func:`harmonic_band_hz`), not at the harmonics themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy import integrate, signal

__all__ = [
    "DECAY_EDGE_PERIODS",
    "Kinematics",
    "amplitude_envelope",
    "bandpass",
    "central_difference",
    "displacement_from_velocity",
    "harmonic_band_hz",
    "kinematics",
    "lowpass",
    "scale_by_maximum",
    "trapezoid_integral",
    "unscale_coefficients",
]

#: Default Butterworth order (per band edge; the band-pass has twice as many poles).
DEFAULT_ORDER = 8
#: Default largest loss of the zero-phase squared gain at a kept harmonic.
DEFAULT_TOLERANCE = 1e-3
#: Edge trim for a free decay, in periods of the lower band edge: after 8 periods the
#: zero-phase band-pass's start transient on a decay switched on at full amplitude is
#: 5e-4 of it (5 % after 2, 1 % after 4, 2e-4 pass-band ripple from 10 on: 100–106 Hz at
#: 10 kHz, order 8). The 20 periods of a phase-resonance record would take the largest
#: amplitudes of a decay away, and the whole of a decay shorter than about 0.6 s.
DECAY_EDGE_PERIODS = 8.0


def harmonic_band_hz(
    frequency_hz: ArrayLike,
    sampling_rate_hz: float,
    n_harmonics: int = 3,
    *,
    order: int = DEFAULT_ORDER,
    tolerance: float = DEFAULT_TOLERANCE,
) -> tuple[float, float]:
    """Pass band (Hz) that keeps harmonics ``1..n_harmonics`` of a tracked frequency.

    The edges are solved for so that the zero-phase (``sosfiltfilt``) gain
    ``|H|²`` of the Butterworth band-pass loses exactly ``tolerance`` at the
    fundamental of the lowest tracked frequency and at harmonic
    ``n_harmonics`` of the highest, and less in between. With the analogue
    prototype ``|H|² = 1 / (1 + Ω^{2N})``, ``Ω = (ω² − ω_l ω_h) / ((ω_h − ω_l) ω)``
    (frequencies pre-warped as the bilinear transform does), this gives
    ``ω_l ω_h = ω_a ω_b`` and ``ω_h − ω_l = (ω_b − ω_a) / ρ`` with
    ``ρ = (tolerance / (1 − tolerance))^{1/(2N)}`` and ``ω_a``, ``ω_b`` the two
    protected frequencies. For 95–105 Hz and the defaults the band is about
    73–411 Hz and the 4th harmonic keeps about 40 % of its amplitude: a
    Butterworth cannot keep the 3rd harmonic undistorted and cut the 4th.

    Parameters
    ----------
    frequency_hz
        Instantaneous-frequency channel (Hz) or any array of tracked frequencies.
    sampling_rate_hz
        Sampling rate (Hz); the upper edge must stay below Nyquist.
    n_harmonics
        Highest harmonic to keep.
    order, tolerance
        Butterworth order per edge and the gain loss allowed at the kept harmonics.

    Returns
    -------
    (low_hz, high_hz)
    """
    f = np.asarray(frequency_hz, dtype=float)
    if f.size == 0 or not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise ValueError("frequency_hz must be non-empty, finite and > 0 everywhere")
    if n_harmonics < 1:
        raise ValueError(f"n_harmonics must be >= 1, got {n_harmonics}")
    if not 0 < tolerance < 0.5:
        raise ValueError(f"tolerance must be in (0, 0.5), got {tolerance}")
    nyquist = sampling_rate_hz / 2
    if n_harmonics * f.max() >= nyquist:
        raise ValueError(
            f"harmonic {n_harmonics} of {f.max():.1f} Hz is not below the Nyquist frequency "
            f"{nyquist:.1f} Hz of sampling_rate_hz={sampling_rate_hz}; lower n_harmonics or "
            "raise the sampling rate"
        )
    warp = 2 * sampling_rate_hz * np.tan(np.pi * np.array([f.min(), n_harmonics * f.max()])
                                         / sampling_rate_hz)  # fmt: skip
    rho = (tolerance / (1 - tolerance)) ** (1 / (2 * order))
    product, width = warp[0] * warp[1], (warp[1] - warp[0]) / rho
    high = 0.5 * (width + np.sqrt(width**2 + 4 * product))
    low_hz, high_hz = (sampling_rate_hz / np.pi) * np.arctan(np.array([product / high, high])
                                                             / (2 * sampling_rate_hz))  # fmt: skip
    if high_hz >= 0.99 * nyquist:
        raise ValueError(
            f"upper band edge {high_hz:.1f} Hz needed to keep harmonic {n_harmonics} of "
            f"{f.max():.1f} Hz is too close to the Nyquist frequency {nyquist:.1f} Hz; lower "
            "n_harmonics or raise the sampling rate"
        )
    return float(low_hz), float(high_hz)


def bandpass(
    values: ArrayLike,
    sampling_rate_hz: float,
    band_hz: tuple[float, float],
    *,
    order: int = DEFAULT_ORDER,
    axis: int = 0,
) -> np.ndarray:
    """Zero-phase Butterworth band-pass (``sosfiltfilt``) along ``axis``."""
    low, high = band_hz
    if not 0 < low < high < sampling_rate_hz / 2:
        raise ValueError(
            f"band_hz=({low}, {high}) must satisfy 0 < low < high < Nyquist "
            f"({sampling_rate_hz / 2} Hz)"
        )
    sos = signal.butter(order, [low, high], btype="bandpass", fs=sampling_rate_hz, output="sos")
    return signal.sosfiltfilt(sos, np.asarray(values, dtype=float), axis=axis)


def lowpass(
    values: ArrayLike,
    sampling_rate_hz: float,
    cutoff_hz: float,
    *,
    order: int = DEFAULT_ORDER,
    axis: int = 0,
) -> np.ndarray:
    """Zero-phase Butterworth low-pass (``sosfiltfilt``) along ``axis``: a signal's slow part."""
    if not 0 < cutoff_hz < sampling_rate_hz / 2:
        raise ValueError(
            f"cutoff_hz={cutoff_hz} must be in (0, Nyquist = {sampling_rate_hz / 2} Hz)"
        )
    sos = signal.butter(order, cutoff_hz, btype="lowpass", fs=sampling_rate_hz, output="sos")
    return signal.sosfiltfilt(sos, np.asarray(values, dtype=float), axis=axis)


def amplitude_envelope(
    values: ArrayLike, sampling_rate_hz: float, cutoff_hz: float, *, axis: int = 0
) -> np.ndarray:
    """Slowly varying amplitude of an oscillating signal: ``sqrt(2 · lowpass(values²))``.

    Exact for a sinusoid of constant amplitude (its square has mean ``a²/2``)
    once ``cutoff_hz`` is well below twice its frequency; the zero-phase
    low-pass keeps the envelope aligned with the signal.
    """
    squared = lowpass(np.square(np.asarray(values, dtype=float)), sampling_rate_hz, cutoff_hz,
                      axis=axis)  # fmt: skip
    return np.sqrt(2 * np.clip(squared, 0.0, None))


def central_difference(values: ArrayLike, sampling_rate_hz: float, *, axis: int = 0) -> np.ndarray:
    """Time derivative by central differences (paper Eq. 1); second-order one-sided at the ends."""
    return np.gradient(np.asarray(values, dtype=float), 1.0 / sampling_rate_hz, axis=axis,
                       edge_order=2)  # fmt: skip


def trapezoid_integral(values: ArrayLike, sampling_rate_hz: float, *, axis: int = 0) -> np.ndarray:
    """Running time integral by the trapezoidal rule (paper Eq. 2), starting at zero."""
    return integrate.cumulative_trapezoid(
        np.asarray(values, dtype=float), dx=1.0 / sampling_rate_hz, axis=axis, initial=0.0
    )


def displacement_from_velocity(
    velocity: ArrayLike,
    sampling_rate_hz: float,
    band_hz: tuple[float, float],
    *,
    order: int = DEFAULT_ORDER,
) -> np.ndarray:
    """Band-limited displacement from a velocity: trapezoidal rule, then the band-pass.

    Integration turns the unknown initial displacement into an offset and any
    low-frequency content of the velocity (sensor offset, noise below the band)
    into a drift; the zero-phase band-pass after it removes both (its zeros at
    DC cancel offsets and ramps, and it rejects a random walk's slow content).
    A plain detrend would not do: the drift of integrated noise is a random
    walk, not a line. Pass the *unfiltered* velocity: the displacement then
    sees the band-pass exactly once, like the velocity and acceleration derived
    from the same samples, so the three stay consistent in the band. The price
    is that a true slow mean of the displacement (the offset an asymmetric
    stiffness creates) is lost too; velocity data cannot show it anyway.
    """
    return bandpass(trapezoid_integral(velocity, sampling_rate_hz), sampling_rate_hz, band_hz,
                    order=order)  # fmt: skip


def scale_by_maximum(values: ArrayLike, *, axis: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Divide by the largest magnitude along ``axis`` (the paper's scaling).

    Returns
    -------
    (scaled, scale)
        ``scaled = values / scale`` with ``scale = max |values|`` along ``axis``
        (kept as an array, one entry per column for 2-D input).

    Raises
    ------
    ValueError
        If a column is identically zero or not finite (its scale is undefined).
    """
    values = np.asarray(values, dtype=float)
    scale = np.max(np.abs(values), axis=axis)
    bad = ~np.isfinite(scale) | (scale == 0)
    if np.any(bad):
        where = np.flatnonzero(np.atleast_1d(bad)).tolist()
        raise ValueError(f"cannot scale by maximum: column(s) {where} are all zero or not finite")
    return values / np.expand_dims(scale, axis), scale


def unscale_coefficients(
    scaled_coefficients: ArrayLike, feature_scales: ArrayLike, target_scale: float
) -> np.ndarray:
    """Map regression coefficients found on scaled data back to the original units.

    If ``y / s_y ≈ Σ ξ_i φ_i / s_i`` then ``y ≈ Σ (ξ_i s_y / s_i) φ_i``.
    """
    return np.asarray(scaled_coefficients, float) * target_scale / np.asarray(feature_scales, float)


@dataclass(frozen=True, eq=False)
class Kinematics:
    """Band-limited kinematics of one record, ready for regression.

    Attributes
    ----------
    t
        Time (s).
    displacement, velocity, acceleration
        Relative displacement (m), velocity (m/s) and acceleration (m/s²) of
        the response point with respect to the base.
    base_acceleration
        Base acceleration (m/s²), the excitation ``a_base`` of the model.
    sampling_rate_hz
        Sampling rate (Hz).
    band_hz
        Pass band used for all channels.
    valid
        Slice of samples away from the filter's end transients; regress on these.
    mean_offset
        Measured slow mean of the displacement about its equilibrium (m), which the
        band-pass takes out of ``displacement``; None where the sensor cannot show it
        (velocity, acceleration).
    """

    t: np.ndarray
    displacement: np.ndarray
    velocity: np.ndarray
    acceleration: np.ndarray
    base_acceleration: np.ndarray
    sampling_rate_hz: float
    band_hz: tuple[float, float]
    valid: slice
    mean_offset: np.ndarray | None = None

    @property
    def absolute_acceleration(self) -> np.ndarray:
        """``ẍ + a_base``: equals ``−Σ c_i φ_i(x, ẋ)`` for the model."""
        return self.acceleration + self.base_acceleration


def kinematics(
    t: ArrayLike,
    response_velocity: ArrayLike,
    base_velocity: ArrayLike,
    frequency_hz: ArrayLike,
    sampling_rate_hz: float,
    *,
    n_harmonics: int = 3,
    order: int = DEFAULT_ORDER,
    tolerance: float = DEFAULT_TOLERANCE,
    edge_periods: float = 20.0,
    band_hz: tuple[float, float] | None = None,
) -> Kinematics:
    """Band-limited displacement, velocity, acceleration and base acceleration of one record.

    Every channel passes the same band-pass exactly once, so displacement,
    velocity and acceleration, and the left- and right-hand sides of the
    model, see the same filter: ``band_hz`` when given, else the band that keeps
    ``n_harmonics`` of the frequency channel (:func:`harmonic_band_hz`).
    ``edge_periods`` periods of the lower band edge are marked invalid at both
    ends, where the zero-phase filter's end transients live.
    """
    t = np.asarray(t, dtype=float)
    channels = {"response_velocity": response_velocity, "base_velocity": base_velocity,
                "frequency_hz": frequency_hz}  # fmt: skip
    arrays = {}
    for name, values in channels.items():
        values = np.asarray(values, dtype=float)
        if values.shape != t.shape:
            raise ValueError(f"{name} has shape {values.shape}, expected {t.shape} like t")
        if not np.all(np.isfinite(values)):
            raise ValueError(f"{name} contains NaN or inf")
        arrays[name] = values
    if band_hz is None:
        band = harmonic_band_hz(arrays["frequency_hz"], sampling_rate_hz, n_harmonics,
                                order=order, tolerance=tolerance)  # fmt: skip
    else:
        band = (float(band_hz[0]), float(band_hz[1]))
        if not 0 < band[0] < band[1] < sampling_rate_hz / 2:
            raise ValueError(f"band {band} Hz must satisfy 0 < low < high < Nyquist "
                             f"({sampling_rate_hz / 2:g} Hz)")  # fmt: skip
    edge = int(np.ceil(edge_periods * sampling_rate_hz / band[0]))
    if t.size <= 4 * edge:
        raise ValueError(
            f"record of {t.size} samples is too short: at least {4 * edge + 1} are needed "
            f"({edge_periods} periods of the {band[0]:.1f} Hz band edge are dropped at each end)"
        )
    velocity = bandpass(arrays["response_velocity"], sampling_rate_hz, band, order=order)
    base_velocity = bandpass(arrays["base_velocity"], sampling_rate_hz, band, order=order)
    displacement = displacement_from_velocity(arrays["response_velocity"], sampling_rate_hz, band,
                                              order=order)  # fmt: skip
    return Kinematics(
        t=t,
        displacement=displacement,
        velocity=velocity,
        acceleration=central_difference(velocity, sampling_rate_hz),
        base_acceleration=central_difference(base_velocity, sampling_rate_hz),
        sampling_rate_hz=float(sampling_rate_hz),
        band_hz=band,
        valid=slice(edge, t.size - edge),
    )
