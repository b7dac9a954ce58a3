"""The PLL loop shared by the one-mode and the N-mode simulators.

One implementation of what the loop does whatever the structure it drives
(:mod:`identification.analytical.pll.closed_loop` for one relative coordinate,
:mod:`identification.multimode.pll.kernel` for N modal coordinates): the layouts of
the settings, control, state and result vectors, the oscillator's excitation
samples, the adaptive Fourier phase detector, the PI controller, the lock detector
at each completed period, the measurement's quadrature in θ and the backbone point
written from it (numba, inlined into the structures' kernels); and on the Python
side the settings and control vectors of a :class:`PLLConfig` and the level-by-level
recorded run. The conventions are those of
:mod:`identification.analytical.pll.closed_loop`.

The numba helpers are inlined into the kernels, whose numba cache checks only their
own file: after editing them, ``make clean-cache``. Where the N-mode loop scales a
quantity by the target mode's weights, the one-mode loop passes a gain of 1.0,
which leaves every one-mode number bit for bit as it was.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from identification.analytical.pll.config import (
    _FORCE_VS_EXCITATION_DEG,
    _REFERENCE_VS_FORCE_DEG,
    _RESONANT_PHASE_VS_FORCE_DEG,
    SENSING,
    PLLConfig,
    _pole_placement,
)

# Layout of the settings vector (shared by all sets of a batch).
(
    DT, TARGET, SENSING_INDEX, TOLERANCE, LOCK_PERIODS, SETTLING_TOLERANCE, MAX_HOLD, RAMP,
    N_PERIODS, X_MAX, HARMONICS, REFERENCE, N_SETTINGS,
) = range(13)  # fmt: skip
# Layout of the per-set control vector.
KP, KI, MU, OMEGA_INITIAL, OMEGA_LOW, OMEGA_HIGH, N_SUB, N_CONTROL = range(8)
# Layout of a level's result row (the N-mode loop appends its modes' coefficients).
(
    AMPLITUDE, FREQUENCY, DAMPING, PHASE_ERROR, LOCKED, DIVERGED, N_SAMPLES, MEASURE_START,
    N_RESULTS,
) = range(9)  # fmt: skip
# Layout of the per-run state vector: the oscillator and controller (carried from level
# to level), the lock detector and measurement of the level being held, the detector's
# 1 + 2·harmonics coefficients, then the structure's own state.
(
    THETA, OMEGA, INTEGRAL, CONTROL_ON, NEXT_BOUNDARY, MAGNITUDE, LOCKED_COUNT, MEASURING,
    REMAINING, DURATION, DETECTOR,
) = range(11)  # fmt: skip


@numba.njit(cache=True)
def wrap_angle(angle):
    """Angle in (−π, π]."""
    return angle - 2.0 * np.pi * np.ceil((angle - np.pi) / (2.0 * np.pi))


@numba.njit(cache=True)
def ramp_level(a_from, a_to, samples, ramp):
    """Raised-cosine ramp from ``a_from`` to ``a_to`` over ``ramp`` samples."""
    if samples >= ramp:
        return a_to
    return a_from + (a_to - a_from) * 0.5 * (1.0 - np.cos(np.pi * samples / ramp))


@numba.njit(cache=True, inline="always")
def level_settings(settings, control):
    """``(dt, sensing, x_max, ramp, max_hold, n_sub)`` of a level's loop, counts as integers."""
    return (
        settings[DT], int(settings[SENSING_INDEX]), settings[X_MAX], int(settings[RAMP]),
        int(settings[MAX_HOLD]), int(control[N_SUB]),
    )  # fmt: skip


@numba.njit(cache=True)
def initial_state(omega, harmonics, n_structure):
    """State vector at rest: oscillator and controller at ``omega``, the rest zero.

    ``n_structure`` values of the structure's own state follow the detector.
    """
    state = np.zeros(DETECTOR + 1 + 2 * harmonics + n_structure)
    state[OMEGA] = omega
    state[INTEGRAL] = omega
    return state


@numba.njit(cache=True, inline="always")
def clear_levels(out):
    """Result rows ``(n_levels, row size)`` before a run: nothing locked, all NaN."""
    out[:] = np.nan
    out[:, LOCKED] = 0.0


@numba.njit(cache=True, inline="always")
def start_level(settings, state, result):
    """Before a level's ramp: a cleared result row and lock detector.

    Returns ``(detector, offset)``: the detector's coefficients (a view of
    ``state``) and where the structure's state starts in ``state``.
    """
    result[:] = np.nan
    result[LOCKED] = 0.0
    result[DIVERGED] = 0.0
    result[MEASURE_START] = -1.0
    state[NEXT_BOUNDARY] = np.inf
    state[MAGNITUDE] = -1.0
    state[LOCKED_COUNT] = 0.0
    state[MEASURING] = 0.0
    state[REMAINING] = 0.0
    state[DURATION] = 0.0
    offset = DETECTOR + 1 + 2 * int(settings[HARMONICS])
    return state[DETECTOR:offset], offset


