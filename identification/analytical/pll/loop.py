"""numba steps of the PLL loop shared by the one-mode and the N-mode kernels.

One implementation of what the loop does whatever the structure it drives
(:mod:`identification.analytical.pll.closed_loop` for one relative coordinate,
:mod:`identification.multimode.pll.kernel` for N modal coordinates): the layouts of
the settings, control and result vectors, the oscillator's excitation samples,
the adaptive Fourier phase detector, the lock detector at each completed period,
the measurement's quadrature in θ and the backbone point written from it. The
conventions are those of :mod:`identification.analytical.pll.closed_loop`.

The helpers are inlined into the loops, whose numba cache checks only their own
file: after editing them, ``make clean-cache``. Where the N-mode loop scales a
quantity by the target mode's weights, the one-mode loop passes a gain of 1.0,
which leaves every one-mode number bit for bit as it was.
"""

from __future__ import annotations

import numba
import numpy as np

# Layout of the settings vector (shared by all sets of a batch).
(
    _DT, _TARGET, _SENSING, _TOLERANCE, _LOCK_PERIODS, _SETTLING_TOLERANCE, _MAX_HOLD, _RAMP,
    _N_PERIODS, _X_MAX, _HARMONICS, _REFERENCE, _N_SETTINGS,
) = range(13)  # fmt: skip
# Layout of the per-set control vector.
_KP, _KI, _MU, _OMEGA_INITIAL, _OMEGA_LOW, _OMEGA_HIGH, _N_SUB, _N_CONTROL = range(8)
# Layout of a level's result row.
(
    _AMPLITUDE, _FREQUENCY, _DAMPING, _PHASE_ERROR, _LOCKED, _DIVERGED, _N_SAMPLES,
    _MEASURE_START, _N_RESULTS,
) = range(9)  # fmt: skip


@numba.njit(cache=True)
def _wrap(angle):
    """Angle in (−π, π]."""
    return angle - 2.0 * np.pi * np.ceil((angle - np.pi) / (2.0 * np.pi))


@numba.njit(cache=True)
def _ramp(a_from, a_to, samples, ramp):
    """Raised-cosine ramp from ``a_from`` to ``a_to`` over ``ramp`` samples."""
    if samples >= ramp:
        return a_to
    return a_from + (a_to - a_from) * 0.5 * (1.0 - np.cos(np.pi * samples / ramp))


