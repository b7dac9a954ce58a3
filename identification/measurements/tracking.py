"""The instantaneous frequency of a record that has no controller frequency channel.

Hold fits follow the phase ``2π ∫ f dt`` of a frequency channel
(:mod:`identification.measurements.extraction`); files from a signal generator
or a shaker controller often hold the excitation alone. :func:`frequency_track`
measures the frequency along the record by local fits of the signal
(:func:`identification.measurements.local_fit.fit_window`, fundamental only):
windows of ``window_periods`` periods, half a window apart, each started from
the previous one, or from the window's spectrum after a jump (a stepped-sine
step) or a stretch without signal; between window centres the frequency is
interpolated linearly and held beyond the first and last.
"""

from __future__ import annotations

import math

import numpy as np

from identification.measurements.local_fit import dominant_frequency_hz, fit_window

__all__ = ["frequency_track"]

#: A window whose fundamental has a larger relative standard error holds no signal.
_SIGNAL_LIMIT = 0.05


def frequency_track(
    time_s: np.ndarray,
    values: np.ndarray,
    *,
    window_periods: float = 10.0,
    band_hz: tuple[float, float] | None = None,
) -> np.ndarray:
    """Instantaneous frequency (Hz) of ``values`` at every sample (see the module notes).

    Raises
    ------
    ValueError
        When no window holds an oscillation.
    """
    t = np.asarray(time_s, dtype=float)
    y = np.asarray(values, dtype=float)
    rate = (t.size - 1) / (t[-1] - t[0])
    head = y[: min(y.size, int(rate))]
    frequency = dominant_frequency_hz(head if np.any(head - head[0]) else y, rate, band_hz)
    centres, found = [], []
    centre = t[0] + 0.5 * window_periods / frequency
    omega = None
    while True:
        half = 0.5 * window_periods / frequency
        if centre + half > t[-1]:
            break
        a, b = np.searchsorted(t, [centre - half, centre + half])
        window = y[a:b]
        fit = None
        if b - a > 20 and np.any(window != window[0]):
            start = omega if omega is not None else 2 * math.pi * dominant_frequency_hz(
                window, rate, band_hz)  # fmt: skip
            try:
                fit = fit_window(t[a:b], window, centre, start, harmonics=1)
            except ValueError:
                fit = None
        good = (
            fit is not None
            and fit.converged
            and fit.frequency_hz > 0
            and fit.relative_amplitude_error < _SIGNAL_LIMIT
            and (band_hz is None or band_hz[0] <= fit.frequency_hz <= band_hz[1])
        )
        if good:
            centres.append(centre)
            found.append(fit.frequency_hz)
            frequency, omega = fit.frequency_hz, fit.omega
        else:
            omega = None  # the next window starts from its own spectrum
        centre += half
    if not found:
        raise ValueError("no oscillation to measure a frequency from")
    return np.interp(t, centres, found)