@numba.njit(cache=True, inline="always")
def oscillator(state, a_from, a_to, k, ramp):
    """Sample ``k``'s oscillator: ``(θ, sin θ, cos θ, A)``, ``A`` the ramped level."""
    theta = state[THETA]
    return theta, np.sin(theta), np.cos(theta), ramp_level(a_from, a_to, k, ramp)


@numba.njit(cache=True, inline="always")
def excitation_samples(forcing, u, a_from, a_to, k, ramp, theta, step):
    """The excitation at the RK4 half sub-steps of sample ``k`` (phase advancing by ``step``)."""
    n_half = forcing.size - 1
    forcing[0] = u
    for j in range(1, n_half + 1):
        fraction = j / n_half
        forcing[j] = ramp_level(a_from, a_to, k + fraction, ramp) * np.sin(theta + step * fraction)


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
def record_loop(record, row, k, u, amplitude, c, theta, omega, phase, settings):
    """The loop's channels of sample ``k``, in rows ``row`` to ``row + 5``.

    The excitation ``u = A sin θ``, its quasi-static integral ``−A cos θ / ω``, the
    frequency (Hz), θ, the detector's phase against the configured reference
    (deg) and the commanded level ``A``.
    """
    record[row, k] = u
    record[row + 1, k] = -amplitude * c / omega
    record[row + 2, k] = omega / (2.0 * np.pi)
    record[row + 3, k] = theta
    record[row + 4, k] = np.degrees(wrap_angle(phase - settings[REFERENCE]))
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
    sensing = int(settings[SENSING_INDEX])
    omega_low, omega_high = control[OMEGA_LOW], control[OMEGA_HIGH]
    magnitude = np.hypot(detector[1], detector[2])
    damping = gain * amplitude * omega**sensing / (2.0 * omega**2 * magnitude)
    change = abs(magnitude - magnitude_previous) / magnitude
    steady = change <= settings[SETTLING_TOLERANCE] * 2.0 * np.pi * damping
    ok = abs(error) <= settings[TOLERANCE] and steady and omega_low < omega < omega_high
    start = False
    if measuring and not ok:
        measuring = False
        locked_count = 0
    elif not measuring:
        locked_count = locked_count + 1 if ok else 0
        if locked_count >= int(settings[LOCK_PERIODS]):
            measuring = True
            start = True
    return measuring, locked_count, magnitude, start


@numba.njit(cache=True, inline="always")
def loop_step(settings, control, state, detector, result, k, y, s, c, amplitude, gain):
    """Detector, controller, lock detector and measurement at sample ``k``.

    ``y`` is the sensed signal, ``amplitude`` the commanded level, ``gain`` the lock
    detector's (1.0 for one mode). Advances the loop's part of ``state``. Returns
    ``(phase, error, start, measuring, step, rotation, done)``: the detector's phase
    and the wrapped phase error; whether a measurement starts at this sample
    (restart the quadratures) and whether this sample is measured, with the phase
    advance counted (cut to what remains of ``n_periods`` periods), ``e^{−iθ}`` times
    it (a left Riemann sum in θ) and whether the measurement is complete.
    """
    dt = settings[DT]
    phase = _detect(detector, y, s, c, int(settings[HARMONICS]), control[MU] * dt)
    error = wrap_angle(phase - settings[TARGET])

    # PI controller with anti-windup at the frequency limits.
    omega = state[OMEGA]
    if state[CONTROL_ON] > 0.0:
        omega_low, omega_high = control[OMEGA_LOW], control[OMEGA_HIGH]
        integral = min(max(state[INTEGRAL] + control[KI] * error * dt, omega_low), omega_high)
        omega = min(max(integral + control[KP] * error, omega_low), omega_high)
        state[INTEGRAL] = integral
        state[OMEGA] = omega

    ramp = int(settings[RAMP])
    theta = state[THETA]
    measuring = state[MEASURING] > 0.0
    start = False
    if k == ramp:  # the hold starts; the first level's controller switches on here
        state[CONTROL_ON] = 1.0
        state[NEXT_BOUNDARY] = theta + 2.0 * np.pi
    elif k > ramp and theta >= state[NEXT_BOUNDARY]:  # a period completed: lock detector
        state[NEXT_BOUNDARY] += 2.0 * np.pi
        measuring, locked_count, magnitude, start = _lock_step(
            settings, control, detector, error, gain, amplitude, omega, state[MAGNITUDE],
            measuring, int(state[LOCKED_COUNT]),
        )  # fmt: skip
        state[MEASURING] = 1.0 if measuring else 0.0
        state[LOCKED_COUNT] = locked_count
        state[MAGNITUDE] = magnitude
        if start:
            state[REMAINING] = 2.0 * np.pi * int(settings[N_PERIODS])
            state[DURATION] = 0.0
            result[MEASURE_START] = k

    step = 0.0
    done = False
    if measuring:
        step = omega * dt
        if step >= state[REMAINING]:
            step = state[REMAINING]
            done = True
        state[REMAINING] -= step
        state[DURATION] += step / omega
    return phase, error, start, measuring, step, complex(c, -s) * step, done


