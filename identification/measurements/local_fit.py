"""Local fits of a decaying, chirping multi-harmonic signal over a window of a few periods.

In a window centred at ``t_c`` (``τ = t − t_c``) a signal of a lightly damped
nonlinear oscillator is, to second order in the window's length,

    s(τ) = m₀ + m₁ τ + Re Σ_{k=1..H} S_k e^{−kστ} e^{ik(ωτ + βτ²/2)}

with ``ω`` the instantaneous angular frequency at the centre, ``β = dω/dt`` its
drift (a decaying softening oscillator speeds up), ``σ = −d ln|S₁|/dt`` the
fundamental's decay rate (harmonic ``k`` of a polynomial restoring force scales
like the ``k``-th power of the amplitude, so it decays ``k`` times as fast),
``S_k`` the complex amplitudes at the centre in the convention
``a cos kφ + b sin kφ = Re((a − ib) e^{ikφ})`` of the hold fits, and ``m₀ + m₁τ``
the slowly moving mean (a displacement's offset). The ``2 + 2H`` amplitudes
enter linearly and ``(ω, β, σ)`` nonlinearly; all are fitted together by
Gauss–Newton with step halving, started from the previous window or from the
peak of a zero-padded Hann spectrum, and their standard errors come from the
Jacobian at the optimum (white-noise assumption: adequate for telling a signal
from the noise floor, optimistic for coloured noise).

Compared with the Hilbert transform, which needs a band-pass to isolate the
fundamental and whose instantaneous frequency and amplitude oscillate at 2ω
when the signal carries harmonics or a mean, the local fit measures the
fundamental, its harmonics and the mean in one step and leaves nothing to
average out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal as sps

from identification.measurements.decay_components import fit_components

__all__ = ["LocalFit", "dominant_frequency_hz", "fit_window"]

#: Zero padding of the spectrum that starts a fit (times the segment length).
_PADDING = 16


@dataclass(frozen=True)
class LocalFit:
    """One window's fit (see the module notes for the model).

    Attributes
    ----------
    centre_s
        Time of the window's centre (s).
    frequency_hz
        ``ω / 2π`` at the centre (Hz).
    chirp_hz_s
        ``β / 2π``: drift of the frequency (Hz/s).
    decay_rate_1_s
        ``σ``: decay rate of the fundamental's amplitude (1/s; negative when it grows).
    phasors
        ``S_k`` at the centre, ``k = 1..H`` (units of the signal).
    phasor_standard_error
        Standard error of the real and of the imaginary part of each ``S_k``.
    mean
        ``m₀``: the window's mean at its centre.
    mean_standard_error
        Standard error of ``m₀``.
    frequency_standard_error_hz, chirp_standard_error_hz_s, decay_rate_standard_error_1_s
        Standard errors of the nonlinear parameters.
    residual_rms
        RMS of the residual.
    n_samples
        Samples in the window.
    converged
        Whether Gauss–Newton met its tolerance.
    """

    centre_s: float
    frequency_hz: float
    chirp_hz_s: float
    decay_rate_1_s: float
    phasors: np.ndarray
    phasor_standard_error: np.ndarray
    mean: float
    mean_standard_error: float
    frequency_standard_error_hz: float
    chirp_standard_error_hz_s: float
    decay_rate_standard_error_1_s: float
    residual_rms: float
    n_samples: int
    converged: bool

    @property
    def omega(self) -> float:
        """Angular frequency at the centre (rad/s)."""
        return 2 * math.pi * self.frequency_hz

    @property
    def rates(self) -> np.ndarray:
        """Complex rates ``λ_k = k(−σ + iω)`` of the harmonics at the centre (1/s)."""
        k = np.arange(1, self.phasors.size + 1)
        return k * (-self.decay_rate_1_s + 1j * self.omega)

    @property
    def relative_amplitude_error(self) -> float:
        """Standard error of ``|S₁|`` over ``|S₁|``: how far above the noise the window is."""
        return float(self.phasor_standard_error[0] / max(abs(self.phasors[0]), 1e-300))


def dominant_frequency_hz(
    values: np.ndarray, sampling_rate_hz: float, band_hz: tuple[float, float] | None = None
) -> float:
    """Frequency (Hz) of the highest peak of a zero-padded Hann spectrum, within ``band_hz``.

    The mean and a linear trend are removed first; the peak is refined by a
    parabola through the log-magnitudes of its three bins.
    """
    detrended = sps.detrend(np.asarray(values, dtype=float))
    n = detrended.size
    spectrum = np.abs(np.fft.rfft(detrended * np.hanning(n), _PADDING * n))
    freqs = np.fft.rfftfreq(_PADDING * n, 1.0 / sampling_rate_hz)
    low, high = band_hz if band_hz is not None else (freqs[1], freqs[-1])
    inside = np.flatnonzero((freqs >= low) & (freqs <= high) & (freqs > 0))
    if inside.size < 3 or not np.any(spectrum[inside] > 0):
        raise ValueError(
            f"no oscillation found between {low:.4g} and {high:.4g} Hz (the signal is flat)"
        )
    i = int(inside[np.argmax(spectrum[inside])])
    if 0 < i < spectrum.size - 1 and np.all(spectrum[i - 1 : i + 2] > 0):
        left, centre, right = np.log(spectrum[i - 1 : i + 2])
        curvature = left - 2 * centre + right
        shift = 0.5 * (left - right) / curvature if curvature < 0 else 0.0
        return float(freqs[i] + np.clip(shift, -0.5, 0.5) * (freqs[1] - freqs[0]))
    return float(freqs[i])


def fit_window(
    time_s: np.ndarray,
    values: np.ndarray,
    centre_s: float,
    omega: float,
    *,
    beta: float = 0.0,
    sigma: float = 0.0,
    harmonics: int = 3,
) -> LocalFit:
    """Fit the module's model to the samples of one window: the one-mode case of
    :func:`~identification.measurements.decay_components.fit_components`.

    Parameters
    ----------
    time_s, values
        The window's samples (s, signal units).
    centre_s
        The window's centre (s); the fitted quantities are its values there.
    omega, beta, sigma
        Starting angular frequency (rad/s), its drift (rad/s²) and decay rate (1/s).
    harmonics
        ``H``: harmonics fitted with the fundamental (≥ 1).

    Raises
    ------
    ValueError
        Too few samples for the model, or a singular fit (a flat window).
    """
    fit = fit_components(time_s, values, centre_s, np.array([[omega, beta, sigma]]),
                         [tuple(range(1, harmonics + 1))])  # fmt: skip
    se = fit.nonlinear_standard_error[0]
    return LocalFit(
        centre_s=fit.centre_s,
        frequency_hz=float(fit.omega[0] / (2 * math.pi)),
        chirp_hz_s=float(fit.beta[0] / (2 * math.pi)),
        decay_rate_1_s=float(fit.sigma[0]),
        phasors=fit.phasors[0],
        phasor_standard_error=fit.phasor_standard_error[0],
        mean=fit.mean,
        mean_standard_error=fit.mean_standard_error,
        frequency_standard_error_hz=float(se[0] / (2 * math.pi)),
        chirp_standard_error_hz_s=float(se[1] / (2 * math.pi)),
        decay_rate_standard_error_1_s=float(se[2]),
        residual_rms=fit.residual_rms,
        n_samples=fit.n_samples,
        converged=fit.converged,
    )
