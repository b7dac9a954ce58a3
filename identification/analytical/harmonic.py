"""Harmonic-balance backbones of a base-excited joint model at phase resonance.

The model (:class:`~identification.model.JointModel`) is ``ẍ + f(x, ẋ) = −a_base(t)``
with ``x`` the displacement relative to the base. A backbone point is the
periodic response whose fundamental harmonic is ``a cos ωt`` while the base
acceleration is the pure fundamental ``a_base = A sin ωt``: the displacement
then lags the effective force ``−a_base`` by 90°, the phase-resonance condition
a PLL test holds. For each amplitude ``a`` the backbone gives

* the frequency ``ω`` (reported in Hz),
* the base-acceleration amplitude ``A`` (m/s²) that holds that amplitude,
* the damping ratio from the power balance of a base-excited test,
  ``D = |Q_b| / (2 |Q|)`` with ``Q_b = A / ω²`` the base-displacement and
  ``Q = a`` the relative-displacement fundamentals, i.e. ``D = A / (2 ω² a)``.

``A`` and ``D`` keep their sign: a negative value means the model's net
damping at that amplitude is negative (e.g. a dominant negative Van der Pol
term), so energy must be taken out to hold the amplitude.

A test's base motion is not a pure sine (shaker distortion, a PLL's frequency
ripple). With ``method="multi"`` the measured excitation's harmonics and mean can be
the forcing (``excitation_harmonics``, :func:`forcing_rows`): its fundamental is still
``A sin ωt`` with ``A`` the unknown the phase-resonance condition fixes, its
harmonics are the measured fractions of ``A``, so the response harmonics the
excitation explains are in the model's prediction and not left to its joint terms.
A force-driven test is the same with the force per unit mass in place of ``−a_base``.

Two methods:

``"single"``
    Single-harmonic balance with the catalogue's closed-form describing
    functions: ``ω² = Σ c_i k_eq,i(a, ω)``, ``D = Σ c_i c_eq,i(a, ω) / (2ω)``.
    Vectorised numpy. The math lives in small pure functions of
    ``(a, omega, coefficient arrays)`` so that a pytensor graph can mirror it.
``"multi"``
    Multi-harmonic balance with harmonics ``0..H`` (the mean included) and
    the alternating frequency–time scheme (AFT): the restoring force is
    evaluated on ``N`` samples per period and projected back. Newton's method
    with the exact Jacobian of the discrete AFT residual, started from the
    single-harmonic point, in one numba loop over all (parameter set, amplitude)
    cases.

Many parameter sets are evaluated at once through a :class:`CoefficientTable`
built from one template model plus override columns (no model per set).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.checks import positive_vector
from identification.effects import CATALOGUE, jenkins_force, memoryless_force
from identification.effects.base import NUMPY
from identification.model import JointModel

__all__ = [
    "EXCITATION_KINDS",
    "CoefficientTable",
    "HarmonicBackbone",
    "backbone",
    "coefficient_table",
    "default_time_samples",
    "describing_sums",
    "forcing_rows",
    "single_harmonic_backbone",
]

_EFFECTS_BY_INDEX = list(CATALOGUE.values())
_MICROSLIP_PARAMETERS = ("microslip", "microslip.k_t", "microslip.F_s")


@dataclass(frozen=True)
class HarmonicBackbone:
    """Phase-resonant backbone, one row per parameter set (or 1-D for one model).

    Attributes
    ----------
    amplitude_m
        Fundamental-harmonic amplitude of the relative displacement (m), shape ``(n_amp,)``.
    frequency_hz
        Backbone frequency (Hz).
    damping_ratio
        ``A / (2 ω² a)`` from the power balance (signed).
    base_acceleration
        Base-acceleration amplitude ``A`` (m/s², fundamental, signed).
    converged
        False where no phase-resonant solution was found; the numbers there are NaN.
    method
        ``"single"`` or ``"multi"``.
    harmonics
        Highest harmonic ``H`` balanced (1 for ``"single"``).
    harmonics_cos_m, harmonics_sin_m
        ``"multi"`` only: ``x(t) = Σ_h C_h cos hωt + S_h sin hωt`` for ``h = 0..H``
        (last axis); ``C_0`` is the mean, ``C_1 = a``, ``S_1 = 0``. None for ``"single"``.
    """

    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    base_acceleration: np.ndarray
    converged: np.ndarray
    method: str
    harmonics: int
    harmonics_cos_m: np.ndarray | None = None
    harmonics_sin_m: np.ndarray | None = None


# --------------------------------------------------------------------------
# Coefficients of many parameter sets.


@dataclass(frozen=True)
class CoefficientTable:
    """Per-set coefficient arrays of one model structure.

    Attributes
    ----------
    indices
        Catalogue indices of the memoryless terms, ``(n_terms,)``.
    coefficients
        ``(n_sets, n_terms)`` coefficients ``c_i``.
    shapes
        ``(n_sets, n_terms, 2)`` shape parameters ``(p0, p1)`` of the force kernels.
    microslip
        ``(n_sets, 3)``: coefficient, ``k_t``, ``F_s`` of the Jenkins element (zeros if absent).
    has_microslip
        Whether the model has the Jenkins element.
    """

    indices: np.ndarray
    coefficients: np.ndarray
    shapes: np.ndarray
    microslip: np.ndarray
    has_microslip: bool

    @property
    def n_sets(self) -> int:
        return self.coefficients.shape[0]


def coefficient_table(
    model: JointModel,
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
) -> CoefficientTable:
    """Coefficient arrays of ``model`` with the named parameters overridden per set.

    Parameters
    ----------
    model
        Template model; its structure (effects) is shared by all sets.
    parameters
        ``(n_sets, len(names))`` values; None gives the single set of ``model``.
    names
        Parameter names as in :attr:`JointModel.parameter_names`.
    """
    indices, coefficients, shapes = model.kernel_arrays()
    microslip = np.array(model.microslip_arrays(), dtype=float)
    if parameters is None:
        if names is not None:
            raise ValueError("names given without parameters")
        return CoefficientTable(
            indices, coefficients[None], shapes[None], microslip[None], model.has_microslip
        )
    if names is None:
        raise ValueError("parameters given without names (the column names)")
    names = list(names)
    values = np.asarray(parameters, dtype=float)
    if values.ndim != 2 or values.shape[1] != len(names) or values.shape[0] == 0:
        raise ValueError(
            f"parameters must have shape (n_sets, {len(names)}) for names {names}, "
            f"got {values.shape}"
        )
    n_sets = values.shape[0]
    arrays = {
        "coefficients": np.repeat(coefficients[None], n_sets, axis=0),
        "shapes": np.repeat(shapes[None], n_sets, axis=0),
        "microslip": np.repeat(microslip[None], n_sets, axis=0),
    }
    locations = _parameter_locations(model)
    if len(set(names)) != len(names):
        raise ValueError(f"parameter names repeat: {names}")
    for column, name in enumerate(names):
        if name not in locations:
            raise ValueError(f"unknown parameter {name!r}; the model has {model.parameter_names}")
        column_values = values[:, column]
        bad = np.flatnonzero(~np.isfinite(column_values))
        if bad.size:
            raise ValueError(f"parameter {name!r} is not finite in set {bad[0]}")
        is_shape = "." in name
        if is_shape and np.any(column_values <= 0):
            row = np.flatnonzero(column_values <= 0)[0]
            raise ValueError(
                f"shape parameter {name!r} must be > 0, set {row} has {column_values[row]}"
            )
        array, position = locations[name]
        arrays[array][(slice(None), *position)] = column_values
    return CoefficientTable(indices, **arrays, has_microslip=model.has_microslip)


def _parameter_locations(model: JointModel) -> dict[str, tuple[str, tuple[int, ...]]]:
    """Table array and index (after the set axis) of every parameter of ``model``."""
    locations = dict(
        zip(_MICROSLIP_PARAMETERS, (("microslip", (k,)) for k in range(3)), strict=True)
    )
    memoryless = [t for t in model.terms if t.effect != "microslip"]
    for i, term in enumerate(memoryless):
        locations[term.effect] = ("coefficients", (i,))
        for slot, shape_name in enumerate(CATALOGUE[term.effect].shape):
            locations[f"{term.effect}.{shape_name}"] = ("shapes", (i, slot))
    return {name: locations[name] for name in model.parameter_names}


# --------------------------------------------------------------------------
# Single-harmonic balance: small pure functions of (a, omega, coefficient arrays).


def describing_sums(
    a: np.ndarray, omega: np.ndarray, table: CoefficientTable
) -> tuple[np.ndarray, np.ndarray]:
    """Equivalent stiffness ``Σ c_i k_eq,i`` and damping ``Σ c_i c_eq,i`` of all terms.

    ``a`` and ``omega`` broadcast against ``(n_sets, 1)``. Even effects (x², ẋ²,
    x·ẋ and the even part of exp) have no single-harmonic signature: their
    describing functions are zero, so this sum (and ``method="single"``) cannot
    see them; only the multi-harmonic balance does, through the mean and the
    second harmonic.
    """
    k_total = np.zeros(np.broadcast_shapes(np.shape(a), np.shape(omega), (table.n_sets, 1)))
    c_total = np.zeros_like(k_total)
    terms = []
    for i, index in enumerate(table.indices):
        effect = _EFFECTS_BY_INDEX[index]
        shape = {name: table.shapes[:, i, slot, None] for slot, name in enumerate(effect.shape)}
        terms.append((effect, table.coefficients[:, i, None], shape))
    if table.has_microslip:
        coefficient, k_t, f_s = (table.microslip[:, j, None] for j in range(3))
        terms.append((CATALOGUE["microslip"], coefficient, {"k_t": k_t, "F_s": f_s}))
    for effect, coefficient, shape in terms:
        # The parts broadcast by themselves: a stiffness part stays the size of the
        # amplitude grid, and a part that is zero costs nothing.
        k_eq, c_eq = effect.describing_parts(NUMPY, a, omega, **shape)
        if k_eq is not None:
            k_total += coefficient * k_eq
        if c_eq is not None:
            c_total += coefficient * c_eq
    return k_total, c_total


def single_harmonic_backbone(
    a: np.ndarray, table: CoefficientTable, *, rtol: float = 1e-13, max_iter: int = 100
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequency (rad/s), damping ratio and convergence of the single-harmonic backbone.

    Solves ``ω² = Σ c_i k_eq,i(a, ω)`` by fixed-point iteration (one step when no
    term's stiffness depends on ω; ``x·ẋ²`` is the catalogue's one that does) and
    gives ``ζ = Σ c_i c_eq,i(a, ω) / (2ω)``. Outputs have shape ``(n_sets, n_amp)``;
    NaN and ``converged = False`` where the equivalent stiffness is not positive
    or the iteration does not settle.
    """
    shape = (table.n_sets, np.size(a))
    linear = _linear_stiffness(table)
    omega = np.broadcast_to(np.sqrt(np.where(linear > 0, linear, 1.0))[:, None], shape).copy()
    damping = np.full(shape, np.nan)
    done = np.zeros(shape, dtype=bool)
    for _ in range(max_iter):
        # Describing functions overflow where a term grows without bound (exp, x·ẋ² at
        # large amplitudes): no backbone there, which the NaN below reports.
        with np.errstate(over="ignore", invalid="ignore"):
            k_eq, c_eq = describing_sums(a, omega, table)
            updated = np.sqrt(np.where(k_eq > 0, k_eq, np.nan))
        settled = ~done & (np.abs(updated - omega) <= rtol * updated)
        # Freeze settled points: the answer must not depend on what else is in the batch.
        damping = np.where(settled, c_eq / (2.0 * omega), damping)
        done |= settled
        failed = ~done & ~np.isfinite(updated)
        omega = np.where(done, omega, updated)
        if np.all(done | failed):
            break
    omega = np.where(done, omega, np.nan)
    return omega, np.where(done, damping, np.nan), done