@numba.njit(cache=True, inline="always")
def close_level(settings, state, result, n_samples, done, amplitude_m, gain, q_base, q_y, error):
    """Write a level's backbone point (when measured) or its last phase error.

    ``q_base``, ``q_y`` are the quadratures ``Σ u e^{−iθ} dθ``, ``Σ y e^{−iθ} dθ`` of the
    excitation and the sensed signal; the damping ratio is the power balance
    ``gain · |Q_b| / (2 |Q|)`` with ``amplitude_m = |Q|``.
    """
    result[N_SAMPLES] = n_samples
    if done:
        n_periods = int(settings[N_PERIODS])
        frequency = n_periods / state[DURATION]
        amplitude_base = abs(q_base) / (np.pi * n_periods) / (2.0 * np.pi * frequency) ** 2
        result[AMPLITUDE] = amplitude_m
        result[FREQUENCY] = frequency
        result[DAMPING] = gain * amplitude_base / (2.0 * amplitude_m)
        phase_difference = np.arctan2(q_y.imag, q_y.real) - np.arctan2(q_base.imag, q_base.real)
        result[PHASE_ERROR] = np.degrees(wrap_angle(phase_difference - settings[TARGET]))
        result[LOCKED] = 1.0
    elif result[DIVERGED] == 0.0:
        result[PHASE_ERROR] = np.degrees(error)


# --------------------------------------------------------------------------
# Python side: the settings and control vectors, the recorded run.

#: Fewest samples per period at the highest frequency the oscillator may reach.
_MIN_SAMPLES_PER_PERIOD = 10


def settings_vector(config: PLLConfig) -> np.ndarray:
    """The settings vector of ``config`` (``N_SETTINGS``), for the one-mode force ``−a_base``."""
    settings = np.zeros(N_SETTINGS)
    excitation = _FORCE_VS_EXCITATION_DEG
    settings[DT] = 1.0 / config.fs
    settings[TARGET] = np.radians(
        _RESONANT_PHASE_VS_FORCE_DEG[config.sensing] + excitation
    )  # detector phases are against a_base = A sin θ
    settings[SENSING_INDEX] = SENSING.index(config.sensing)
    settings[TOLERANCE] = np.radians(config.lock_tolerance_deg)
    settings[LOCK_PERIODS] = config.lock_periods
    settings[SETTLING_TOLERANCE] = config.settling_tolerance
    settings[MAX_HOLD] = round(config.max_hold_s * config.fs)
    settings[RAMP] = round(config.ramp_s * config.fs)
    settings[N_PERIODS] = config.n_periods
    settings[X_MAX] = config.max_displacement_m
    settings[HARMONICS] = config.harmonics
    settings[REFERENCE] = np.radians(_REFERENCE_VS_FORCE_DEG[config.reference] + excitation)
    return settings


