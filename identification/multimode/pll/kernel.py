"""numba core of the N-mode PLL: the modal equations, their RK4 step and one level's hold.

The loop is the one-mode PLL's (:mod:`identification.analytical.pll.closed_loop`:
same settings and control vectors, the same phase detector, controller, level
schedule and lock detector, from :mod:`identification.analytical.pll.loop`) with
the scalar state ``(x, ẋ)`` replaced by the modal state ``(η, η̇)`` of a
:class:`~identification.multimode.model.ModalModel`::

    η̈_m = w_m u(t) − 2ζ_m ω_m η̇_m − ω_m² η_m − Σ_e φ_{j(e) m} g_e(q_j, q̇_j) − couplings_m

with ``u = A sin θ`` the excitation (base acceleration, or force at a driving
point) and ``w_m`` its modal weight (``−Γ_m`` for the base, the driving point's
shape for a force). Catalogue elements are evaluated by
:func:`identification.effects.memoryless_force` and, for the hysteretic one, by
:func:`identification.effects.jenkins_force` with one anchor per element, moved to
the accepted state after each sub-step as in the one-mode integrator.

The detector sees the locked signal ``Σ_m c_m η_m^{(s)}`` (``c`` the unit vector of
the target mode for a modal lock, a sensor's shapes for a sensor lock; ``s`` the
derivative order of the sensing). During the measurement the Fourier
coefficients ``[C0, C1, S1, …, C3, S3]`` of every modal coordinate are
accumulated over exactly ``n_periods`` oscillator periods.

Arrays of one parameter set (``N`` modes, ``J`` joints, ``E`` elements, ``C`` couplings):

``modal`` (N, 3)
    ``ω_m², 2ζ_m ω_m, w_m``.
``shapes`` (J, N)
    Joint shapes ``φ_jm``.
``el_int`` (E, 3), ``el_float`` (E, 3)
    Per element ``[catalogue index, joint, hysteretic]`` and ``[coefficient, p0, p1]``.
``cp_int`` (C, 1 + N), ``cp_coef`` (C,)
    Per coupling ``[equation, powers…]`` and its coefficient.

The kernels are inlined into the loop, whose numba cache checks only its own
file: after editing them, ``make clean-cache``.
"""

from __future__ import annotations

import numba
import numpy as np

from identification.analytical.pll import loop
from identification.analytical.pll.loop import (
    DIVERGED,
    HARMONICS,
    N_PERIODS,
    N_RESULTS,
    OMEGA,
    OMEGA_INITIAL,
    THETA,
)
from identification.effects import jenkins_force, memoryless_force

#: Harmonics of every mode measured per hold (``[C0, C1, S1, …, C3, S3]``).
PARTICIPATION_HARMONICS = 3
#: Fourier coefficients per mode in a result row.
N_COEFFICIENTS = 2 * PARTICIPATION_HARMONICS + 1
#: Columns of ``modal``.
_STIFFNESS, _DAMPER, _WEIGHT = range(3)
#: Rows of the work array: the state η, η̇, η̈, then the RK4 stages.
(
    X, V, ACC, _ACC0, _X2, _V2, _ACC2, _X3, _V3, _ACC3, _X4, _V4, _ACC4, N_WORK,
) = range(14)  # fmt: skip
#: Recorded channels besides the modal ones (then η, η̇, η̈ of every mode).
CHANNELS = (
    "base_acceleration", "base_velocity", "frequency_hz", "phase", "response_phase_deg", "level",
)  # fmt: skip


@numba.njit(cache=True, inline="always")
def accelerations(modal, shapes, el_int, el_float, cp_int, cp_coef, work, x, v, xa, fa, u, out):
    """``work[out, m] = η̈_m`` at ``η = work[x]``, ``η̇ = work[v]`` under excitation ``u``.

    Rows of one 2-D work array rather than separate arrays: slicing rows in the
    hot loop would cost atomic reference counts at every stage of every step.
    Hysteretic elements are evaluated from their anchors.
    """
    n = work.shape[1]
    for m in range(n):
        work[out, m] = (
            modal[m, _WEIGHT] * u
            - modal[m, _DAMPER] * work[v, m]
            - modal[m, _STIFFNESS] * work[x, m]
        )
    for e in range(el_int.shape[0]):
        j = el_int[e, 1]
        q = 0.0
        q_dot = 0.0
        for m in range(n):
            q += shapes[j, m] * work[x, m]
            q_dot += shapes[j, m] * work[v, m]
        if el_int[e, 2]:
            g = el_float[e, 0] * jenkins_force(q, xa[e], fa[e], el_float[e, 1], el_float[e, 2])
        else:
            g = el_float[e, 0] * memoryless_force(el_int[e, 0], q, q_dot, el_float[e, 1],
                                                  el_float[e, 2])  # fmt: skip
        for m in range(n):
            work[out, m] -= shapes[j, m] * g
    for i in range(cp_int.shape[0]):
        term = cp_coef[i]
        for k in range(n):
            for _ in range(cp_int[i, 1 + k]):
                term *= work[x, k]
        work[out, cp_int[i, 0]] -= term


