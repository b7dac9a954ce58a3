"""Open loop: the response of a joint model to a prescribed base acceleration.

:func:`simulate_base_excitation` integrates the equation of motion
(:mod:`identification.analytical.pll.integrator`) on a given sample grid, with
the base acceleration interpolated between samples: the force-driven rig and
the SINDy validation and admissibility checks simulate with it.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.harmonic import coefficient_table
from identification.analytical.pll.config import _MAX_SUBSTEPS
from identification.analytical.pll.integrator import (
    _acceleration,
    _advance,
    _substep_message,
    _substeps,
)
from identification.model import JointModel


@numba.njit(cache=True)
def _interpolate(t, values, i, tau):
    """Cubic Lagrange interpolation at ``tau`` in ``[t[i], t[i+1]]`` (keeps RK4 4th order)."""
    n = t.size
    if n < 4:
        w = (tau - t[i]) / (t[i + 1] - t[i])
        return (1.0 - w) * values[i] + w * values[i + 1]
    first = min(max(i - 1, 0), n - 4)
    total = 0.0
    for j in range(first, first + 4):
        weight = 1.0
        for m in range(first, first + 4):
            if m != j:
                weight *= (tau - t[m]) / (t[j] - t[m])
        total += weight * values[j]
    return total


@numba.njit(cache=True)
def _open_loop(indices, coefficients, shapes, microslip, t, base_acceleration, x0, v0, n_sub):
    c_ms, k_t, f_s = microslip[0], microslip[1], microslip[2]
    n = t.size
    xs = np.full(n, np.nan)
    vs = np.full(n, np.nan)
    accs = np.full(n, np.nan)
    x, v = x0, v0
    xa = fa = 0.0  # the Jenkins element starts unstressed at x = 0
    forcing = np.empty(2 * n_sub + 1)
    for i in range(n):
        acc = _acceleration(
            indices, coefficients, shapes, c_ms, k_t, f_s, xa, fa, x, v, base_acceleration[i]
        )
        if not (np.isfinite(acc) and np.isfinite(x) and np.isfinite(v)):
            break
        xs[i], vs[i], accs[i] = x, v, acc
        if i == n - 1:
            break
        h = (t[i + 1] - t[i]) / n_sub
        forcing[0] = base_acceleration[i]
        forcing[-1] = base_acceleration[i + 1]
        for j in range(1, 2 * n_sub):
            forcing[j] = _interpolate(t, base_acceleration, i, t[i] + 0.5 * j * h)
        x, v, xa, fa = _advance(
            indices, coefficients, shapes, c_ms, k_t, f_s, x, v, xa, fa, acc, h, forcing
        )
    return xs, vs, accs


def simulate_base_excitation(
    model: JointModel,
    t: ArrayLike,
    base_acceleration: ArrayLike,
    x0: float = 0.0,
    v0: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Response of ``model`` to a prescribed base acceleration (open loop).

    RK4 on the sample grid ``t`` (strictly increasing, need not be uniform),
    with the base acceleration interpolated cubically between samples and
    automatic sub-steps where the model is stiff (:func:`stable_substeps`).
    The microslip element starts unstressed.

    Parameters
    ----------
    model
        Joint model.
    t
        Sample times (s), 1-D.
    base_acceleration
        Base acceleration at ``t`` (m/s²).
    x0, v0
        Initial relative displacement (m) and velocity (m/s).

    Returns
    -------
    x, v, a
        Relative displacement, velocity and acceleration at ``t``; NaN from
        the first sample where the solution stops being finite.
    """
    t = _finite_vector("t", t)
    base_acceleration = _finite_vector("base_acceleration", base_acceleration)
    if t.size < 2:
        raise ValueError(f"t needs at least 2 samples, got {t.size}")
    if base_acceleration.size != t.size:
        raise ValueError(
            f"base_acceleration has {base_acceleration.size} samples but t has {t.size}"
        )
    steps = np.diff(t)
    if np.any(steps <= 0):
        raise ValueError(f"t must be strictly increasing (sample {np.argmax(steps <= 0) + 1})")
    for name, value in (("x0", x0), ("v0", v0)):
        if not math.isfinite(value):
            raise ValueError(f"{name} must be finite, got {value}")
    table = coefficient_table(model)
    n_sub = int(_substeps(table, float(steps.max()))[0])
    if n_sub > _MAX_SUBSTEPS:
        raise ValueError(_substep_message(model, n_sub, _MAX_SUBSTEPS))
    return _open_loop(
        table.indices, table.coefficients[0], table.shapes[0], table.microslip[0],
        t, base_acceleration, float(x0), float(v0), n_sub,
    )  # fmt: skip


def _finite_vector(name: str, values: ArrayLike) -> np.ndarray:
    array = np.ascontiguousarray(values, dtype=float)
    if array.ndim != 1:
        raise ValueError(f"{name} must be 1-D, got shape {array.shape}")
    bad = np.flatnonzero(~np.isfinite(array))
    if bad.size:
        raise ValueError(f"{name} is not finite at sample {bad[0]}")
    return array
