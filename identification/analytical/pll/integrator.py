"""The equation of motion of a base-excited joint model and its explicit RK4 step.

``ẍ + f(x, ẋ) = −a_base(t)`` for a :class:`~identification.model.JointModel`,
integrated by classical RK4 in numba; shared by the open-loop integrator
(:mod:`identification.analytical.pll.open_loop`) and the PLL
(:mod:`identification.analytical.pll.closed_loop`).

Smoothed friction (slope ``F/v_reg``) and a stiff Jenkins spring make the
equation stiff, so a sample step is split into enough sub-steps to keep every
linearised eigenvalue inside RK4's stability region (:func:`stable_substeps`).
The Jenkins element is evaluated at each RK stage from the anchor state of the
step start and the anchor moves to the accepted state after the step.

The two kernels here are inlined into the loops' kernels, whose numba cache
checks only its own file: after editing them, ``make clean-cache``.
"""

from __future__ import annotations

import numba
import numpy as np

from identification.analytical.coefficients import small_amplitude_stiffness
from identification.analytical.harmonic import CoefficientTable, coefficient_table
from identification.analytical.pll.config import _check_positive
from identification.effects import (
    CATALOGUE,
    HYSTERETIC,
    VISCOUS_DAMPING,
    jenkins_force,
    memoryless_force,
)
from identification.model import JointModel

#: RK4 is stable for h·|λ| up to about 2.8 along both axes; keep a margin for nonlinearity.
RK4_STABLE_STEP = 2.0


@numba.njit(cache=True, inline="always")
def _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, x_anchor, f_anchor, x, v, a_base):
    """ẍ = −f(x, ẋ) − c_ms·Jenkins(x) − a_base, the Jenkins element from its anchor."""
    # The sum of `restoring_force` written out: calling that separately compiled
    # function from the hot loop costs atomic reference counts on its array
    # arguments at every stage of every step.
    force = 0.0
    for i in range(indices.size):
        force += coefficients[i] * memoryless_force(indices[i], x, v, shapes[i, 0], shapes[i, 1])
    if c_ms != 0.0:
        force += c_ms * jenkins_force(x, x_anchor, f_anchor, k_t, f_s)
    return -force - a_base


@numba.njit(cache=True, inline="always")
def _advance(indices, coefficients, shapes, c_ms, k_t, f_s, x, v, xa, fa, acc0, h, forcing):
    """RK4 over ``len(forcing) // 2`` sub-steps of ``h``; returns ``(x, v, x_anchor, f_anchor)``.

    ``acc0`` is the acceleration at the start and ``forcing[j]`` the base
    acceleration at ``j·h/2``. Within a sub-step the Jenkins element is
    evaluated from its anchor at the sub-step start; the anchor then moves to
    the accepted state.
    """
    for j in range(forcing.size // 2):
        if j > 0:
            acc0 = _acceleration(
                indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x, v, forcing[2 * j]
            )
        a_mid = forcing[2 * j + 1]
        x2 = x + 0.5 * h * v
        v2 = v + 0.5 * h * acc0
        acc2 = _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x2, v2, a_mid)
        x3 = x + 0.5 * h * v2
        v3 = v + 0.5 * h * acc2
        acc3 = _acceleration(indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x3, v3, a_mid)
        x4 = x + h * v3
        v4 = v + h * acc3
        acc4 = _acceleration(
            indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x4, v4, forcing[2 * j + 2]
        )
        x = x + h / 6.0 * (v + 2.0 * v2 + 2.0 * v3 + v4)
        v = v + h / 6.0 * (acc0 + 2.0 * acc2 + 2.0 * acc3 + acc4)
        if c_ms != 0.0:
            fa = jenkins_force(x, xa, fa, k_t, f_s)
            xa = x
    return x, v, xa, fa


# --------------------------------------------------------------------------
# Stability of the explicit step.


def linear_coefficients(table: CoefficientTable) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-set small-amplitude stiffness, viscous damping and stiffest |damping| slope."""
    coefficients, shapes = table.coefficients, table.shapes
    by_effect = {e.index: e for e in CATALOGUE.values()}

    def total(effect: str) -> np.ndarray:
        return coefficients[:, table.indices == CATALOGUE[effect].index].sum(axis=1)

    stiffness = small_amplitude_stiffness(table)
    damping = total(VISCOUS_DAMPING)
    slope = np.abs(damping)
    for i, index in enumerate(table.indices):
        effect = by_effect[index]
        if "v_reg" in effect.shape:  # smoothed sign: slope c / v_reg at ẋ = 0
            v_reg = shapes[:, i, effect.shape.index("v_reg")]
            slope = slope + np.abs(coefficients[:, i]) / v_reg
    return stiffness, damping, slope


def _substeps(table: CoefficientTable, dt: float) -> np.ndarray:
    """Sub-steps per sample keeping the linearised eigenvalues in RK4's stability region."""
    stiffness, _, slope = linear_coefficients(table)
    stuck = HYSTERETIC.stuck_stiffness(table.hysteretic[:, 0], table.hysteretic_shape())
    stiffness = np.abs(stiffness) + np.abs(stuck)
    largest_eigenvalue = 0.5 * slope + np.sqrt(0.25 * slope**2 + stiffness)
    return np.maximum(1, np.ceil(largest_eigenvalue * dt / RK4_STABLE_STEP)).astype(np.int64)


def stable_substeps(model: JointModel, fs: float) -> int:
    """RK4 sub-steps per sample at ``fs`` Hz that keep ``model``'s linearisation stable.

    The bound is the largest eigenvalue magnitude of the linearisation at rest,
    where the smoothed friction terms add their slope ``|c|/v_reg`` as viscous
    damping and the Jenkins spring its stiffness ``c·k_t``.
    """
    _check_positive("fs", fs)
    return int(_substeps(coefficient_table(model), 1.0 / fs)[0])


def _substep_message(model: JointModel, n_sub: int, limit: int) -> str:
    return (
        f"model {model.name or model.equation()!r} needs {n_sub} RK4 sub-steps per sample "
        f"(more than max_substeps = {limit}) to stay stable: a friction coefficient over its "
        "v_reg or a Jenkins stiffness is too stiff; raise v_reg or fs"
    )