def _linear_stiffness(table: CoefficientTable) -> np.ndarray:
    """Small-amplitude stiffness per set: linear term plus a sticking Jenkins spring."""
    linear_index = CATALOGUE["linear_stiffness"].index
    k = table.coefficients[:, table.indices == linear_index].sum(axis=1)
    return k + table.microslip[:, 0] * table.microslip[:, 1]


# --------------------------------------------------------------------------
# Multi-harmonic balance with alternating frequency–time (AFT).
#
# Unknowns y = [X0, ω, C2, S2, …, CH, SH] (the fundamental is fixed to a cos θ),
# residual rows [mean, cos θ, cos 2θ, sin 2θ, …, cos Hθ, sin Hθ]: row e pairs with
# unknown e, row 1 (the fundamental's cosine) with ω. The sin θ row only gives the
# base acceleration, A = −F_s1; a measured excitation's harmonics and mean enter row e
# as A·u_e = −u_e·F_s1 (forcing_rows), which folds into that row's projection.

#: Relative forward-difference step of the per-sample tangents ∂f/∂x, ∂f/∂ẋ (≈ √ε).
_TANGENT_STEP = 1e-8


def default_time_samples(model: JointModel, harmonics: int) -> int:
    """AFT samples per period: ``16 H`` for polynomial models, else ``max(32 H, 128)``.

    ``4H + 1`` samples make the balance exact for polynomial terms up to cubic.
    Other forces alias: kinks (``x·|x|``, ``ẋ·|ẋ|``) with errors falling like
    ``1/N³``, (near-)jumps (friction, microslip) like ``1/N²`` (≈ 1e-4 of the
    friction damping at 160 samples), and tanh/exp need ``N`` to resolve
    ``a / x_s``.
    """
    n = 16 * harmonics
    polynomial = all(CATALOGUE[effect].polynomial for effect in model.effects)
    return n if polynomial else max(2 * n, 128)


