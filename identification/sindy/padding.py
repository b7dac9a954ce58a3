"""Zero-phase filtering of records that start or end in motion: padding by linear prediction.

A free decay starts at its largest amplitude. ``scipy.signal.sosfiltfilt``
pads a record with its odd reflection about the end sample, which for an
oscillation that starts at a crest (a release from rest) continues it about
twice the crest: a step in the mean that the band-pass rings on. On a
switched-on cosine the order-8 band-pass of the pipeline is then 12 % off one
period of its lower edge into the record, 2 % after three periods and at its
pass-band error (4e-4) only after eight; the slow-mean low-pass, four times
slower, rings longer still. A decay would lose its largest amplitudes to the
trimmed edges, and what is left of the transient is read as physics by the
regression (an exact model's residual over a decay's first eighth was five
times that of the rest).

:func:`zero_phase` pads each end instead with the record's own continuation:
a least-squares linear predictor (an autoregressive model of order
:data:`PREDICTOR_ORDER`, enough for a decaying fundamental and its harmonics)
fitted to the first and last :data:`FIT_PERIODS` periods and run outwards (an
all-pole filter, ``scipy.signal.lfilter``). On the same switched-on cosine the
band-pass is then at its pass-band error from the first period on. Records that
start and end at rest (phase-resonance tests ramp up from zero) pad to near
zero either way.
"""

from __future__ import annotations

import functools

import numpy as np
from numpy.typing import ArrayLike
from scipy import signal

from identification.measurements.signals import DEFAULT_ORDER

#: Order of the linear predictor (each damped sinusoid takes two).
PREDICTOR_ORDER = 24
#: Length of record each predictor is fitted to, in periods of the filter's lowest edge.
FIT_PERIODS = 4.0
#: Length of each pad, in periods of the filter's lowest edge: longer than its transient.
PAD_PERIODS = 16.0


def zero_phase(
    values: ArrayLike, sos: np.ndarray, sampling_rate_hz: float, edge_hz: float
) -> np.ndarray:
    """``sosfiltfilt`` along the last axis with each end padded by linear prediction.

    Parameters
    ----------
    values
        Signals along the last axis (1-D or 2-D).
    sos
        The filter (second-order sections).
    sampling_rate_hz
        Sampling rate (Hz).
    edge_hz
        The filter's lowest edge (Hz): sets the pad and fit lengths.
    """
    values = np.asarray(values, dtype=float)
    rows = np.atleast_2d(values)
    period = sampling_rate_hz / edge_hz
    n_pad = int(np.ceil(PAD_PERIODS * period))
    n_fit = min(rows.shape[-1], max(int(np.ceil(FIT_PERIODS * period)), 4 * PREDICTOR_ORDER))
    padded = np.empty((rows.shape[0], rows.shape[1] + 2 * n_pad))
    for i, row in enumerate(rows):
        padded[i, :n_pad] = _predict(row[:n_fit][::-1], n_pad)[::-1]
        padded[i, n_pad:-n_pad] = row
        padded[i, -n_pad:] = _predict(row[-n_fit:], n_pad)
    filtered = signal.sosfiltfilt(sos, padded, axis=-1)[:, n_pad:-n_pad]
    return filtered.reshape(values.shape)


def bandpass(
    values: ArrayLike,
    sampling_rate_hz: float,
    band_hz: tuple[float, float],
    order: int = DEFAULT_ORDER,
) -> np.ndarray:
    """Zero-phase Butterworth band-pass along the last axis, padded by prediction."""
    edges = (float(band_hz[0]), float(band_hz[1]))
    sos = _butter(order, edges, "bandpass", sampling_rate_hz).copy()
    return zero_phase(values, sos, sampling_rate_hz, band_hz[0])


def lowpass(
    values: ArrayLike, sampling_rate_hz: float, cutoff_hz: float, order: int = DEFAULT_ORDER
) -> np.ndarray:
    """Zero-phase Butterworth low-pass along the last axis, padded by prediction."""
    sos = _butter(order, float(cutoff_hz), "lowpass", sampling_rate_hz).copy()
    return zero_phase(values, sos, sampling_rate_hz, cutoff_hz)


@functools.lru_cache(maxsize=64)
def _butter(
    order: int, edges_hz: float | tuple[float, float], btype: str, sampling_rate_hz: float
) -> np.ndarray:
    """The Butterworth design (second-order sections): the same few filters are asked for
    once per library column, and designing one takes as long as filtering a column (copied
    by the callers: scipy's filters want a writable array)."""
    return signal.butter(order, edges_hz, btype=btype, fs=float(sampling_rate_hz), output="sos")


def _predict(segment: np.ndarray, n: int) -> np.ndarray:
    """The ``n`` samples that follow ``segment`` by its least-squares linear predictor."""
    p = PREDICTOR_ORDER
    scale = float(np.max(np.abs(segment)))
    if segment.size < 2 * p or scale == 0:
        return np.zeros(n)
    lagged = np.lib.stride_tricks.sliding_window_view(segment[:-1] / scale, p)[:, ::-1]
    a = np.linalg.lstsq(lagged, segment[p:] / scale, rcond=None)[0]
    denominator = np.concatenate([[1.0], -a])
    # An unstable predictor (growing poles) would blow the pad up: pad with zeros instead.
    if np.max(np.abs(np.roots(denominator))) > 1.0 + 10.0 / n:
        return np.zeros(n)
    state = signal.lfiltic([1.0], denominator, segment[::-1][:p])
    return signal.lfilter([1.0], denominator, np.zeros(n), zi=state)[0]