@numba.njit(cache=True, inline="always")
def advance(modal, shapes, el_int, el_float, cp_int, cp_coef, work, xa, fa, h, forcing):
    """RK4 over ``len(forcing) // 2`` sub-steps of ``h``, in place on ``work[X], work[V]``.

    ``work[ACC]`` holds the accelerations at the start, ``forcing[j]`` the
    excitation at ``j·h/2``; the other rows of ``work`` are the stages. The anchors
    ``xa, fa`` move to the accepted state after each sub-step.
    """
    n = work.shape[1]
    for m in range(n):
        work[_ACC0, m] = work[ACC, m]
    for j in range(forcing.size // 2):
        if j > 0:
            accelerations(modal, shapes, el_int, el_float, cp_int, cp_coef, work, X, V, xa, fa,
                           forcing[2 * j], _ACC0)  # fmt: skip
        # Stages 2, 3, 4: rows (x, v, a) = _X2 + 3i, …; each from the previous
        # stage's velocity and acceleration, a half, a half and a whole step on.
        for i in range(3):
            x_row, v_row, a_row = _X2 + 3 * i, _V2 + 3 * i, _ACC2 + 3 * i
            v_previous = V if i == 0 else v_row - 3
            fraction = 1.0 if i == 2 else 0.5
            for m in range(n):
                work[x_row, m] = work[X, m] + fraction * h * work[v_previous, m]
                work[v_row, m] = work[V, m] + fraction * h * work[a_row - 3, m]
            accelerations(modal, shapes, el_int, el_float, cp_int, cp_coef, work, x_row, v_row,
                           xa, fa, forcing[2 * j + 1 + i // 2], a_row)  # fmt: skip
        for m in range(n):
            work[X, m] = work[X, m] + h / 6.0 * (
                work[V, m] + 2.0 * work[_V2, m] + 2.0 * work[_V3, m] + work[_V4, m]
            )
            work[V, m] = work[V, m] + h / 6.0 * (
                work[_ACC0, m] + 2.0 * work[_ACC2, m] + 2.0 * work[_ACC3, m] + work[_ACC4, m]
            )
        for e in range(el_int.shape[0]):
            if el_int[e, 2]:
                q = 0.0
                for m in range(n):
                    q += shapes[el_int[e, 1], m] * work[X, m]
                fa[e] = jenkins_force(q, xa[e], fa[e], el_float[e, 1], el_float[e, 2])
                xa[e] = q


@numba.njit(cache=True)
def initial_state(omega, harmonics, n_modes, n_elements):
    """Run state at rest: the loop's at ``omega``, then η, η̇ and the anchors (x, f), all zero."""
    return loop.initial_state(omega, harmonics, 2 * n_modes + 2 * n_elements)


@numba.njit(cache=True)
def run_level(modal, shapes, el_int, el_float, cp_int, cp_coef, lock, target_mode, control,
              settings, state, a_from, a_to, record, result):  # fmt: skip
    """Ramp to level ``a_to`` and hold it until measured or given up; advances ``state``.

    ``lock`` (N,) weighs the modal coordinates into the locked signal, whose
    dominant mode is ``target_mode`` (from 0). Writes the
    level's outcome into ``result`` (the one-mode row, then ``N_COEFFICIENTS``
    Fourier coefficients per mode) and, when ``record`` has columns, its samples
    (the rows of :data:`CHANNELS`, then ``η``, ``η̇``, ``η̈`` of every mode).
    """
    dt, sensing, x_max, ramp, max_hold, n_sub = loop.level_settings(settings, control)
    n = modal.shape[0]
    n_elements = el_int.shape[0]
    # The power balance of the target mode is |w_t||U| / (2ω²|Q_t|); during the
    # hold |Q_t| is read from the detector as |Y| / (|c_t| ω^s), hence the lock
    # detector's gain |w_t||c_t|.
    weight = abs(modal[target_mode, _WEIGHT])
    lock_gain = weight * abs(lock[target_mode])
    recording = record.shape[1] > 0
    n_channels = len(CHANNELS)
    detector, offset = loop.start_level(settings, state, result)
    xa = state[offset + 2 * n : offset + 2 * n + n_elements]
    fa = state[offset + 2 * n + n_elements : offset + 2 * n + 2 * n_elements]
    work = np.empty((N_WORK, n))
    for m in range(n):
        work[X, m] = state[offset + m]
        work[V, m] = state[offset + n + m]
    forcing = np.empty(2 * n_sub + 1)
    q_modes = np.zeros((n, PARTICIPATION_HARMONICS + 1), dtype=np.complex128)
    q_y = q_base = 0j
    done = False
    error = np.nan
    k = 0
    while True:
        theta, s, c, amplitude = loop.oscillator(state, a_from, a_to, k, ramp)
        u = amplitude * s
        accelerations(modal, shapes, el_int, el_float, cp_int, cp_coef, work, X, V, xa, fa, u, ACC)
        y = 0.0
        finite = True
        for m in range(n):
            if not (
                abs(work[X, m]) <= x_max and np.isfinite(work[V, m]) and np.isfinite(work[ACC, m])
            ):
                finite = False
            y += lock[m] * work[sensing, m]  # rows X, V, ACC are the sensings' order
        if not finite:
            result[DIVERGED] = 1.0
            break
        phase, error, start, measuring, step, rotation, done = loop.loop_step(
            settings, control, state, detector, result, k, y, s, c, amplitude, lock_gain
        )
        omega = state[OMEGA]
        if recording:
            loop.record_loop(record, 0, k, u, amplitude, c, theta, omega, phase, settings)
            for m in range(n):
                for row in range(3):
                    record[n_channels + row * n + m, k] = work[row, m]
        if start:
            q_y = q_base = 0j
            q_modes[:] = 0j
        if measuring:
            q_y += y * rotation
            q_base += u * rotation
            turn = rotation
            for m in range(n):
                q_modes[m, 0] += work[X, m] * step
            for h in range(1, PARTICIPATION_HARMONICS + 1):
                for m in range(n):
                    q_modes[m, h] += work[X, m] * turn
                turn *= complex(c, -s)

        loop.excitation_samples(forcing, u, a_from, a_to, k, ramp, theta, omega * dt)
        advance(modal, shapes, el_int, el_float, cp_int, cp_coef, work, xa, fa, dt / n_sub, forcing)
        state[THETA] = theta + omega * dt
        k += 1
        if done or k - ramp >= max_hold:
            break

    for m in range(n):
        state[offset + m] = work[X, m]
        state[offset + n + m] = work[V, m]
    scale = np.pi * int(settings[N_PERIODS])
    if done:
        for m in range(n):
            row = N_RESULTS + m * N_COEFFICIENTS
            result[row] = q_modes[m, 0].real / (2.0 * scale)
            for h in range(1, PARTICIPATION_HARMONICS + 1):
                # Σ η e^{−ihθ} dθ = πn (C_h − i S_h)
                result[row + 2 * h - 1] = q_modes[m, h].real / scale
                result[row + 2 * h] = -q_modes[m, h].imag / scale
    amplitude_t = abs(q_modes[target_mode, 1]) / scale
    loop.close_level(settings, state, result, k, done, amplitude_t, weight, q_base, q_y, error)


@numba.njit(cache=True)
def backbone(modal, shapes, el_int, el_float, cp_int, cp_coef, lock, target_mode, control,
             settings, excitation, out):  # fmt: skip
    """All levels of one parameter set; ``out`` is ``(n_levels, row size)``."""
    loop.clear_levels(out)
    if not (control[OMEGA_INITIAL] > 0.0):
        return
    state = initial_state(control[OMEGA_INITIAL], int(settings[HARMONICS]), modal.shape[0],
                          el_int.shape[0])  # fmt: skip
    record = np.empty((0, 0))
    a_from = 0.0
    for j in range(excitation.size):
        run_level(modal, shapes, el_int, el_float, cp_int, cp_coef, lock, target_mode, control,
                  settings, state, a_from, excitation[j], record, out[j])  # fmt: skip
        if out[j, DIVERGED] > 0.0:
            return
        a_from = excitation[j]


@numba.njit(cache=True, parallel=True)
def backbones_parallel(modal, shapes, el_int, el_float, cp_int, cp_coef, lock, target_mode,
                       control, settings, excitation, out):  # fmt: skip
    """:func:`backbone` of every parameter set (leading axis), on numba threads."""
    for i in numba.prange(modal.shape[0]):
        backbone(modal[i], shapes[i], el_int, el_float[i], cp_int, cp_coef[i], lock, target_mode,
                 control[i], settings, excitation, out[i])  # fmt: skip
