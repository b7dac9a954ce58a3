"""Kinematics of any response sensor: displacement, velocity or acceleration, base channel or none.

Phase-resonance records carry a velocity response, a base velocity and a frequency
channel (:func:`~identification.measurements.signals.kinematics`). Free decays and
many lab files carry one response channel, a displacement (laser triangulation, a
finite-element output), a velocity (vibrometer) or an acceleration
(accelerometer), often with no base motion and no frequency channel.
:func:`sensor_kinematics` gives the same band-limited ``(x, ẋ, ẍ)`` for each, every
channel passing the band-pass once:

* velocity: the pipeline's chain (trapezoidal rule and central differences, the
  paper's Eqs. 1–2);
* displacement: velocity and acceleration by central differences of the
  band-passed displacement; its slow mean is kept (``Kinematics.mean_offset``),
  measured from the equilibrium, the mean the record tends to at zero amplitude
  (:func:`measured_mean_offset`);
* acceleration: velocity and displacement by the trapezoidal rule, once and
  twice, each detrended (linear, quadratic) before the band-pass, so that an
  unknown initial velocity or a sensor bias does not leave a ramp of millimetres
  whose filter transients swamp the oscillation.

Without a frequency channel the band follows the response's own spectrum
(:func:`frequency_range_hz`).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike
from scipy import signal

from identification.measurements.signals import (
    DEFAULT_ORDER,
    DEFAULT_TOLERANCE,
    Kinematics,
    central_difference,
    harmonic_band_hz,
    trapezoid_integral,
)
from identification.sindy import padding
from identification.sindy.library import slow_cutoff_hz

QUANTITIES = ("displacement", "velocity", "acceleration")
#: Default edge trim, in periods of the band's lower edge: after 8 periods the start
#: transient of the zero-phase band-pass (order 8) on a switched-on sinusoid is below its
#: pass-band error (4e-4 of the amplitude; 2 % after 3 periods, 0.4 % after 5).
DEFAULT_EDGE_PERIODS = 2.0
#: Spectrogram segments whose peak lies more than this below the strongest segment's
#: (power ratio) are left out of the frequency range: a decay that has sunk into the noise.
PEAK_DYNAMIC_RANGE = 1e-4
#: Margin put on each side of the tracked frequency range (relative).
FREQUENCY_MARGIN = 0.03


def sensor_kinematics(
    t: ArrayLike,
    response: ArrayLike,
    quantity: str,
    *,
    base_velocity: ArrayLike | None = None,
    frequency_hz: ArrayLike | None = None,
    n_harmonics: int = 3,
    order: int = DEFAULT_ORDER,
    tolerance: float = DEFAULT_TOLERANCE,
    edge_periods: float = DEFAULT_EDGE_PERIODS,
    band_hz: tuple[float, float] | None = None,
) -> Kinematics:
    """Band-limited kinematics of one record from a displacement, velocity or acceleration.

    Every filter is zero-phase and padded by linear prediction (:mod:`.padding`),
    so that a record that starts in motion (a release) keeps its first periods.

    Parameters
    ----------
    t
        Sample times (s), uniformly sampled.
    response
        Response relative to the base, in SI units of ``quantity`` (m, m/s or m/s²).
    quantity
        ``"displacement"``, ``"velocity"`` or ``"acceleration"``.
    base_velocity
        Base velocity (m/s) of a base-driven test; None for a free decay (no excitation).
    frequency_hz
        Instantaneous excitation frequency (Hz), or None to take the band from the
        response's spectrum (:func:`frequency_range_hz`).
    n_harmonics, order, tolerance
        Pass band (:func:`~identification.measurements.signals.harmonic_band_hz`).
    edge_periods
        Periods of the band's lower edge left out at each end (see :data:`DEFAULT_EDGE_PERIODS`).
    band_hz
        The pass band (Hz) when given (the CLI's ``--band``); else from ``frequency_hz``.

    Returns
    -------
    Kinematics
        With ``mean_offset`` set for a displacement, None otherwise.

    Raises
    ------
    ValueError
        Unknown quantity, arrays of different shapes, NaN or inf, a record too short for
        its edges, or no oscillation to take a band from.
    """
    if quantity not in QUANTITIES:
        raise ValueError(f"quantity must be one of {QUANTITIES}, got {quantity!r}")
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 3:
        raise ValueError("t must be 1-D with at least 3 samples")
    response = _finite("response", response, t.shape)
    rate = (t.size - 1) / (t[-1] - t[0])
    if band_hz is not None:
        band = (float(band_hz[0]), float(band_hz[1]))
        if not 0 < band[0] < band[1] < rate / 2:
            raise ValueError(f"band_hz={band_hz} must satisfy 0 < low < high < Nyquist")
    else:
        if frequency_hz is None:
            frequency_hz = frequency_range_hz(response, rate, quantity)
        band = harmonic_band_hz(_finite("frequency_hz", np.atleast_1d(frequency_hz),
                                        np.atleast_1d(frequency_hz).shape),
                                rate, n_harmonics, order=order, tolerance=tolerance)  # fmt: skip
    edge = int(np.ceil(edge_periods * rate / band[0]))
    if t.size <= 4 * edge:
        raise ValueError(
            f"record of {t.size} samples is too short: at least {4 * edge + 1} are needed "
            f"({edge_periods} periods of the {band[0]:.1f} Hz band edge are dropped at each end)"
        )

    def band_passed(values: np.ndarray) -> np.ndarray:
        return padding.bandpass(values, rate, band, order)

    offset = None
    if quantity == "displacement":
        displacement = band_passed(response)
        velocity = central_difference(displacement, rate)
        acceleration = central_difference(velocity, rate)
        offset = measured_mean_offset(response, displacement, rate, band, slice(edge, -edge))
    else:
        # Integrate before filtering, so that every channel sees the band-pass once; the
        # trends are integration constants and sensor offsets, not the motion.
        raw_velocity = response if quantity == "velocity" else signal.detrend(
            trapezoid_integral(response, rate))  # fmt: skip
        velocity = band_passed(raw_velocity)
        displacement = band_passed(_detrend_quadratic(trapezoid_integral(raw_velocity, rate)))
        acceleration = (central_difference(velocity, rate) if quantity == "velocity"
                        else band_passed(response))  # fmt: skip
    base = np.zeros_like(t) if base_velocity is None else central_difference(
        band_passed(_finite("base_velocity", base_velocity, t.shape)), rate)  # fmt: skip
    return Kinematics(
        t=t,
        displacement=displacement,
        velocity=velocity,
        acceleration=acceleration,
        base_acceleration=base,
        sampling_rate_hz=float(rate),
        band_hz=band,
        valid=slice(edge, t.size - edge),
        mean_offset=offset,
    )


def measured_mean_offset(
    displacement_m: np.ndarray,
    band_limited_m: np.ndarray,
    sampling_rate_hz: float,
    band_hz: tuple[float, float],
    valid: slice,
) -> np.ndarray:
    """Slow mean of a measured displacement about its equilibrium (m).

    The slow part is what the band-pass leaves out, ``x − x'`` with ``x'`` the
    band-limited displacement, low-passed as :func:`.library.mean_offset` does
    (:func:`.library.slow_cutoff_hz`); so ``x' + offset`` is the measured
    displacement below the band's upper edge, the first periods after a release
    included, where a low-pass of ``x`` alone and the band-pass do not add up.
    Its value at zero amplitude is the equilibrium, which the sensor's zero need
    not be: the model has no constant force, so its ``x = 0`` must be the
    equilibrium. It is the intercept of the least-squares fit of the slow mean
    by ``1, a², a⁴`` (an asymmetric stiffness shifts the mean by ``−c₂ a² / (2k)``
    to leading order, a cubic one adds ``a⁴`` terms), subtracted.
    """
    cutoff = slow_cutoff_hz(band_hz)
    slow = padding.lowpass(displacement_m - band_limited_m, sampling_rate_hz, cutoff)
    squared = 2 * padding.lowpass(band_limited_m**2, sampling_rate_hz, cutoff)
    squared = squared[valid] / np.max(squared[valid])
    design = np.column_stack([np.ones_like(squared), squared, squared**2])
    equilibrium = np.linalg.lstsq(design, slow[valid], rcond=None)[0][0]
    return slow - equilibrium


def frequency_range_hz(
    response: ArrayLike, sampling_rate_hz: float, quantity: str = "displacement"
) -> tuple[float, float]:
    """Lowest and highest dominant frequency (Hz) of a response over time.

    The peak of each spectrogram segment (Hann window of about 0.2 s, peaks
    interpolated on the log magnitude), with the spectrum divided by ``ω`` once
    per derivative (``quantity``) so that the displacement's fundamental
    dominates, over the segments within :data:`PEAK_DYNAMIC_RANGE` of the
    strongest, searched within ±30 % of the record's dominant frequency, widened by
    :data:`FREQUENCY_MARGIN` on each side.

    Raises
    ------
    ValueError
        No segment holds an oscillation (the response is constant).
    """
    values = np.asarray(response, dtype=float)
    segment = min(values.size, 2 ** round(np.log2(0.2 * sampling_rate_hz)))
    frequencies, _, spectrum = signal.stft(values - values.mean(), sampling_rate_hz,
                                           nperseg=segment, detrend="linear")  # fmt: skip
    magnitude = np.abs(spectrum)
    derivatives = QUANTITIES.index(quantity) if quantity in QUANTITIES else 0
    magnitude[1:] /= (2 * np.pi * frequencies[1:, None]) ** derivatives
    magnitude[:3] = 0.0  # the slow mean and the window's leakage of it
    # Segments are searched near the record's dominant frequency: where the response has
    # decayed, leakage at low frequencies (raised by the division by ω) can otherwise win.
    dominant = np.argmax(np.sum(magnitude**2, axis=1))
    if dominant == 0:
        raise ValueError("the response does not oscillate: no band can be taken from it")
    near = (frequencies > 0.7 * frequencies[dominant]) & (frequencies < 1.3 * frequencies[dominant])
    magnitude[~near] = 0.0
    peaks = np.argmax(magnitude, axis=0)
    power = magnitude[peaks, np.arange(peaks.size)] ** 2
    keep = (power >= PEAK_DYNAMIC_RANGE * power.max()) & (peaks > 0) & (
        peaks < frequencies.size - 1)  # fmt: skip
    located = []
    for column, k in zip(np.flatnonzero(keep), peaks[keep], strict=True):
        left, mid, right = np.log(magnitude[k - 1 : k + 2, column] + 1e-300)
        bend = left - 2 * mid + right
        shift = 0.5 * (left - right) / bend if bend < 0 else 0.0
        located.append(frequencies[k] + shift * (frequencies[1] - frequencies[0]))
    return (1 - FREQUENCY_MARGIN) * min(located), (1 + FREQUENCY_MARGIN) * max(located)


def _finite(name: str, values: ArrayLike, shape: tuple[int, ...]) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.shape != shape:
        raise ValueError(f"{name} has shape {array.shape}, expected {shape} like t")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name} contains NaN or inf")
    return array


def _detrend_quadratic(values: np.ndarray) -> np.ndarray:
    s = np.linspace(-1.0, 1.0, values.size)
    return values - np.polynomial.polynomial.polyval(
        s, np.polynomial.polynomial.polyfit(s, values, 2))  # fmt: skip
