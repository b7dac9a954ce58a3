"""One hold window fitted against a clean reference phase: the hold-fit core.

A hold of a stepped-sine or phase-resonance test is fitted by least squares with a
Fourier series ``s(t) = c₀ + Re Σ_k S_k e^{ikφ(t)}`` in a reference phase ``φ``.
What that reference is decides what the harmonics mean, so it is built with care:

* **Period-averaged frequency channel.** A PLL's instantaneous-frequency channel
  carries the controller's ripple (at 2ω from the phase detector, at 1ω from an
  offset or a 2nd harmonic; a few Hz to tens of Hz on a lab loop). A Fourier basis
  in the phase integrated from that channel is phase-modulated, and a clean
  sinusoid fitted against it shows false harmonics (a 3 Hz 2ω ripple at 100 Hz puts
  about 0.7 % of "3rd harmonic" on it). The channel is therefore averaged over one
  period at every sample (:func:`period_averaged_frequency`): ripple at any multiple
  of the excitation frequency averages out, while a slow drift of the frequency
  within the hold (the PLL following the structure) is kept.
* **Cross-checked on the excitation's own fundamental.** The excitation signal's
  fundamental is fitted with a linear phase drift against that reference
  (a linearised four-parameter sine fit); where the drift is significant (the
  channel is scaled or from another clock) the reference takes it over, so the
  fit follows what drove the structure, and the offset is reported
  (:attr:`HoldFit.reference_offset_hz`) for the caller to warn about. Only in a
  settled hold: while the response amplitude still moves, the measured base
  motion's phase moves with it (the structure pushes the shaker's armature back,
  in quadrature with the drive), which is physics, not a wrong channel.
* **Spike-robust.** Laser-vibrometer dropouts put spikes of the size of the signal
  into a few samples. Samples whose residual is more than
  :data:`OUTLIER_THRESHOLD` robust standard deviations (1.4826 × the median
  absolute deviation) off the fit in either signal are dropped and the fit
  repeated until the set is stable; their number is reported.
* **Settling.** The response's fundamental is also fitted with a linear trend of
  its complex amplitude over the window: its relative change over the window
  (:attr:`HoldFit.amplitude_change`) says whether the hold had settled
  (:func:`is_settled`).

:func:`fit_hold` is a function of plain arrays (time, excitation, response,
frequency channel), whatever the excitation's kind; what the coefficients mean
physically (a base-excited backbone point, a force-driven one) is the caller's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import cumulative_trapezoid
from scipy.interpolate import CubicSpline

__all__ = [
    "OUTLIER_THRESHOLD",
    "SETTLE_TOLERANCE",
    "SIGNIFICANCE",
    "HoldFit",
    "ShortHoldError",
    "fit_hold",
    "fourier_basis",
    "hold_window",
    "is_settled",
    "period_averaged_frequency",
]

#: Robust standard deviations (1.4826 × MAD of the residual) beyond which a sample is a
#: spike. Gaussian noise exceeds 5σ in 6e-7 of the samples: about none per hold.
OUTLIER_THRESHOLD = 5.0
#: Standard errors an estimated drift (reference offset, amplitude trend) must exceed to
#: count as real rather than noise.
SIGNIFICANCE = 4.0
#: Largest relative change of the response amplitude over a window for a settled hold: a
#: response still growing by 1 % over 70 periods reads about 1 % of the damping ratio high
#: at 0.3 % damping (the amplitude's rate over ζω).
SETTLE_TOLERANCE = 0.01
#: Times the reference is refined on the excitation's fundamental at most.
_REFINEMENTS = 3
#: Relative size (of the signal's RMS) below which no departure is a spike: it could not
#: move a fit, and it keeps noise-free records from reporting dropped samples.
_SPIKE_FLOOR = 1e-6
#: Relative size (of the frequency) below which a drift is rounding.
_ROUNDING = 1e-9


class ShortHoldError(ValueError):
    """A hold phase has fewer periods than asked for."""

    def __init__(self, periods: float, n_periods: int) -> None:
        super().__init__(f"holds {periods:.1f} periods, fewer than n_periods = {n_periods}")
        self.periods = periods


@dataclass(frozen=True)
class HoldFit:
    """Fourier coefficients of one hold window and what the fit says about the hold.

    ``excitation`` and ``response`` are the complex amplitudes ``S_k`` of orders
    ``1..harmonics`` (``s = c₀ + Re Σ S_k e^{ikφ}``, in the units of the signals);
    their standard errors are those of each real component, from the fit residual.

    Attributes
    ----------
    time_s
        Centre of the window, on the clock of the ``time_s`` given.
    duration_s
        Length of the window (s).
    frequency_hz
        Mean frequency of the reference over the window (Hz).
    periods
        Whole periods of the window.
    excitation, response
        Complex amplitudes of orders ``1..harmonics``.
    excitation_standard_error, response_standard_error
        Standard error of each real component of them.
    dropped_samples
        Samples left out as spikes (in either signal).
    amplitude_change, amplitude_change_standard_error
        Relative change of the response fundamental's amplitude over the window
        (0.01: it grew by 1 % from the window's start to its end) and its standard error.
    frequency_change
        Relative change of the reference frequency over the window (the PLL's drift):
        a velocity's amplitude changes by it more than the displacement's.
    reference_offset_hz, reference_offset_standard_error_hz
        Frequency of the excitation's own fundamental minus that of the
        period-averaged channel (Hz), as the reference was refined on it (0 when the
        channel was followed as it is: it agreed, or the hold had not settled), and
        the standard error of the last estimate.
    response_mean
        The response signal's constant ``c₀`` over the window (its units).
    """

    time_s: float
    duration_s: float
    frequency_hz: float
    periods: int
    excitation: np.ndarray
    response: np.ndarray
    excitation_standard_error: np.ndarray
    response_standard_error: np.ndarray
    dropped_samples: int
    amplitude_change: float
    amplitude_change_standard_error: float
    frequency_change: float
    reference_offset_hz: float
    reference_offset_standard_error_hz: float
    response_mean: float


def is_settled(amplitude_change: float, standard_error: float) -> bool:
    """Whether an amplitude changed by at most :data:`SETTLE_TOLERANCE` over a window, or
    not significantly (:data:`SIGNIFICANCE` standard errors) more."""
    return not (
        abs(amplitude_change) > SETTLE_TOLERANCE
        and abs(amplitude_change) > SIGNIFICANCE * standard_error
    )


def period_averaged_frequency(time_s: np.ndarray, frequency_hz: np.ndarray) -> np.ndarray:
    """The frequency channel averaged over one period around every sample (Hz).

    ``f̄(t) = (1/T) ∫_{t−T/2}^{t+T/2} f dt`` with ``T`` the hold's mean period:
    ripple at any multiple of the excitation frequency averages out exactly, a
    frequency that drifts linearly is returned as it is. Within half a period of
    either end the period averaged over is the first or last one of the hold. The
    integral is interpolated by a cubic spline, so the averaging window need not
    fall on samples (linear interpolation would leave a slow beat of the ripple
    against the sampling grid).

    Raises
    ------
    ValueError
        If the channel is not positive.
    """
    if not (frequency_hz > 0).all():
        raise ValueError("the frequency channel is not positive")
    cycles = cumulative_trapezoid(frequency_hz, time_s, initial=0.0)
    span = time_s[-1] - time_s[0]
    period = span / cycles[-1]
    if span <= period:
        return np.full(time_s.shape, cycles[-1] / span)
    upper = np.clip(time_s + 0.5 * period, time_s[0] + period, time_s[-1])
    integral = CubicSpline(time_s, cycles)
    return (integral(upper) - integral(upper - period)) / period


def hold_window(
    time_s: np.ndarray, frequency_hz: np.ndarray, n_periods: int
) -> tuple[int, np.ndarray, float]:
    """The last ``n_periods`` periods of a hold: first sample, phase from 0, mean ω (rad/s).

    The phase is ``2π ∫ f̄ dt`` of the period-averaged frequency channel
    (:func:`period_averaged_frequency`), so the window spans whole periods of the
    excitation even while the PLL moves, and the controller's ripple is not in it.

    Raises
    ------
    ValueError
        If the frequency channel is not positive; :class:`ShortHoldError` if the
        hold has fewer than ``n_periods`` periods.
    """
    if not (frequency_hz > 0).all():
        raise ValueError("the frequency channel is not positive")
    channel_phase = 2 * np.pi * cumulative_trapezoid(frequency_hz, time_s, initial=0.0)
    periods = float(channel_phase[-1] / (2 * np.pi))
    if periods < n_periods:
        raise ShortHoldError(periods, n_periods)
    averaged = period_averaged_frequency(time_s, frequency_hz)
    phase = 2 * np.pi * cumulative_trapezoid(averaged, time_s, initial=0.0)
    start = int(np.searchsorted(phase, phase[-1] - 2 * np.pi * n_periods, side="right") - 1)
    phi = phase[start:] - phase[start]
    return start, phi, float(phi[-1] / (time_s[-1] - time_s[start]))


def fourier_basis(phi: np.ndarray, harmonics: int) -> np.ndarray:
    """Columns ``[1, cos kφ…, sin kφ…]`` for ``k = 1..harmonics``."""
    k = np.arange(1, harmonics + 1)
    return np.column_stack([np.ones_like(phi), np.cos(np.outer(phi, k)), np.sin(np.outer(phi, k))])


def _robust_lstsq(basis: np.ndarray, signals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares coefficients of every column of ``signals`` without its spikes.

    A spike is short: it shows in the second difference of the fit residual,
    ``r[n+1] − 2r[n] + r[n−1]`` (dropped neighbours interpolated from kept ones),
    which keeps a sample's departure from its neighbours while taking out anything
    smooth on the scale of a few samples
    (a residual the fit does not model, such as a transient or harmonics above
    the basis, changes by ``(ωΔt)² ≈ 0.004`` of itself between samples at 100
    samples per period). Samples whose second difference exceeds
    :data:`OUTLIER_THRESHOLD` robust standard deviations (1.4826 × its MAD over the
    kept samples), in any signal, are dropped, and the fit is repeated until the set
    is stable (samples are re-admitted when a refit brings them back). Below
    :data:`_SPIKE_FLOOR` of the signal's RMS nothing is a spike. Returns the
    coefficients and the mask of kept samples.
    """
    keep = np.ones(basis.shape[0], dtype=bool)
    floor = _SPIKE_FLOOR * np.sqrt(np.mean(signals**2, axis=0))
    for _ in range(10):
        coef = np.linalg.lstsq(basis[keep], signals[keep], rcond=None)[0]
        residual = signals - basis @ coef
        # Dropped neighbours are interpolated from the kept samples, so that a spike
        # between spikes, which its neighbours' spikes may hide, shows once they are
        # dropped, while a smooth residual is followed across the gap.
        around = residual.copy()
        if not keep.all():
            index = np.arange(keep.size)
            for j in range(residual.shape[1]):
                around[~keep, j] = np.interp(index[~keep], index[keep], residual[keep, j])
        curvature = np.empty_like(residual)
        curvature[1:-1] = around[2:] - 2 * residual[1:-1] + around[:-2]
        # the ends: the same stencil one sample in
        curvature[0] = residual[0] - 2 * around[1] + around[2]
        curvature[-1] = residual[-1] - 2 * around[-2] + around[-3]
        kept = curvature[keep]
        spread = 1.4826 * np.median(np.abs(kept - np.median(kept, axis=0)), axis=0)
        limit = OUTLIER_THRESHOLD * np.maximum(spread, floor)
        updated = ~(np.abs(curvature) > limit).any(axis=1)
        if (updated == keep).all():
            break
        keep = updated
    return coef, keep


def _standard_errors(design: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Standard errors of least-squares coefficients, one row per column of ``residual``."""
    dof = max(design.shape[0] - design.shape[1], 1)
    variance = np.sum(residual**2, axis=0) / dof
    return np.sqrt(np.outer(variance, np.diag(np.linalg.inv(design.T @ design))))


def _fundamental_rate(
    basis: np.ndarray, tau: np.ndarray, signal: np.ndarray, harmonics: int
) -> tuple[complex, float]:
    """Relative rate ``S₁'/S₁`` (1/s) of a signal's fundamental and its standard error.

    The fundamental is fitted as ``S₁(1 + ρτ)`` with ``τ`` the time from the window's
    centre: ``Re ρ`` is the relative growth rate of its amplitude, ``Im ρ`` the rate of
    its phase against the reference, i.e. its frequency offset (rad/s).
    """
    trend = tau[:, None] * basis[:, [1, 1 + harmonics]]
    design = np.hstack([basis, trend])
    coef = np.linalg.lstsq(design, signal, rcond=None)[0]
    fundamental = coef[1] - 1j * coef[1 + harmonics]
    if fundamental == 0:
        return complex(np.nan, np.nan), np.nan
    se = _standard_errors(design, (signal - design @ coef)[:, None])[0, -2]
    return complex(coef[-2] - 1j * coef[-1]) / fundamental, float(se / abs(fundamental))


def fit_hold(
    time_s: np.ndarray,
    excitation: np.ndarray,
    response: np.ndarray,
    frequency_hz: np.ndarray,
    n_periods: int = 70,
    harmonics: int = 3,
) -> HoldFit:
    """Fourier fit of the last ``n_periods`` periods of one hold (see the module notes).

    Parameters
    ----------
    time_s, excitation, response, frequency_hz
        Samples of the hold: time, the excitation signal (e.g. base velocity), the
        response signal (e.g. relative velocity), the instantaneous excitation
        frequency (the channel is the reference's start; a constant guess will do
        where a test has none, if it is within a fraction of a period per window).
    n_periods
        Whole periods used, counted back from the end of the hold.
    harmonics
        Orders fitted along with a constant: ``1..harmonics``. Harmonics left out of
        the basis do not bias the fundamental over whole periods, but they leak
        into it over a window that is not.

    Raises
    ------
    ValueError
        If the frequency channel is not positive; :class:`ShortHoldError` if the hold
        has fewer than ``n_periods`` periods.
    """
    start, phi, omega = hold_window(time_s, frequency_hz, n_periods)
    t = time_s[start:]
    centre = 0.5 * (t[0] + t[-1])
    tau = t - centre
    signals = np.column_stack([excitation[start:], response[start:]])
    duration = t[-1] - t[0]
    correction, offset_se = 0.0, np.nan
    for attempt in range(_REFINEMENTS + 1):
        basis = fourier_basis(phi + correction * tau, harmonics)
        coef, keep = _robust_lstsq(basis, signals)
        rate, rate_se = _fundamental_rate(basis[keep], tau[keep], signals[keep, 0], harmonics)
        offset_se = rate_se
        if attempt == 0:
            growth, growth_se = _fundamental_rate(
                basis[keep], tau[keep], signals[keep, 1], harmonics
            )
            steady = is_settled(growth.real * duration, growth_se * duration)
        drift = rate.imag
        real = abs(drift) > SIGNIFICANCE * rate_se and abs(drift) > _ROUNDING * omega
        if attempt == _REFINEMENTS or not (steady and real):
            break
        correction += drift
    errors = _standard_errors(basis[keep], signals[keep] - basis[keep] @ coef)
    growth, growth_se = _fundamental_rate(basis[keep], tau[keep], signals[keep, 1], harmonics)
    complex_amplitudes = coef[1 : 1 + harmonics] - 1j * coef[1 + harmonics :]
    # least-squares slope of the reference's phase rate over the window
    slope = np.polyfit(tau, np.gradient(phi, t), 1)[0]
    return HoldFit(
        time_s=float(centre),
        duration_s=float(duration),
        frequency_hz=(omega + correction) / (2 * np.pi),
        periods=n_periods,
        excitation=complex_amplitudes[:, 0],
        response=complex_amplitudes[:, 1],
        excitation_standard_error=errors[0, 1 : 1 + harmonics],
        response_standard_error=errors[1, 1 : 1 + harmonics],
        dropped_samples=int(keep.size - keep.sum()),
        amplitude_change=float(growth.real * duration),
        amplitude_change_standard_error=float(growth_se * duration),
        frequency_change=float(slope * duration / (omega + correction)),
        reference_offset_hz=correction / (2 * np.pi),
        reference_offset_standard_error_hz=float(offset_se / (2 * np.pi)),
        response_mean=float(coef[0, 1]),
    )