def _aft_tables(harmonics: int, n_time: int) -> dict[str, np.ndarray]:
    """Projection and basis tables of the AFT residual (see the layout note above)."""
    theta = 2.0 * np.pi * np.arange(n_time) / n_time
    n_unknowns = 2 * harmonics
    orders = np.concatenate([[0, 1], np.repeat(np.arange(2, harmonics + 1), 2)])
    is_sine = np.zeros(n_unknowns, dtype=bool)
    is_sine[3::2] = True
    cos = np.cos(orders[:, None] * theta)
    sin = np.sin(orders[:, None] * theta)
    projection = np.where(is_sine[:, None], sin, cos) * (2.0 / n_time)
    projection[0] /= 2.0
    basis_x = np.where(is_sine[:, None], sin, cos)
    # ∂ẋ/∂C_h = −hω sin hθ, ∂ẋ/∂S_h = hω cos hθ; the factor ω is applied in the kernel.
    basis_v = orders[:, None] * np.where(is_sine[:, None], cos, -sin)
    basis_x[1] = basis_v[1] = 0.0  # unknown 1 is ω, which moves no displacement
    return {
        "orders": orders.astype(float),
        "projection": projection,
        "projection_sin1": np.sin(theta) * (2.0 / n_time),
        "basis_x": basis_x,
        "basis_v": basis_v,
        "cos1": np.cos(theta),
        "sin1": np.sin(theta),
    }


