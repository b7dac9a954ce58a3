"""Multi-harmonic balance with alternating frequency–time (AFT).

Harmonics ``0..H`` (the mean included): the restoring force is evaluated on
``N`` samples per period and projected back. Newton's method with the exact
Jacobian of the discrete AFT residual, started from the single-harmonic point
(:mod:`~identification.analytical.single_harmonic`), in one numba loop over all
(parameter set, amplitude) cases. The hysteretic term (the Jenkins element)
is marched through two periods from the unstressed state, its history entering
the Jacobian through the sample where it last slipped.

A measured excitation's harmonics and mean can be the forcing
(:func:`forcing_rows`): its fundamental is still ``A sin ωt`` with ``A`` the unknown
the phase-resonance condition fixes, its harmonics are the measured fractions of ``A``.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.coefficients import CoefficientTable
from identification.effects import CATALOGUE, jenkins_force, memoryless_force
from identification.model import JointModel

__all__ = ["EXCITATION_KINDS", "default_time_samples", "forcing_rows", "multi_harmonic"]

# Layout of the residual. Unknowns y = [X0, ω, C2, S2, …, CH, SH] (the fundamental
# is fixed to a cos θ), residual rows [mean, cos θ, cos 2θ, sin 2θ, …, cos Hθ, sin Hθ]:
# row e pairs with unknown e, row 1 (the fundamental's cosine) with ω. The sin θ row
# only gives the base acceleration, A = −F_s1; a measured excitation's harmonics and
# mean enter row e as A·u_e = −u_e·F_s1 (forcing_rows), which folds into that row's
# projection.

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


# Serial on purpose: batches scale out through executors, and numba's
# threading layers are neither fork-safe (OpenMP) nor re-entrant (workqueue), which
# PyMC chains and dask thread workers would hit. Reassociation lets the projections
# vectorise without giving up NaN semantics.
@numba.njit(cache=True, nogil=True, fastmath={"reassoc", "contract"})
def _multi_harmonic_kernel(
    amplitude, omega_start, set_index, indices, coefficients, shapes, jenkins,
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
        # The hysteretic term is the Jenkins element: coefficient, k_t, F_s.
        c_ms, k_t, f_s = jenkins[s, 0], jenkins[s, 1], jenkins[s, 2]
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


def multi_harmonic(
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
        np.ascontiguousarray(table.shapes), np.ascontiguousarray(table.hysteretic),
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
