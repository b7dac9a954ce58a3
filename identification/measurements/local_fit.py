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

__all__ = ["LocalFit", "dominant_frequency_hz", "fit_window"]

#: Gauss–Newton iterations per window at most.
_MAX_ITERATIONS = 40
#: Relative change of the residual sum of squares that ends the iterations.
_TOLERANCE = 1e-12
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


def _columns(tau, omega, beta, sigma, harmonics):
    """Basis ``[1, τ, E_k cos kφ…, E_k sin kφ…]`` and the pieces its derivatives need."""
    k = np.arange(1, harmonics + 1)
    phase = np.outer(omega * tau + 0.5 * beta * tau**2, k)
    envelope = np.exp(-np.outer(tau, k) * sigma)
    cos, sin = envelope * np.cos(phase), envelope * np.sin(phase)
    basis = np.column_stack([np.ones_like(tau), tau, cos, sin])
    return basis, cos, sin, k


def _jacobian(tau, linear, cos, sin, k, basis):
    """Model derivatives: the basis, then ∂/∂ω, ∂/∂β, ∂/∂σ."""
    h = k.size
    a, b = linear[2 : 2 + h], linear[2 + h :]
    quadrature = (-sin * a + cos * b) * k  # ∂/∂(phase) of Σ a cos + b sin, per unit of φ
    in_phase = (cos * a + sin * b) * k
    d_omega = tau * quadrature.sum(axis=1)
    d_beta = 0.5 * tau**2 * quadrature.sum(axis=1)
    d_sigma = -tau * in_phase.sum(axis=1)
    return np.column_stack([basis, d_omega, d_beta, d_sigma])


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
    """Fit the module's model to the samples of one window.

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
    tau = np.asarray(time_s, dtype=float) - centre_s
    y = np.asarray(values, dtype=float)
    n_linear = 2 + 2 * harmonics
    n_params = n_linear + 3
    if y.size <= 2 * n_params:
        raise ValueError(f"a window of {y.size} samples is too short for {n_params} parameters")
    nonlinear = np.array([omega, beta, sigma], dtype=float)
    basis, cos, sin, k = _columns(tau, *nonlinear, harmonics)
    linear = np.linalg.lstsq(basis, y, rcond=None)[0]
    rss = float(np.sum((y - basis @ linear) ** 2))
    converged = False
    for _ in range(_MAX_ITERATIONS):
        jac = _jacobian(tau, linear, cos, sin, k, basis)
        norms = np.linalg.norm(jac, axis=0)
        norms[norms == 0] = 1.0
        step = np.linalg.lstsq(jac / norms, y - basis @ linear, rcond=None)[0] / norms
        for _halving in range(30):
            trial_nonlinear = nonlinear + step[n_linear:]
            trial = _columns(tau, *trial_nonlinear, harmonics)
            trial_linear = linear + step[:n_linear]
            trial_rss = float(np.sum((y - trial[0] @ trial_linear) ** 2))
            if trial_rss <= rss:
                break
            step = 0.5 * step
        else:
            converged = True  # no step lowers the residual: at the optimum to rounding
            break
        done = rss - trial_rss <= _TOLERANCE * rss
        nonlinear, linear, rss = trial_nonlinear, trial_linear, trial_rss
        basis, cos, sin, k = trial
        if done:
            converged = True
            break
    jac = _jacobian(tau, linear, cos, sin, k, basis)
    dof = max(y.size - n_params, 1)
    variance = rss / dof
    try:
        covariance = variance * np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        raise ValueError("singular window fit (the window is flat or too short)") from None
    se = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    h = harmonics
    phasors = linear[2 : 2 + h] - 1j * linear[2 + h :]
    phasor_se = np.sqrt(0.5 * (se[2 : 2 + h] ** 2 + se[2 + h : n_linear] ** 2))
    return LocalFit(
        centre_s=float(centre_s),
        frequency_hz=float(nonlinear[0] / (2 * math.pi)),
        chirp_hz_s=float(nonlinear[1] / (2 * math.pi)),
        decay_rate_1_s=float(nonlinear[2]),
        phasors=phasors,
        phasor_standard_error=phasor_se,
        mean=float(linear[0]),
        mean_standard_error=float(se[0]),
        frequency_standard_error_hz=float(se[n_linear] / (2 * math.pi)),
        chirp_standard_error_hz_s=float(se[n_linear + 1] / (2 * math.pi)),
        decay_rate_standard_error_1_s=float(se[n_linear + 2]),
        residual_rms=math.sqrt(rss / y.size),
        n_samples=int(y.size),
        converged=converged,
    )