@numba.njit(cache=True)
def _solve_in_place(matrix, rhs):
    """Solve ``matrix · z = rhs`` into ``rhs`` (partial pivoting); False if singular.

    Hand-written because numba's np.linalg.solve raises on a singular matrix,
    which would abort the whole batch instead of flagging one case.
    """
    n = rhs.size
    for col in range(n):
        pivot = col
        best = abs(matrix[col, col])
        for row in range(col + 1, n):
            if abs(matrix[row, col]) > best:
                best = abs(matrix[row, col])
                pivot = row
        if not best > 0.0:
            return False
        if pivot != col:
            for k in range(col, n):
                matrix[col, k], matrix[pivot, k] = matrix[pivot, k], matrix[col, k]
            rhs[col], rhs[pivot] = rhs[pivot], rhs[col]
        for row in range(col + 1, n):
            factor = matrix[row, col] / matrix[col, col]
            if factor != 0.0:
                for k in range(col, n):
                    matrix[row, k] -= factor * matrix[col, k]
                rhs[row] -= factor * rhs[col]
    for col in range(n - 1, -1, -1):
        total = rhs[col]
        for k in range(col + 1, n):
            total -= matrix[col, k] * rhs[k]
        rhs[col] = total / matrix[col, col]
    return np.isfinite(rhs).all()


@numba.njit(cache=True)
def _orbit(a, y, basis_x, basis_v, cos1, sin1, x, v):
    """Displacement and velocity samples of the periodic orbit of unknowns ``y``."""
    n_unknowns, n_time = basis_x.shape
    omega = y[1]
    for n in range(n_time):
        xn = a * cos1[n]
        vn = -a * sin1[n]
        for j in range(n_unknowns):
            xn += y[j] * basis_x[j, n]
            vn += y[j] * basis_v[j, n]
        x[n] = xn
        v[n] = omega * vn


@numba.njit(cache=True)
def _memoryless_force(indices, coefficients, shapes, x, v, dx, dv, out):
    """``out[n] = Σ_i c_i φ_i(x_n + dx, v_n + dv)``.

    Terms in the outer loop (unlike ``effects.restoring_force``) so the effect
    dispatch is taken once per term, not once per sample.
    """
    out[:] = 0.0
    for i in range(indices.size):
        index = indices[i]
        c = coefficients[i]
        p0 = shapes[i, 0]
        p1 = shapes[i, 1]
        for n in range(x.size):
            out[n] += c * memoryless_force(index, x[n] + dx, v[n] + dv, p0, p1)


@numba.njit(cache=True)
def _memoryless_slopes(indices, coefficients, shapes, x, v, force, hx, hv, slope_x, slope_v):
    """Forward-difference tangents ``∂f/∂x``, ``∂f/∂ẋ`` of the memoryless force.

    One-sided steps of ≈ √ε relative give ~1e-8 relative tangents, plenty for
    Newton (the residual itself is exact) at half the cost of central ones.
    """
    _memoryless_force(indices, coefficients, shapes, x, v, hx, 0.0, slope_x)
    _memoryless_force(indices, coefficients, shapes, x, v, 0.0, hv, slope_v)
    for n in range(x.size):
        slope_x[n] = (slope_x[n] - force[n]) / hx
        slope_v[n] = (slope_v[n] - force[n]) / hv


