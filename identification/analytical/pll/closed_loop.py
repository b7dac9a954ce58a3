"""Closed loop: the phase-locked loop (PLL) of a virtual phase-resonance test.

:func:`simulate_pll` runs the loop on one model, level after level, as the TRC
rig and NLtest do; the kernels here also serve the batch
(:mod:`identification.analytical.pll.batch`), and :class:`PLLResult` /
:class:`PLLTimeSeries` are what both return.

Conventions
-----------
Excitation
    ``a_base(t) = A(t) · sin θ(t)`` with ``θ̇ = ω(t)``, the PLL's frequency. The
    effective force on the relative coordinate is ``−a_base``.
Phase
    Phases are those of fundamental harmonics. Relative to the effective force
    ``−a_base``, phase resonance means the relative displacement lags by 90°,
    the relative velocity is in phase and the relative acceleration leads by
    90°. The real rig uses the **base velocity** as reference; it leads the
    force by 90°, so against it the relative displacement is at −180°, the
    relative velocity at −90° and the relative acceleration at 0°
    (:func:`target_phase_deg`). The choice of reference only changes the
    reported phases, not the point the loop locks on.
Phase detector
    The adaptive-filter Fourier estimator of Hippold et al. (2024): the sensed
    response is fitted online by ``c₀ + Σₖ aₖ sin kθ + bₖ cos kθ`` (k ≤
    ``harmonics``) with the LMS law ``ȧₖ = μ e sin kθ``, ``ḃₖ = μ e cos kθ``,
    ``e`` the fit residual. Averaged over a period this is a first-order low
    pass of bandwidth ``μ/2`` in the frame rotating with θ, with no phase delay
    at steady state, and because the harmonics are fitted too the fundamental's
    estimate carries no ripple from them (unlike multiply-and-low-pass
    demodulation). The excitation needs no detector: the oscillator synthesises
    it, so its phase is θ.
Controller
    ``ω = ω_I + K_p e_φ``, ``ω̇_I = K_i e_φ`` with ``e_φ`` the wrapped phase
    error (measured − target), clamped to ``frequency_limits`` with
    anti-windup. Near a resonance of modal bandwidth ``σ = ζω₀`` the phase of
    the response obeys ``δφ̇ = −σ δφ − δω`` (the slowly varying amplitude of a
    lightly damped mode, ``dφ/dω = −1/σ`` at steady state); with the detector's
    low pass ``ω_f`` the loop is third order, and :func:`design_gains` places
    its three poles at ``−p``: ``ω_f = 3p − σ``, ``K_p = 3p²/ω_f − σ``,
    ``K_i = p³/ω_f``, with ``p`` a multiple of ``σ`` (kept between ω₀/100 and
    ω₀/30 so that the averaged picture holds).
Level schedule
    Levels (base-acceleration amplitudes, m/s²) are approached by raised-cosine
    ramps of ``ramp_s`` (the first from rest, at the initial frequency with the
    controller off). A hold follows: at every completed oscillator period a lock
    detector checks that the phase error is within ``lock_tolerance_deg`` and
    that the response amplitude has settled: it approaches its steady state
    like ``exp(−ζωt)``, so a relative change ``δ`` per period means it is still
    ``δ / (2πζ)`` away, which must be below ``settling_tolerance`` (ζ estimated
    on line from the power balance); after ``lock_periods`` such periods
    in a row the last ``n_periods`` periods are measured (a lost lock restarts
    the settling). A hold that has not finished after ``max_hold_s`` is marked
    unlocked.
Backbone point
    Over exactly ``n_periods`` oscillator periods: fundamental harmonic ``Q`` of
    the relative displacement (amplitude, m), mean frequency, damping ratio
    from the power balance ``D = |Q_b| / (2|Q|)`` with ``Q_b = B/ω²`` the
    base-displacement fundamental (``B`` that of ``a_base``), and the phase
    error of the sensed response against the target.

Time integration is classical RK4 at the sampling step ``1/fs``, in numba
(:mod:`identification.analytical.pll.integrator`); the loop's steps (excitation
samples, detector, lock detector, measurement) are
:mod:`identification.analytical.pll.loop`'s, shared with the N-mode PLL.

A run that diverges (non-finite state or ``|x| > max_displacement_m``) marks
the current and all later levels unlocked, with NaN numbers; so does a model
with no positive linear stiffness when no initial frequency is given.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.harmonic import CoefficientTable, coefficient_table
from identification.analytical.pll.config import (
    _FORCE_VS_EXCITATION_DEG,
    _REFERENCE_VS_FORCE_DEG,
    _RESONANT_PHASE_VS_FORCE_DEG,
    SENSING,
    PLLConfig,
    _pole_placement,
)
from identification.analytical.pll.integrator import (
    _acceleration,
    _advance,
    _linear_coefficients,
    _substep_message,
    _substeps,
)
from identification.analytical.pll.loop import (
    _AMPLITUDE,
    _DAMPING,
    _DIVERGED,
    _DT,
    _FREQUENCY,
    _HARMONICS,
    _KI,
    _KP,
    _LOCK_PERIODS,
    _LOCKED,
    _MAX_HOLD,
    _MEASURE_START,
    _MU,
    _N_CONTROL,
    _N_PERIODS,
    _N_RESULTS,
    _N_SAMPLES,
    _N_SETTINGS,
    _N_SUB,
    _OMEGA_HIGH,
    _OMEGA_INITIAL,
    _OMEGA_LOW,
    _PHASE_ERROR,
    _RAMP,
    _REFERENCE,
    _SENSING,
    _SETTLING_TOLERANCE,
    _TARGET,
    _TOLERANCE,
    _X_MAX,
    _clear_result,
    _close_level,
    _detect,
    _excitation_samples,
    _lock_step,
    _loop_settings,
    _measure_step,
    _ramp,
    _record_loop,
    _wrap,
)
from identification.checks import positive_vector
from identification.model import JointModel

#: Fewest samples per period at the highest frequency the oscillator may reach.
_MIN_SAMPLES_PER_PERIOD = 10


@dataclass(frozen=True, eq=False)
class PLLTimeSeries:
    """Samples of a virtual phase-resonance test (``fs`` Hz, SI units).

    ``x``, ``v``, ``a`` are the relative displacement, velocity, acceleration;
    ``base_velocity`` is the quasi-static integral ``−A cos θ / ω`` of the base
    acceleration (zero mean; exact while a level holds, off by ``Ȧ cos θ / ω``
    during ramps); ``frequency_hz`` and ``phase`` (θ, rad, unwrapped) are the
    oscillator's; ``response_phase_deg`` is the detector's phase of the sensed
    response against the configured reference; ``level`` the commanded
    amplitude ``A(t)`` (m/s²) and ``level_index`` the level being approached or held.
    ``holds[j] = (start, stop)`` are the sample ranges (stop exclusive) of the
    hold of level ``j``, where ``level`` is constant; ``measurements[j]`` the
    measured last periods. Rows of levels never reached are ``(-1, -1)``.
    """

    fs: float
    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    base_acceleration: np.ndarray
    base_velocity: np.ndarray
    frequency_hz: np.ndarray
    phase: np.ndarray
    response_phase_deg: np.ndarray
    level: np.ndarray
    level_index: np.ndarray
    holds: np.ndarray
    measurements: np.ndarray


@dataclass(frozen=True, eq=False)
class PLLResult:
    """Backbone points of virtual phase-resonance tests.

    Arrays have shape ``(n_levels,)`` for one model and ``(n_sets, n_levels)``
    for a batch; ``level`` is always ``(n_levels,)``. Unlocked levels have NaN
    amplitude, frequency and damping; their ``phase_error_deg`` is the
    detector's last error (NaN after divergence).

    Attributes
    ----------
    level
        Base-acceleration amplitude of each level (m/s²).
    amplitude_m
        Fundamental-harmonic amplitude of the relative displacement (m).
    frequency_hz
        Mean oscillator frequency over the measured periods (Hz).
    damping_ratio
        Power-balance damping ratio ``|Q_b| / (2|Q|)``.
    phase_error_deg
        Phase of the sensed response's fundamental minus its resonant target (deg).
    locked
        Whether the level locked and was measured.
    time_series
        The samples (single runs with ``record=True``), else None.
    """

    level: np.ndarray
    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    phase_error_deg: np.ndarray
    locked: np.ndarray
    time_series: PLLTimeSeries | None = field(default=None, repr=False)


# --------------------------------------------------------------------------
# numba core: one level at a time, state carried from level to level.

# Layout of the per-run state vector (the settings, control and result layouts are
# :mod:`identification.analytical.pll.loop`'s).
_X, _V, _XA, _FA, _THETA, _OMEGA, _INTEGRAL, _CONTROL_ON, _DETECTOR = range(9)
# Recorded channels.
_CHANNELS = (
    "x", "v", "a", "base_acceleration", "base_velocity", "frequency_hz", "phase",
    "response_phase_deg", "level",
)  # fmt: skip


@numba.njit(cache=True)
def _initial_state(omega, harmonics):
    state = np.zeros(_DETECTOR + 1 + 2 * harmonics)
    state[_OMEGA] = omega
    state[_INTEGRAL] = omega
    return state


@numba.njit(cache=True)
def _run_level(
    indices, coefficients, shapes, microslip, control, settings, state, a_from, a_to, record,
    result,
):  # fmt: skip
    """Ramp to level ``a_to`` and hold it until measured or given up; advances ``state``.

    Writes the level's outcome into ``result`` and, when ``record`` has
    columns, its samples (one row per channel of ``_CHANNELS``).
    """
    (
        dt, target, sensing, max_hold, ramp, n_periods, x_max, harmonics, kp, ki, mu_dt,
        omega_low, omega_high, n_sub,
    ) = _loop_settings(settings, control)  # fmt: skip
    c_ms, k_t, f_s = microslip[0], microslip[1], microslip[2]
    recording = record.shape[1] > 0

    x, v, xa, fa = state[_X], state[_V], state[_XA], state[_FA]
    theta, omega, integral = state[_THETA], state[_OMEGA], state[_INTEGRAL]
    control_on = state[_CONTROL_ON] > 0.0
    detector = state[_DETECTOR:]
    forcing = np.empty(2 * n_sub + 1)
    _clear_result(result)

    locked_count = 0
    measuring = False
    done = False
    next_boundary = np.inf
    magnitude_previous = -1.0
    remaining = 0.0
    duration = 0.0
    q_x = q_y = q_base = 0j
    error = np.nan
    n = 0
    while True:
        s, c = np.sin(theta), np.cos(theta)
        amplitude = _ramp(a_from, a_to, n, ramp)
        a_base = amplitude * s
        acc = _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x, v, a_base)
        if not (abs(x) <= x_max and np.isfinite(v) and np.isfinite(acc)):
            result[_DIVERGED] = 1.0
            break
        if sensing == 0:
            y = x
        elif sensing == 1:
            y = v
        else:
            y = acc

        phase = _detect(detector, y, s, c, harmonics, mu_dt)
        error = _wrap(phase - target)

        # PI controller with anti-windup at the frequency limits.
        if control_on:
            integral = min(max(integral + ki * error * dt, omega_low), omega_high)
            omega = min(max(integral + kp * error, omega_low), omega_high)

        if recording:
            record[0, n] = x
            record[1, n] = v
            record[2, n] = acc
            _record_loop(record, 3, n, a_base, amplitude, c, theta, omega, phase, settings)

        if n == ramp:  # the hold starts; the first level's controller switches on here
            control_on = True
            next_boundary = theta + 2.0 * np.pi
        elif n > ramp and theta >= next_boundary:  # a period completed: lock detector
            next_boundary += 2.0 * np.pi
            measuring, locked_count, magnitude_previous, start = _lock_step(
                settings, control, detector, error, 1.0, amplitude, omega, magnitude_previous,
                measuring, locked_count,
            )  # fmt: skip
            if start:
                remaining = 2.0 * np.pi * n_periods
                duration = 0.0
                q_x = q_y = q_base = 0j
                result[_MEASURE_START] = n
        if measuring:
            _, remaining, duration, rotation, done = _measure_step(
                omega, dt, remaining, duration, c, s
            )
            q_x += x * rotation
            q_y += y * rotation
            q_base += a_base * rotation

        _excitation_samples(forcing, a_base, a_from, a_to, n, ramp, theta, omega * dt)
        x, v, xa, fa = _advance(
            indices, coefficients, shapes, c_ms, k_t, f_s, x, v, xa, fa, acc, dt / n_sub, forcing
        )
        theta = theta + omega * dt
        n += 1
        if done or n - ramp >= max_hold:
            break

    state[_X], state[_V], state[_XA], state[_FA] = x, v, xa, fa
    state[_THETA], state[_OMEGA], state[_INTEGRAL] = theta, omega, integral
    state[_CONTROL_ON] = 1.0 if control_on else 0.0
    amplitude_x = abs(q_x) / (np.pi * n_periods)
    _close_level(result, n, done, amplitude_x, 1.0, q_base, q_y, duration, n_periods, target, error)


@numba.njit(cache=True)
def _backbone(indices, coefficients, shapes, microslip, control, settings, excitation_m_s2, out):
    """All levels of one parameter set; ``out`` is ``(n_levels, _N_RESULTS)``."""
    out[:] = np.nan
    out[:, _LOCKED] = 0.0
    if not (control[_OMEGA_INITIAL] > 0.0):
        return
    state = _initial_state(control[_OMEGA_INITIAL], int(settings[_HARMONICS]))
    record = np.empty((len(_CHANNELS), 0))
    a_from = 0.0
    for j in range(excitation_m_s2.size):
        _run_level(
            indices, coefficients, shapes, microslip, control, settings, state, a_from,
            excitation_m_s2[j], record, out[j],
        )  # fmt: skip
        if out[j, _DIVERGED] > 0.0:
            return
        a_from = excitation_m_s2[j]


# --------------------------------------------------------------------------
# Python side: inputs, per-set arrays, results.


def _settings(config: PLLConfig) -> np.ndarray:
    settings = np.zeros(_N_SETTINGS)
    excitation = _FORCE_VS_EXCITATION_DEG
    settings[_DT] = 1.0 / config.fs
    settings[_TARGET] = np.radians(
        _RESONANT_PHASE_VS_FORCE_DEG[config.sensing] + excitation
    )  # detector phases are against a_base = A sin θ
    settings[_SENSING] = SENSING.index(config.sensing)
    settings[_TOLERANCE] = np.radians(config.lock_tolerance_deg)
    settings[_LOCK_PERIODS] = config.lock_periods
    settings[_SETTLING_TOLERANCE] = config.settling_tolerance
    settings[_MAX_HOLD] = round(config.max_hold_s * config.fs)
    settings[_RAMP] = round(config.ramp_s * config.fs)
    settings[_N_PERIODS] = config.n_periods
    settings[_X_MAX] = config.max_displacement_m
    settings[_HARMONICS] = config.harmonics
    settings[_REFERENCE] = np.radians(_REFERENCE_VS_FORCE_DEG[config.reference] + excitation)
    return settings


def _control(table: CoefficientTable, config: PLLConfig, model: JointModel) -> np.ndarray:
    """Per-set gains, frequency range and sub-steps, ``(n_sets, _N_CONTROL)``."""
    stiffness, damping, _ = _linear_coefficients(table)
    with np.errstate(invalid="ignore"):
        omega_linear = np.where(stiffness > 0, np.sqrt(np.abs(stiffness)), np.nan)
    if config.initial_frequency_hz is not None:
        omega_initial = np.full(table.n_sets, 2.0 * np.pi * config.initial_frequency_hz)
    else:
        omega_initial = omega_linear
    control = np.zeros((table.n_sets, _N_CONTROL))
    if config.gains is None:
        # Design at the resonance the loop starts on; σ = c/2 from the viscous term.
        omega_design = np.where(np.isfinite(omega_linear), omega_linear, omega_initial)
        kp, ki, bandwidth = _pole_placement(
            omega_design, 0.5 * damping / omega_design, config.bandwidth_ratio
        )
    else:
        kp, ki, bandwidth = config.gains.kp, config.gains.ki, config.gains.detector_bandwidth
    control[:, _KP] = kp
    control[:, _KI] = ki
    control[:, _MU] = 2.0 * np.asarray(bandwidth)
    control[:, _OMEGA_INITIAL] = omega_initial
    control[:, _OMEGA_LOW] = config.frequency_limits[0] * omega_initial
    control[:, _OMEGA_HIGH] = config.frequency_limits[1] * omega_initial
    n_sub = _substeps(table, 1.0 / config.fs)
    worst = int(np.argmax(n_sub))
    if n_sub[worst] > config.max_substeps:
        raise ValueError(
            ("" if table.n_sets == 1 else f"parameter set {worst}: ")
            + _substep_message(model, int(n_sub[worst]), config.max_substeps)
        )
    control[:, _N_SUB] = n_sub
    if config.gains is None:
        # Sets with no resonance to design for have nothing to lock on.
        control[~np.isfinite(control[:, _KP]), _OMEGA_INITIAL] = np.nan
    return control


def _check_timing(config: PLLConfig, control: np.ndarray) -> None:
    """The hold must fit the lock and measurement periods, the sampling the frequencies."""
    omega = control[:, _OMEGA_INITIAL]
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


def _result(excitation_m_s2: np.ndarray, out: np.ndarray, time_series=None) -> PLLResult:
    return PLLResult(
        level=excitation_m_s2,
        amplitude_m=out[..., _AMPLITUDE].copy(),
        frequency_hz=out[..., _FREQUENCY].copy(),
        damping_ratio=out[..., _DAMPING].copy(),
        phase_error_deg=out[..., _PHASE_ERROR].copy(),
        locked=out[..., _LOCKED] > 0.0,
        time_series=time_series,
    )


def simulate_pll(
    model: JointModel,
    levels: ArrayLike,
    config: PLLConfig | None = None,
    record: bool = False,
) -> PLLResult:
    """Virtual phase-resonance test of ``model`` at stepped excitation levels.

    Parameters
    ----------
    model
        Joint model (mass-normalised, base-excited).
    levels
        Base-acceleration amplitudes of the holds (m/s²), in test order (e.g.
        up then down), each finite and > 0.
    config
        Test settings; default :class:`PLLConfig()`.
    record
        Keep the samples (:class:`PLLTimeSeries`) for virtual test records.

    Returns
    -------
    PLLResult
        One backbone point per level, arrays of shape ``(n_levels,)``.
    """
    config = PLLConfig() if config is None else config
    excitation_m_s2 = positive_vector(levels, "levels")
    table = coefficient_table(model)
    control = _control(table, config, model)
    _check_timing(config, control)
    settings = _settings(config)
    arrays = (table.indices, table.coefficients[0], table.shapes[0], table.microslip[0])
    out = np.empty((excitation_m_s2.size, _N_RESULTS))
    if not record:
        _backbone(*arrays, control[0], settings, excitation_m_s2, out)
        return _result(excitation_m_s2, out)
    return _recorded_run(arrays, control[0], settings, excitation_m_s2, out, config.fs)


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
    out[:] = np.nan
    out[:, _LOCKED] = 0.0
    n_levels = excitation_m_s2.size
    holds = np.full((n_levels, 2), -1, dtype=np.int64)
    measurements = np.full((n_levels, 2), -1, dtype=np.int64)
    pieces, indices = [], []
    ramp, max_hold = int(settings[_RAMP]), int(settings[_MAX_HOLD])
    if run is not None:
        buffer = np.empty((n_rows, ramp + max_hold + 1))
        start, a_from = 0, 0.0
        for j, a_to in enumerate(excitation_m_s2):
            run(a_from, a_to, buffer, out[j])
            n = int(out[j, _N_SAMPLES])
            pieces.append(buffer[:, :n].copy())
            indices.append(np.full(n, j, dtype=np.int64))
            if n > ramp:
                holds[j] = start + ramp, start + n
            if out[j, _LOCKED] > 0:
                measurements[j] = start + int(out[j, _MEASURE_START]), start + n
            start += n
            if out[j, _DIVERGED] > 0:
                break
            a_from = a_to
    samples = np.concatenate(pieces, axis=1) if pieces else np.empty((n_rows, 0))
    level_index = np.concatenate(indices) if indices else np.empty(0, dtype=np.int64)
    return RecordedLevels(samples, level_index, holds, measurements)


def _recorded_run(arrays, control, settings, excitation_m_s2, out, fs) -> PLLResult:
    """Level by level through the same kernel as :func:`_backbone`, keeping the samples."""
    run = None
    if control[_OMEGA_INITIAL] > 0.0:
        state = _initial_state(control[_OMEGA_INITIAL], int(settings[_HARMONICS]))

        def run(a_from, a_to, buffer, row):
            _run_level(*arrays, control, settings, state, a_from, a_to, buffer, row)

    recorded = record_levels(run, excitation_m_s2, out, len(_CHANNELS), settings)
    series = PLLTimeSeries(
        fs=fs,
        t=np.arange(recorded.samples.shape[1]) / fs,
        level_index=recorded.level_index,
        holds=recorded.holds,
        measurements=recorded.measurements,
        **dict(zip(_CHANNELS, recorded.samples, strict=True)),
    )
    return _result(excitation_m_s2, out, series)
