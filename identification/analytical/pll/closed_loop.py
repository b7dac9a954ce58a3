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

from dataclasses import dataclass, field

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.harmonic import CoefficientTable, coefficient_table
from identification.analytical.pll import loop
from identification.analytical.pll.config import PLLConfig
from identification.analytical.pll.integrator import (
    _acceleration,
    _advance,
    _substep_message,
    _substeps,
    linear_coefficients,
)
from identification.analytical.pll.loop import (
    AMPLITUDE,
    DAMPING,
    DIVERGED,
    FREQUENCY,
    HARMONICS,
    LOCKED,
    N_PERIODS,
    N_RESULTS,
    OMEGA,
    OMEGA_INITIAL,
    PHASE_ERROR,
    THETA,
)
from identification.analytical.pll.loop import RecordedLevels as RecordedLevels
from identification.analytical.pll.loop import record_levels as record_levels
from identification.checks import positive_vector
from identification.model import JointModel


@dataclass(frozen=True, eq=False)
class LoopSamples:
    """The loop's samples of a virtual phase-resonance test (``fs`` Hz, SI units).

    What the one-mode and the N-mode records share: ``base_acceleration`` is the
    excitation ``A sin θ``, ``base_velocity`` its quasi-static integral
    ``−A cos θ / ω`` (zero mean; exact while a level holds, off by ``Ȧ cos θ / ω``
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
class PLLTimeSeries(LoopSamples):
    """Samples of a virtual phase-resonance test of one joint model.

    The loop's channels (:class:`LoopSamples`) and ``x``, ``v``, ``a``, the
    relative displacement, velocity, acceleration.
    """

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray


@dataclass(frozen=True, eq=False)
class LoopBackbone:
    """Backbone points of virtual phase-resonance tests, whatever the structure.

    Arrays have shape ``(n_levels,)`` for one model and ``(n_sets, n_levels)``
    for a batch; ``level`` is always ``(n_levels,)``. Unlocked levels have NaN
    amplitude, frequency and damping; their ``phase_error_deg`` is the
    detector's last error (NaN after divergence).

    Attributes
    ----------
    level
        Excitation amplitude of each level (m/s²).
    amplitude_m
        Fundamental-harmonic amplitude of the locked coordinate (m).
    frequency_hz
        Mean oscillator frequency over the measured periods (Hz).
    damping_ratio
        Power-balance damping ratio.
    phase_error_deg
        Phase of the sensed response's fundamental minus its resonant target (deg).
    locked
        Whether the level locked and was measured.
    """

    level: np.ndarray
    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    phase_error_deg: np.ndarray
    locked: np.ndarray


@dataclass(frozen=True, eq=False)
class PLLResult(LoopBackbone):
    """Backbone points of virtual phase-resonance tests of a joint model (:class:`LoopBackbone`).

    ``level`` is the base-acceleration amplitude (m/s²), ``amplitude_m`` the
    fundamental of the relative displacement, ``damping_ratio`` the power balance
    ``|Q_b| / (2|Q|)``; ``time_series`` the samples (single runs with
    ``record=True``), else None.
    """

    time_series: PLLTimeSeries | None = field(default=None, repr=False)


# --------------------------------------------------------------------------
# numba core: one level at a time, state carried from level to level.

# The structure's part of the run state (after :mod:`identification.analytical.pll.loop`'s).
_X, _V, _XA, _FA, _N_STRUCTURE = range(5)
# Recorded channels.
_CHANNELS = (
    "x", "v", "a", "base_acceleration", "base_velocity", "frequency_hz", "phase",
    "response_phase_deg", "level",
)  # fmt: skip


@numba.njit(cache=True)
def _run_level(
    indices, coefficients, shapes, microslip, control, settings, state, a_from, a_to, record,
    result,
):  # fmt: skip
    """Ramp to level ``a_to`` and hold it until measured or given up; advances ``state``.

    Writes the level's outcome into ``result`` and, when ``record`` has
    columns, its samples (one row per channel of ``_CHANNELS``).
    """
    dt, sensing, x_max, ramp, max_hold, n_sub = loop.level_settings(settings, control)
    c_ms, k_t, f_s = microslip[0], microslip[1], microslip[2]
    recording = record.shape[1] > 0
    detector, offset = loop.start_level(settings, state, result)
    x, v, xa, fa = state[offset + _X], state[offset + _V], state[offset + _XA], state[offset + _FA]
    forcing = np.empty(2 * n_sub + 1)
    q_x = q_y = q_base = 0j
    done = False
    error = np.nan
    k = 0
    while True:
        theta, s, c, amplitude = loop.oscillator(state, a_from, a_to, k, ramp)
        a_base = amplitude * s
        acc = _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x, v, a_base)
        if not (abs(x) <= x_max and np.isfinite(v) and np.isfinite(acc)):
            result[DIVERGED] = 1.0
            break
        if sensing == 0:
            y = x
        elif sensing == 1:
            y = v
        else:
            y = acc
        phase, error, start, measuring, _, rotation, done = loop.loop_step(
            settings, control, state, detector, result, k, y, s, c, amplitude, 1.0
        )
        omega = state[OMEGA]
        if recording:
            record[0, k] = x
            record[1, k] = v
            record[2, k] = acc
            loop.record_loop(record, 3, k, a_base, amplitude, c, theta, omega, phase, settings)
        if start:
            q_x = q_y = q_base = 0j
        if measuring:
            q_x += x * rotation
            q_y += y * rotation
            q_base += a_base * rotation

        loop.excitation_samples(forcing, a_base, a_from, a_to, k, ramp, theta, omega * dt)
        x, v, xa, fa = _advance(
            indices, coefficients, shapes, c_ms, k_t, f_s, x, v, xa, fa, acc, dt / n_sub, forcing
        )
        state[THETA] = theta + omega * dt
        k += 1
        if done or k - ramp >= max_hold:
            break

    state[offset + _X], state[offset + _V], state[offset + _XA], state[offset + _FA] = x, v, xa, fa
    amplitude_x = abs(q_x) / (np.pi * int(settings[N_PERIODS]))
    loop.close_level(settings, state, result, k, done, amplitude_x, 1.0, q_base, q_y, error)


@numba.njit(cache=True)
def _backbone(indices, coefficients, shapes, microslip, control, settings, excitation_m_s2, out):
    """All levels of one parameter set; ``out`` is ``(n_levels, N_RESULTS)``."""
    loop.clear_levels(out)
    if not (control[OMEGA_INITIAL] > 0.0):
        return
    state = loop.initial_state(control[OMEGA_INITIAL], int(settings[HARMONICS]), _N_STRUCTURE)
    record = np.empty((len(_CHANNELS), 0))
    a_from = 0.0
    for j in range(excitation_m_s2.size):
        _run_level(
            indices, coefficients, shapes, microslip, control, settings, state, a_from,
            excitation_m_s2[j], record, out[j],
        )  # fmt: skip
        if out[j, DIVERGED] > 0.0:
            return
        a_from = excitation_m_s2[j]


# --------------------------------------------------------------------------
# Python side: inputs, per-set arrays, results.


def _control(table: CoefficientTable, config: PLLConfig, model: JointModel) -> np.ndarray:
    """Per-set gains, frequency range and sub-steps, ``(n_sets, N_CONTROL)``."""
    stiffness, damping, _ = linear_coefficients(table)
    n_sub = _substeps(table, 1.0 / config.fs)
    return loop.control_vector(
        config, stiffness, damping, n_sub, lambda n: _substep_message(model, n, config.max_substeps)
    )


def backbone_result(
    excitation_m_s2: np.ndarray, out: np.ndarray, time_series: PLLTimeSeries | None = None
) -> PLLResult:
    """The backbone points of result rows ``out`` (``(…, n_levels, N_RESULTS)`` or longer)."""
    return PLLResult(
        level=excitation_m_s2,
        amplitude_m=out[..., AMPLITUDE].copy(),
        frequency_hz=out[..., FREQUENCY].copy(),
        damping_ratio=out[..., DAMPING].copy(),
        phase_error_deg=out[..., PHASE_ERROR].copy(),
        locked=out[..., LOCKED] > 0.0,
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
    loop.check_timing(config, control)
    settings = loop.settings_vector(config)
    arrays = (table.indices, table.coefficients[0], table.shapes[0], table.microslip[0])
    out = np.empty((excitation_m_s2.size, N_RESULTS))
    if not record:
        _backbone(*arrays, control[0], settings, excitation_m_s2, out)
        return backbone_result(excitation_m_s2, out)
    return _recorded_run(arrays, control[0], settings, excitation_m_s2, out, config.fs)


def _recorded_run(arrays, control, settings, excitation_m_s2, out, fs) -> PLLResult:
    """Level by level through the same kernel as :func:`_backbone`, keeping the samples."""
    run = None
    if control[OMEGA_INITIAL] > 0.0:
        state = loop.initial_state(control[OMEGA_INITIAL], int(settings[HARMONICS]), _N_STRUCTURE)

        def run(a_from, a_to, buffer, row):
            _run_level(*arrays, control, settings, state, a_from, a_to, buffer, row)

    recorded = loop.record_levels(run, excitation_m_s2, out, len(_CHANNELS), settings)
    series = PLLTimeSeries(
        fs=fs,
        t=np.arange(recorded.samples.shape[1]) / fs,
        level_index=recorded.level_index,
        holds=recorded.holds,
        measurements=recorded.measurements,
        **dict(zip(_CHANNELS, recorded.samples, strict=True)),
    )
    return backbone_result(excitation_m_s2, out, series)