@numba.njit(cache=True)
def _jenkins_loop(x, c_ms, k_t, f_s, force, anchor):
    """Steady Jenkins force (times its coefficient) into ``force``, and the element state.

    Marches two periods from the unstressed state and keeps the second one.
    ``anchor[n]`` is −2 while slipping (no stiffness), −1 while sticking since
    the unstressed start, m ≥ 0 while sticking since the last slip at sample m:
    there f = ±F_s + k_t (x_n − x_m), so ∂f/∂y = k_t (∂x_n/∂y − ∂x_m/∂y).
    """
    n_time = x.size
    x_anchor = 0.0
    f_anchor = 0.0
    last_slip = -1
    for i in range(2 * n_time):
        n = i % n_time
        f = jenkins_force(x[n], x_anchor, f_anchor, k_t, f_s)
        slipping = abs(f) >= f_s
        if slipping:
            last_slip = n
        x_anchor = x[n]
        f_anchor = f
        if i >= n_time:
            force[n] = c_ms * f
            anchor[n] = -2 if slipping else last_slip


# Serial on purpose: batches scale out through executors (docs/architecture.md), and numba's
# threading layers are neither fork-safe (OpenMP) nor re-entrant (workqueue), which
# PyMC chains and dask thread workers would hit. Reassociation lets the projections
# vectorise without giving up NaN semantics.
@numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _multi_harmonic_kernel(
    amplitude, omega_start, set_index, indices, coefficients, shapes, microslip,
    orders, projection, projection_sin1, basis_x, basis_v, cos1, sin1, tol, max_iter,
    out_y, out_base, out_converged,
):  # fmt: skip
    """Newton's method on the AFT residual, one independent case per (set, amplitude)."""
    n_cases = amplitude.size
    n_unknowns, n_time = projection.shape
    for case in range(n_cases):
        out_converged[case] = False
        out_base[case] = np.nan
        out_y[case, :] = np.nan
        a = amplitude[case]
        s = set_index[case]
        if not omega_start[case] > 0.0:
            continue
        c_ms, k_t, f_s = microslip[s, 0], microslip[s, 1], microslip[s, 2]
        y = np.zeros(n_unknowns)
        y[1] = omega_start[case]
        x = np.empty(n_time)
        v = np.empty(n_time)
        force = np.empty(n_time)
        slope_x = np.empty(n_time)
        slope_v = np.empty(n_time)
        anchor = np.full(n_time, -2)
        tangent = np.empty(n_time)
        hysteretic = np.zeros(n_time)
        weight = np.zeros((n_unknowns, n_time))
        jacobian = np.empty((n_unknowns, n_unknowns))
        residual = np.empty(n_unknowns)
        for iteration in range(max_iter + 1):
            _orbit(a, y, basis_x, basis_v, cos1, sin1, x, v)
            _memoryless_force(indices, coefficients[s], shapes[s], x, v, 0.0, 0.0, force)
            if c_ms != 0.0:
                _jenkins_loop(x, c_ms, k_t, f_s, hysteretic, anchor)
            omega = y[1]
            worst = 0.0
            for e in range(n_unknowns):
                total = 0.0
                for n in range(n_time):
                    total += projection[e, n] * (force[n] + hysteretic[n])
                displacement = a if e == 1 else y[e]
                residual[e] = total - (orders[e] * omega) ** 2 * displacement
                worst = max(worst, abs(residual[e]))
            if not np.isfinite(worst):
                break
            if worst <= tol * omega * omega * a:
                base = 0.0
                for n in range(n_time):
                    base -= projection_sin1[n] * (force[n] + hysteretic[n])
                out_base[case] = base
                out_y[case, :] = y
                out_converged[case] = True
                break
            if iteration == max_iter:
                break
            # Jacobian: projections of the per-sample tangents ∂f/∂x, ∂f/∂ẋ.
            hx = _TANGENT_STEP * a
            hv = _TANGENT_STEP * a * omega
            _memoryless_slopes(
                indices, coefficients[s], shapes[s], x, v, force, hx, hv, slope_x, slope_v
            )
            if c_ms != 0.0:
                for n in range(n_time):
                    if anchor[n] != -2:
                        slope_x[n] += c_ms * k_t
            for j in range(n_unknowns):
                if j == 1:
                    for n in range(n_time):
                        tangent[n] = slope_v[n] * v[n] / omega
                else:
                    for n in range(n_time):
                        tangent[n] = slope_x[n] * basis_x[j, n] + omega * slope_v[n] * basis_v[j, n]
                for e in range(n_unknowns):
                    total = 0.0
                    for n in range(n_time):
                        total += projection[e, n] * tangent[n]
                    jacobian[e, j] = total
            for e in range(n_unknowns):
                displacement = a if e == 1 else y[e]
                jacobian[e, 1] -= 2.0 * orders[e] ** 2 * omega * displacement
                if e != 1:
                    jacobian[e, e] -= (orders[e] * omega) ** 2
            if c_ms != 0.0:
                # Jenkins history: sticking samples also depend on the last slip sample.
                weight[:, :] = 0.0
                for n in range(n_time):
                    m = anchor[n]
                    if m >= 0:
                        for e in range(n_unknowns):
                            weight[e, m] += projection[e, n]
                for m in range(n_time):
                    for e in range(n_unknowns):
                        if weight[e, m] != 0.0:
                            for j in range(n_unknowns):
                                jacobian[e, j] -= c_ms * k_t * weight[e, m] * basis_x[j, m]
            for e in range(n_unknowns):
                residual[e] = -residual[e]
            if not _solve_in_place(jacobian, residual):
                break
            # Keep ω positive: never let one step take away more than half of it.
            scale = 1.0
            if residual[1] < -0.5 * omega:
                scale = -0.5 * omega / residual[1]
            for j in range(n_unknowns):
                y[j] += scale * residual[j]