def control_vector(
    config: PLLConfig,
    stiffness: np.ndarray,
    damping: np.ndarray,
    n_sub: np.ndarray,
    too_stiff: Callable[[int], str],
) -> np.ndarray:
    """Per-set gains, frequency range and sub-steps, ``(n_sets, N_CONTROL)``.

    ``stiffness`` and ``damping`` are the locked mode's small-amplitude stiffness
    (ω², 1/s²) and viscous damping (2ζω, 1/s) per set, ``n_sub`` its RK4 sub-steps
    per sample; ``too_stiff(n)`` says why a set needing ``n`` sub-steps (more than
    ``config.max_substeps``) is refused.
    """
    n_sets = len(n_sub)
    with np.errstate(invalid="ignore"):
        omega_linear = np.where(stiffness > 0, np.sqrt(np.abs(stiffness)), np.nan)
    if config.initial_frequency_hz is not None:
        omega_initial = np.full(n_sets, 2.0 * np.pi * config.initial_frequency_hz)
    else:
        omega_initial = omega_linear
    control = np.zeros((n_sets, N_CONTROL))
    if config.gains is None:
        # Design at the resonance the loop starts on; σ = c/2 from the viscous term.
        omega_design = np.where(np.isfinite(omega_linear), omega_linear, omega_initial)
        kp, ki, bandwidth = _pole_placement(
            omega_design, 0.5 * damping / omega_design, config.bandwidth_ratio
        )
    else:
        kp, ki, bandwidth = config.gains.kp, config.gains.ki, config.gains.detector_bandwidth
    control[:, KP] = kp
    control[:, KI] = ki
    control[:, MU] = 2.0 * np.asarray(bandwidth)
    control[:, OMEGA_INITIAL] = omega_initial
    control[:, OMEGA_LOW] = config.frequency_limits[0] * omega_initial
    control[:, OMEGA_HIGH] = config.frequency_limits[1] * omega_initial
    worst = int(np.argmax(n_sub))
    if n_sub[worst] > config.max_substeps:
        raise ValueError(
            ("" if n_sets == 1 else f"parameter set {worst}: ") + too_stiff(int(n_sub[worst]))
        )
    control[:, N_SUB] = n_sub
    if config.gains is None:
        # Sets with no resonance to design for have nothing to lock on.
        control[~np.isfinite(control[:, KP]), OMEGA_INITIAL] = np.nan
    return control


def check_timing(config: PLLConfig, control: np.ndarray) -> None:
    """The hold must fit the lock and measurement periods, the sampling the frequencies."""
    omega = control[:, OMEGA_INITIAL]
    omega = omega[np.isfinite(omega)]
    if omega.size == 0:
        return
    needed = (config.lock_periods + config.n_periods) * 2.0 * np.pi / omega.min()
    if config.max_hold_s < needed:
        raise ValueError(
            f"PLLConfig.max_hold_s = {config.max_hold_s} s is shorter than lock_periods + "
            f"n_periods = {config.lock_periods + config.n_periods} periods ({needed:.3g} s)"
        )
    highest_hz = config.frequency_limits[1] * omega.max() / (2.0 * np.pi)
    if config.fs < _MIN_SAMPLES_PER_PERIOD * highest_hz:
        raise ValueError(
            f"PLLConfig.fs = {config.fs} Hz gives fewer than {_MIN_SAMPLES_PER_PERIOD} samples "
            f"per period at {highest_hz:.4g} Hz (frequency_limits × initial frequency)"
        )


@dataclass(frozen=True)
class RecordedLevels:
    """The samples of a recorded run, level after level, and where each level's hold and
    measurement lie in them (``(start, end)`` sample indices, -1 where there is none)."""

    samples: np.ndarray
    level_index: np.ndarray
    holds: np.ndarray
    measurements: np.ndarray


def record_levels(
    run: Callable[[float, float, np.ndarray, np.ndarray], None] | None,
    excitation_m_s2: np.ndarray,
    out: np.ndarray,
    n_rows: int,
    settings: np.ndarray,
) -> RecordedLevels:
    """Run ``run(a_from, a_to, buffer, out_row)`` level by level, keeping the ``n_rows``
    channels it writes into ``buffer``; None runs nothing (no initial frequency). Stops
    after a level that diverged. Shared by the one-mode and the N-mode recorded runs."""
    clear_levels(out)
    n_levels = excitation_m_s2.size
    holds = np.full((n_levels, 2), -1, dtype=np.int64)
    measurements = np.full((n_levels, 2), -1, dtype=np.int64)
    pieces, indices = [], []
    ramp, max_hold = int(settings[RAMP]), int(settings[MAX_HOLD])
    if run is not None:
        buffer = np.empty((n_rows, ramp + max_hold + 1))
        start, a_from = 0, 0.0
        for j, a_to in enumerate(excitation_m_s2):
            run(a_from, a_to, buffer, out[j])
            n = int(out[j, N_SAMPLES])
            pieces.append(buffer[:, :n].copy())
            indices.append(np.full(n, j, dtype=np.int64))
            if n > ramp:
                holds[j] = start + ramp, start + n
            if out[j, LOCKED] > 0:
                measurements[j] = start + int(out[j, MEASURE_START]), start + n
            start += n
            if out[j, DIVERGED] > 0:
                break
            a_from = a_to
    samples = np.concatenate(pieces, axis=1) if pieces else np.empty((n_rows, 0))
    level_index = np.concatenate(indices) if indices else np.empty(0, dtype=np.int64)
    return RecordedLevels(samples, level_index, holds, measurements)