@numba.njit(cache=True, inline="always")
def _loop_settings(settings, control):
    """The settings and control values a level's loop reads at every sample.

    ``(dt, target, sensing, max_hold, ramp, n_periods, x_max, harmonics, kp, ki,
    μ·dt, omega_low, omega_high, n_sub)``, counts as integers.
    """
    dt = settings[_DT]
    return (
        dt, settings[_TARGET], int(settings[_SENSING]), int(settings[_MAX_HOLD]),
        int(settings[_RAMP]), int(settings[_N_PERIODS]), settings[_X_MAX],
        int(settings[_HARMONICS]), control[_KP], control[_KI], control[_MU] * dt,
        control[_OMEGA_LOW], control[_OMEGA_HIGH], int(control[_N_SUB]),
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def _clear_result(result):
    """A level's result row before its hold: not locked, not diverged, nothing measured."""
    result[:] = np.nan
    result[_LOCKED] = 0.0
    result[_DIVERGED] = 0.0
    result[_MEASURE_START] = -1.0


@numba.njit(cache=True, inline="always")
def _excitation_samples(forcing, u, a_from, a_to, k, ramp, theta, step):
    """The excitation at the RK4 half sub-steps of sample ``k`` (phase advancing by ``step``)."""
    n_half = forcing.size - 1
    forcing[0] = u
    for j in range(1, n_half + 1):
        fraction = j / n_half
        forcing[j] = _ramp(a_from, a_to, k + fraction, ramp) * np.sin(theta + step * fraction)


@numba.njit(cache=True, inline="always")
def _detect(detector, y, s, c, harmonics, mu_dt):
    """One LMS step of the adaptive Fourier detector; the fundamental's phase.

    ``detector`` holds ``c₀, a₁, b₁, …``; ``s, c`` are ``sin θ, cos θ``; the fit is
    ``y₁ = |Y| sin(θ + phase)``.
    """
    fit = detector[0] + detector[1] * s + detector[2] * c
    sk, ck = s, c
    for i in range(3, 2 * harmonics + 1, 2):
        sk, ck = sk * c + ck * s, ck * c - sk * s
        fit += detector[i] * sk + detector[i + 1] * ck
    residual = mu_dt * (y - fit)
    detector[0] += 0.5 * residual  # the mean's gain halved: same time constant 2/μ
    detector[1] += residual * s
    detector[2] += residual * c
    sk, ck = s, c
    for i in range(3, 2 * harmonics + 1, 2):
        sk, ck = sk * c + ck * s, ck * c - sk * s
        detector[i] += residual * sk
        detector[i + 1] += residual * ck
    return np.arctan2(detector[2], detector[1])


@numba.njit(cache=True, inline="always")
def _record_loop(record, row, k, u, amplitude, c, theta, omega, phase, settings):
    """The loop's channels of sample ``k``, in rows ``row`` to ``row + 5``.

    The excitation ``u = A sin θ``, its quasi-static integral ``−A cos θ / ω``, the
    frequency (Hz), θ, the detector's phase against the configured reference
    (deg) and the commanded level ``A``.
    """
    record[row, k] = u
    record[row + 1, k] = -amplitude * c / omega
    record[row + 2, k] = omega / (2.0 * np.pi)
    record[row + 3, k] = theta
    record[row + 4, k] = np.degrees(_wrap(phase - settings[_REFERENCE]))
    record[row + 5, k] = amplitude


@numba.njit(cache=True, inline="always")
def _lock_step(settings, control, detector, error, gain, amplitude, omega, magnitude_previous,
               measuring, locked_count):  # fmt: skip
    """The lock detector at a completed oscillator period.

    The period is good when the phase error is within tolerance, the frequency
    inside its limits and the detector's magnitude settled against the damping
    ratio of the power balance ``gain · A ω^s / (2ω² |Y|)`` (``gain`` 1 for one
    mode). Returns ``(measuring, locked_count, magnitude, start)``: a bad period
    stops a measurement, ``lock_periods`` good ones in a row start one
    (``start``).
    """
    sensing = int(settings[_SENSING])
    omega_low, omega_high = control[_OMEGA_LOW], control[_OMEGA_HIGH]
    magnitude = np.hypot(detector[1], detector[2])
    damping = gain * amplitude * omega**sensing / (2.0 * omega**2 * magnitude)
    change = abs(magnitude - magnitude_previous) / magnitude
    steady = change <= settings[_SETTLING_TOLERANCE] * 2.0 * np.pi * damping
    ok = abs(error) <= settings[_TOLERANCE] and steady and omega_low < omega < omega_high
    start = False
    if measuring and not ok:
        measuring = False
        locked_count = 0
    elif not measuring:
        locked_count = locked_count + 1 if ok else 0
        if locked_count >= int(settings[_LOCK_PERIODS]):
            measuring = True
            start = True
    return measuring, locked_count, magnitude, start


@numba.njit(cache=True, inline="always")
def _measure_step(omega, dt, remaining, duration, c, s):
    """One sample of the measurement: a left Riemann sum in θ over exactly ``n_periods``.

    Returns ``(step, remaining, duration, rotation, done)``, ``step`` the phase
    advance counted (cut to what remains) and ``rotation = e^{−iθ} step``.
    """
    step = omega * dt
    done = False
    if step >= remaining:
        step = remaining
        done = True
    remaining -= step
    duration += step / omega
    return step, remaining, duration, complex(c, -s) * step, done


@numba.njit(cache=True, inline="always")
def _close_level(result, n_samples, done, amplitude_m, gain, q_base, q_y, duration, n_periods,
                 target, error):  # fmt: skip
    """Write a level's backbone point (when measured) or its last phase error.

    ``q_base``, ``q_y`` are the quadratures ``Σ u e^{−iθ} dθ``, ``Σ y e^{−iθ} dθ`` of the
    excitation and the sensed signal; the damping ratio is the power balance
    ``gain · |Q_b| / (2 |Q|)`` with ``amplitude_m = |Q|``.
    """
    result[_N_SAMPLES] = n_samples
    if done:
        frequency = n_periods / duration
        amplitude_base = abs(q_base) / (np.pi * n_periods) / (2.0 * np.pi * frequency) ** 2
        result[_AMPLITUDE] = amplitude_m
        result[_FREQUENCY] = frequency
        result[_DAMPING] = gain * amplitude_base / (2.0 * amplitude_m)
        phase_difference = np.arctan2(q_y.imag, q_y.real) - np.arctan2(q_base.imag, q_base.real)
        result[_PHASE_ERROR] = np.degrees(_wrap(phase_difference - target))
        result[_LOCKED] = 1.0
    elif result[_DIVERGED] == 0.0:
        result[_PHASE_ERROR] = np.degrees(error)