def _multi_harmonic(
    a: np.ndarray,
    table: CoefficientTable,
    omega_start: np.ndarray,
    harmonics: int,
    n_time: int,
    tol: float,
    max_iter: int,
    forcing: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Solved unknowns ``(n_sets, n_amp, 2H)``, base acceleration and convergence.

    ``forcing`` is None (a pure sine) or the ``(n_amp, 2H)`` rows of
    :func:`forcing_rows`, one per amplitude.

    The cases are independent: they are split over ``numba.get_num_threads()``
    Python threads (the kernel releases the GIL). Threads rather than numba's
    ``prange``, whose OpenMP pool breaks in processes forked after first use
    (the samplers' chains, process pools).
    """
    shape = omega_start.shape
    tables = _aft_tables(harmonics, n_time)
    n_unknowns = 2 * harmonics
    n_cases = omega_start.size
    y = np.empty((n_cases, n_unknowns))
    base = np.empty(n_cases)
    converged = np.empty(n_cases, dtype=np.bool_)
    amplitude = np.broadcast_to(a, shape).ravel().astype(float)
    omega_start = omega_start.ravel()
    set_index = np.repeat(np.arange(table.n_sets), shape[1])
    coefficients = (
        table.indices, np.ascontiguousarray(table.coefficients),
        np.ascontiguousarray(table.shapes), np.ascontiguousarray(table.microslip),
        tables["orders"],
    )  # fmt: skip
    rest = (
        tables["projection_sin1"], tables["basis_x"], tables["basis_v"], tables["cos1"],
        tables["sin1"], float(tol), int(max_iter),
    )  # fmt: skip

    def solve(part: slice, projection: np.ndarray) -> None:
        _multi_harmonic_kernel(
            amplitude[part], omega_start[part], set_index[part], *coefficients, projection,
            *rest, y[part], base[part], converged[part],
        )  # fmt: skip

    n_threads = min(numba.get_num_threads(), n_cases // _CASES_PER_THREAD)
    if forcing is None:  # interleaved: neighbouring amplitudes cost alike
        parts = [slice(i, None, max(n_threads, 1)) for i in range(max(n_threads, 1))]
        projections = [tables["projection"]] * len(parts)
    else:
        # The fundamental's amplitude A = −F_s1 scales the whole excitation, so row e
        # balances F_e + u_e·F_s1: amplitude j's cases get the sin θ projection added to
        # each row with the weight of its excitation.
        parts = [slice(j, None, shape[1]) for j in range(shape[1])]
        projections = [
            np.ascontiguousarray(tables["projection"] + np.outer(u, tables["projection_sin1"]))
            for u in forcing
        ]
    if n_threads < 2:
        for part, projection in zip(parts, projections, strict=True):
            solve(part, projection)
    else:
        list(_thread_pool(n_threads).map(solve, parts, projections))
    return y.reshape(*shape, n_unknowns), base.reshape(shape), converged.reshape(shape)


#: Fewest harmonic-balance cases worth a thread of their own (each takes ~30 µs).
_CASES_PER_THREAD = 32
_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}


def _thread_pool(n_threads: int) -> ThreadPoolExecutor:
    """A pool of ``n_threads`` kept per process (a forked child gets a new one)."""
    key = (os.getpid(), n_threads)
    if key not in _POOLS:
        _POOLS[key] = ThreadPoolExecutor(n_threads, thread_name_prefix="harmonic")
    return _POOLS[key]


# --------------------------------------------------------------------------
# A measured excitation as the forcing of the multi-harmonic balance.

#: What a measured excitation is: the base acceleration of a base-excited test (the
#: model's forcing ``p`` in ``ẍ + f(x, ẋ) = p`` is its negative), or the force per unit
#: modal mass of a force-driven one (``p`` itself).
EXCITATION_KINDS = ("base_acceleration", "force")


def forcing_rows(
    excitation_harmonics: ArrayLike,
    n_amplitudes: int,
    harmonics: int,
    kind: str = "base_acceleration",
    excitation_mean: ArrayLike | None = None,
) -> np.ndarray | None:
    """The excitation's shape in the residual rows of the multi-harmonic balance.

    The excitation ``e`` is described as measured: its orders ``k = 2, 3, …`` as complex
    fractions ``r_k`` of its fundamental, in the frame where that fundamental is a real
    cosine (:attr:`~identification.measurements.backbone.Backbone.excitation_harmonics`),
    ``e = |E₁| (cos θ_e + Σ_k Re(r_k e^{ikθ_e}) + m)`` with ``m`` the mean over ``|E₁|``.
    At phase resonance the forcing's fundamental is ``p₁ = −A sin θ`` in the frame where
    the displacement's is ``a cos θ`` (``A`` the fundamental's amplitude the balance
    solves for), so with ``p = σ e`` (``σ = −1`` for a base acceleration, ``+1`` for a
    force) the forcing's order ``k`` is ``A·σ r_k (iσ)^k`` and its mean ``A·σ m``.

    Parameters
    ----------
    excitation_harmonics
        ``(n_orders,)`` ratios shared by every amplitude, or ``(n_amplitudes, n_orders)``;
        orders start at 2; orders above ``harmonics`` are not balanced.
    n_amplitudes, harmonics
        Amplitudes and highest harmonic of the balance.
    kind
        One of :data:`EXCITATION_KINDS`.
    excitation_mean
        Mean of the excitation over its fundamental's amplitude (scalar or per
        amplitude); None: 0 (a periodic base motion has no mean acceleration).

    Returns
    -------
    ``(n_amplitudes, 2·harmonics)`` rows ``u`` in the layout of the residual (mean,
    cos θ, then cos kθ, sin kθ for ``k = 2..H``; the cos θ entry is 0), per unit ``A``;
    None when the excitation is a pure sine.
    """
    if kind not in EXCITATION_KINDS:
        raise ValueError(f"excitation kind must be one of {EXCITATION_KINDS}, got {kind!r}")
    ratios = np.asarray(excitation_harmonics, dtype=complex)
    if ratios.ndim == 1:
        ratios = np.broadcast_to(ratios, (n_amplitudes, ratios.size))
    if ratios.ndim != 2 or ratios.shape[0] != n_amplitudes:
        raise ValueError(
            f"excitation_harmonics must have shape (n_orders,) or ({n_amplitudes}, n_orders), "
            f"got {np.shape(excitation_harmonics)}"
        )
    mean = np.broadcast_to(
        np.asarray(0.0 if excitation_mean is None else excitation_mean, dtype=float),
        (n_amplitudes,),
    )
    if not (np.isfinite(ratios).all() and np.isfinite(mean).all()):
        raise ValueError("excitation_harmonics and excitation_mean must be finite")
    sign = -1.0 if kind == "base_acceleration" else 1.0
    rows = np.zeros((n_amplitudes, 2 * harmonics))
    rows[:, 0] = sign * mean
    for m in range(min(ratios.shape[1], harmonics - 1)):
        k = m + 2
        forcing = sign * ratios[:, m] * (1j * sign) ** k
        rows[:, 2 * k - 2], rows[:, 2 * k - 1] = forcing.real, -forcing.imag
    return rows if rows.any() else None


# --------------------------------------------------------------------------
# Public entry point.


def backbone(
    model: JointModel,
    amplitudes_m: ArrayLike,
    *,
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
    method: str = "single",
    harmonics: int = 5,
    n_time: int | None = None,
    tol: float = 1e-10,
    max_iter: int = 50,
    excitation_harmonics: ArrayLike | None = None,
    excitation_kind: str = "base_acceleration",
    excitation_mean: ArrayLike | None = None,
) -> HarmonicBackbone:
    """Phase-resonant backbone of ``model`` at the given fundamental amplitudes.

    Parameters
    ----------
    model
        The joint model (template when ``parameters`` is given).
    amplitudes_m
        Fundamental-harmonic amplitudes of the relative displacement (m), 1-D, > 0.
    parameters, names
        Optional ``(n_sets, len(names))`` values of the named parameters
        (:attr:`JointModel.parameter_names`, e.g. ``"cubic_stiffness"``,
        ``"microslip.k_t"``); outputs then have shape ``(n_sets, n_amp)``, else ``(n_amp,)``.
    method
        ``"single"`` (describing functions; even terms have no effect there) or
        ``"multi"`` (harmonic balance with harmonics 0..``harmonics`` and AFT).
    harmonics
        Highest harmonic ``H`` of ``"multi"``.
    n_time
        AFT samples per period (≥ 4H + 1); default :func:`default_time_samples`.
        Friction terms converge like ``1/N²`` in the damping: raise it for
        precise friction damping.
    tol
        ``"multi"``: converged when every harmonic residual is below ``tol · ω² a``.
    max_iter
        ``"multi"``: Newton iterations before a case is declared not converged.
    excitation_harmonics, excitation_kind, excitation_mean
        ``"multi"``: the measured excitation as the forcing (:func:`forcing_rows`): its
        orders ``2, 3, …`` as fractions of its fundamental in its own frame, per
        amplitude ``(n_amp, n_orders)`` or shared ``(n_orders,)``; what it is
        (:data:`EXCITATION_KINDS`: a base acceleration or a force per unit mass); its
        mean over its fundamental's amplitude. The fundamental's amplitude is still
        the unknown the phase-resonance condition fixes (``base_acceleration``, which
        is then the force per unit mass for ``"force"``), the harmonics scale with
        it, and the damping ratio stays that of the fundamental's power balance. None:
        a pure sine.

    Returns
    -------
    HarmonicBackbone
        NaN and ``converged = False`` where there is no phase-resonant solution
        (e.g. no positive stiffness) or the solver did not converge.
    """
    a = positive_vector(amplitudes_m, "amplitudes_m")
    if method not in ("single", "multi"):
        raise ValueError(f"method must be 'single' or 'multi', got {method!r}")
    table = coefficient_table(model, parameters, names)
    omega, damping, converged = single_harmonic_backbone(a, table)
    cos_m = sin_m = None
    forced = excitation_harmonics is not None or excitation_mean is not None
    if method == "single":
        if forced:
            raise ValueError("an excitation with harmonics or a mean needs method='multi'")
        harmonics = 1
    else:
        if not isinstance(harmonics, int | np.integer) or harmonics < 1:
            raise ValueError(f"harmonics must be an integer ≥ 1, got {harmonics!r}")
        if not (np.isfinite(tol) and tol > 0):
            raise ValueError(f"tol must be finite and > 0, got {tol!r}")
        if not isinstance(max_iter, int | np.integer) or max_iter < 0:
            raise ValueError(f"max_iter must be an integer ≥ 0, got {max_iter!r}")
        if n_time is None:
            n_time = default_time_samples(model, harmonics)
        if not isinstance(n_time, int | np.integer) or n_time < 4 * harmonics + 1:
            raise ValueError(
                f"n_time must be an integer ≥ 4·harmonics + 1 = {4 * harmonics + 1}, got {n_time!r}"
            )
        forcing = None
        if forced:
            ratios = np.zeros(0) if excitation_harmonics is None else excitation_harmonics
            forcing = forcing_rows(ratios, a.size, harmonics, excitation_kind, excitation_mean)
        y, base, converged = _multi_harmonic(
            a, table, omega, harmonics, n_time, tol, max_iter, forcing
        )
        omega = y[..., 1]
        with np.errstate(over="ignore", invalid="ignore"):  # NaN or inf: not converged
            damping = base / (2.0 * omega**2 * a)
        cos_m = np.concatenate([y[..., :1], np.broadcast_to(a, omega.shape)[..., None],
                                y[..., 2::2]], axis=-1)  # fmt: skip
        sin_m = np.concatenate([np.zeros((*omega.shape, 2)), y[..., 3::2]], axis=-1)
        sin_m[~converged] = np.nan
        cos_m[~converged] = np.nan
    with np.errstate(over="ignore", invalid="ignore"):
        base_acceleration = 2.0 * omega**2 * a * damping
    squeeze = (lambda z: z[0]) if parameters is None else (lambda z: z)
    return HarmonicBackbone(
        amplitude_m=a,
        frequency_hz=squeeze(omega / (2.0 * np.pi)),
        damping_ratio=squeeze(damping),
        base_acceleration=squeeze(base_acceleration),
        converged=squeeze(converged),
        method=method,
        harmonics=harmonics,
        harmonics_cos_m=None if cos_m is None else squeeze(cos_m),
        harmonics_sin_m=None if sin_m is None else squeeze(sin_m),
    )
