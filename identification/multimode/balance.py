"""The multi-harmonic balance residual of a ModalModel with alternating frequency–time (AFT).

Each modal coordinate is a truncated Fourier series in ``θ = ωt``::

    η_m(θ) = C_m0 + Σ_{h=1..H} C_mh cos hθ + S_mh sin hθ

stored per mode in the order ``[C0, C1, S1, C2, S2, …, CH, SH]`` (``2H + 1``
coefficients). The linear part of the modal equations is balanced in closed
form; the nonlinear forces (joint elements, couplings) are evaluated on ``n_time``
samples of one period and projected back onto the harmonics (AFT). The state of
a balance is one vector per parameter set::

    y = [Q (n_modes·(2H+1)), ω, ξ, A_c, A_s]

with ``ω`` the fundamental angular frequency, ``ξ`` the negative-damping term
of the extended periodic motion concept (``−ξ η̇_m`` added to every modal
equation; 0 for a forced response) and ``a_base = A_c cos kθ + A_s sin kθ`` the
base acceleration at the forcing harmonic ``k``. :func:`evaluate` gives the
residual and its Jacobian with respect to the whole of ``y``; the problems of
:mod:`identification.multimode.solve` pick which entries are unknown.

Everything is batched over parameter sets (leading axis ``B``) with numpy; the
per-sample tangents of memoryless elements are central differences of the
catalogue kernels, those of the polynomial couplings are exact, and the Jenkins
element's tangent follows its stick/slip history (as in the one-mode balance).
Shape parameters of the elements are shared by all sets.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.effects import Effect, get_effect, jenkins_force
from identification.multimode.model import ModalModel
from identification.parameter_sets import checked_column, checked_sets

__all__ = [
    "HarmonicGrid",
    "ModalArrays",
    "StateLayout",
    "default_time_samples",
    "evaluate",
    "harmonic_grid",
    "modal_arrays",
]

#: Central-difference step of the per-sample tangents, relative to the largest sample.
_TANGENT_STEP = 1e-6


# --------------------------------------------------------------------------
# The harmonic grid: bases and projections of the AFT.


@dataclass(frozen=True)
class HarmonicGrid:
    """Bases of the truncated Fourier series on ``n_time`` samples of a period.

    Attributes
    ----------
    harmonics, n_time
        Highest harmonic ``H`` and samples per period.
    orders
        Harmonic order of each coefficient, ``(2H+1,)``: ``[0, 1, 1, 2, 2, …]``.
    basis
        ``(n_time, 2H+1)``: the series' functions at the samples.
    basis_theta
        ``(n_time, 2H+1)``: their derivatives in θ.
    projection
        ``(2H+1, n_time)``: samples → coefficients (exact for harmonics ≤ H).
    derivative
        ``(2H+1, 2H+1)``: coefficients of ``dη/dθ`` from those of ``η``.
    tangent_basis, tangent_basis_theta
        ``(n_time, (2H+1)²)``: ``P_hn E_nk`` and ``P_hn ∂E_nk/∂θ`` per sample ``n``, so
        that the projection ``P diag(g) E`` of per-sample tangents ``g`` is one
        matrix product ``g · tangent_basis`` for a whole batch.
    """

    harmonics: int
    n_time: int
    orders: np.ndarray
    basis: np.ndarray
    basis_theta: np.ndarray
    projection: np.ndarray
    derivative: np.ndarray
    tangent_basis: np.ndarray
    tangent_basis_theta: np.ndarray

    @property
    def size(self) -> int:
        """Coefficients per mode, ``2H + 1``."""
        return 2 * self.harmonics + 1


def harmonic_grid(harmonics: int, n_time: int) -> HarmonicGrid:
    """The :class:`HarmonicGrid` of ``harmonics`` harmonics on ``n_time`` samples."""
    if isinstance(harmonics, bool) or not isinstance(harmonics, int | np.integer) or harmonics < 1:
        raise ValueError(f"harmonics must be an integer ≥ 1, got {harmonics!r}")
    if not isinstance(n_time, int | np.integer) or n_time < 4 * harmonics + 1:
        raise ValueError(
            f"n_time must be an integer ≥ 4·harmonics + 1 = {4 * harmonics + 1} (cubic terms "
            f"alias below it), got {n_time!r}"
        )
    size = 2 * harmonics + 1
    theta = 2.0 * np.pi * np.arange(n_time) / n_time
    orders = np.concatenate([[0], np.repeat(np.arange(1, harmonics + 1), 2)]).astype(float)
    is_sine = np.zeros(size, dtype=bool)
    is_sine[2::2] = True
    cos = np.cos(np.outer(theta, orders))
    sin = np.sin(np.outer(theta, orders))
    basis = np.where(is_sine, sin, cos)
    basis_theta = orders * np.where(is_sine, cos, -sin)
    projection = basis.T * (2.0 / n_time)
    projection[0] /= 2.0
    derivative = np.zeros((size, size))
    for h in range(1, harmonics + 1):
        derivative[2 * h - 1, 2 * h] = h  # cos hθ coefficient of dη/dθ is h·S_h
        derivative[2 * h, 2 * h - 1] = -h  # sin hθ coefficient is −h·C_h
    tangent_basis = np.einsum("hn,nk->nhk", projection, basis).reshape(n_time, -1)
    tangent_basis_theta = np.einsum("hn,nk->nhk", projection, basis_theta).reshape(n_time, -1)
    return HarmonicGrid(int(harmonics), int(n_time), orders, basis, basis_theta, projection,
                        derivative, tangent_basis, tangent_basis_theta)  # fmt: skip


def default_time_samples(model: ModalModel, harmonics: int) -> int:
    """AFT samples per period: ``16 H`` for polynomial models, else ``max(32 H, 128)``.

    The rule of the one-mode balance (:func:`identification.analytical.harmonic.
    default_time_samples`): exact for polynomial terms up to cubic, and resolving
    kinks and jumps of friction and slip to about 1e-4 otherwise.
    """
    n = 16 * harmonics
    return n if model.polynomial else max(2 * n, 128)


# --------------------------------------------------------------------------
# A model's numbers, batched over parameter sets.


@dataclass(frozen=True)
class ModalArrays:
    """Per-set arrays of one ModalModel structure (leading axis: parameter set).

    Attributes
    ----------
    omega, zeta, participation
        ``(B, N)`` linear angular frequencies (rad/s), damping ratios, base participations.
    joint_shapes
        ``(B, J, N)`` mode shapes at the joint coordinates.
    element_coefficients
        ``(B, E)`` coefficients of the joint elements.
    coupling_coefficients
        ``(B, C)`` coefficients of the couplings.
    effects, element_joints, element_shapes
        Per element: the catalogue effect, its joint index (from 0), its shape parameters.
    coupling_modes, coupling_powers
        ``(C,)`` equation index (from 0) and ``(C, N)`` exponents of the couplings.
    """

    omega: np.ndarray
    zeta: np.ndarray
    participation: np.ndarray
    joint_shapes: np.ndarray
    element_coefficients: np.ndarray
    coupling_coefficients: np.ndarray
    effects: tuple[Effect, ...]
    element_joints: tuple[int, ...]
    element_shapes: tuple[dict[str, float], ...]
    coupling_modes: np.ndarray
    coupling_powers: np.ndarray

    @property
    def n_sets(self) -> int:
        return self.omega.shape[0]

    @property
    def n_modes(self) -> int:
        return self.omega.shape[1]

    def take(self, sets: np.ndarray) -> ModalArrays:
        """The arrays of the parameter sets ``sets`` (indices)."""
        return replace(
            self,
            omega=self.omega[sets],
            zeta=self.zeta[sets],
            participation=self.participation[sets],
            joint_shapes=self.joint_shapes[sets],
            element_coefficients=self.element_coefficients[sets],
            coupling_coefficients=self.coupling_coefficients[sets],
        )


def modal_arrays(
    model: ModalModel, parameters: ArrayLike | None = None, names: Sequence[str] | None = None
) -> ModalArrays:
    """The arrays of ``model``, with the named parameters overridden per set.

    Parameters
    ----------
    model
        Template model (its structure is shared by all sets).
    parameters
        ``(n_sets, len(names))`` values; None gives the single set of ``model``.
    names
        Names from :attr:`ModalModel.parameter_names`.
    """
    base = {
        "frequency": np.array([m.frequency_hz for m in model.modes]),
        "zeta": np.array([m.damping_ratio for m in model.modes]),
        "participation": np.array([m.participation for m in model.modes]),
        "joint_shapes": np.array(model.joint_shapes, dtype=float).reshape(
            model.n_joints, model.n_modes
        ),
        "element_coefficients": np.array([e.coefficient for e in model.elements]),
        "coupling_coefficients": np.array([c.coefficient for c in model.couplings]),
    }
    checked = checked_sets(parameters, names)
    values, names = (np.zeros((1, 0)), []) if checked is None else checked
    n_sets = values.shape[0]
    arrays = {key: np.repeat(value[None], n_sets, axis=0) for key, value in base.items()}
    locations = _parameter_locations(model)
    for column, name in enumerate(names):
        column_values = checked_column(values, column, name, model.parameter_names)
        key, position = locations[name]
        arrays[key][(slice(None), *position)] = column_values
    if np.any(arrays["frequency"] <= 0) or np.any(arrays["zeta"] < 0):
        raise ValueError("mode frequencies must be > 0 and damping ratios ≥ 0 in every set")
    return ModalArrays(
        omega=2.0 * np.pi * arrays["frequency"],
        zeta=arrays["zeta"],
        participation=arrays["participation"],
        joint_shapes=arrays["joint_shapes"],
        element_coefficients=arrays["element_coefficients"].reshape(n_sets, len(model.elements)),
        coupling_coefficients=arrays["coupling_coefficients"].reshape(n_sets, len(model.couplings)),
        effects=tuple(get_effect(e.effect) for e in model.elements),
        element_joints=tuple(e.joint - 1 for e in model.elements),
        element_shapes=tuple(dict(e.shape) for e in model.elements),
        coupling_modes=np.array([c.mode - 1 for c in model.couplings], dtype=int),
        coupling_powers=np.array([c.powers for c in model.couplings], dtype=int).reshape(
            len(model.couplings), model.n_modes
        ),
    )


def _parameter_locations(model: ModalModel) -> dict[str, tuple[str, tuple[int, ...]]]:
    """Array and index (after the set axis) of every name of ``model.parameter_names``."""
    locations: dict[str, tuple[str, tuple[int, ...]]] = {}
    for m in range(model.n_modes):
        locations[f"mode{m + 1}.frequency_hz"] = ("frequency", (m,))
        locations[f"mode{m + 1}.damping_ratio"] = ("zeta", (m,))
        locations[f"mode{m + 1}.participation"] = ("participation", (m,))
        for j in range(model.n_joints):
            locations[f"joint{j + 1}.mode{m + 1}"] = ("joint_shapes", (j, m))
    for i, element in enumerate(model.elements):
        locations[element.label] = ("element_coefficients", (i,))
    for i in range(len(model.couplings)):
        locations[f"coupling{i + 1}"] = ("coupling_coefficients", (i,))
    return locations


# --------------------------------------------------------------------------
# The residual and its Jacobian.


@dataclass(frozen=True)
class StateLayout:
    """Positions in the state vector ``y`` of a balance with ``n_modes`` modes."""

    n_modes: int
    size: int  # coefficients per mode, 2H + 1

    @property
    def n_coefficients(self) -> int:
        return self.n_modes * self.size

    def coefficient(self, mode: int, index: int) -> int:
        """Position of coefficient ``index`` of ``mode`` (both from 0)."""
        return mode * self.size + index

    @property
    def omega(self) -> int:
        return self.n_coefficients

    @property
    def xi(self) -> int:
        return self.n_coefficients + 1

    @property
    def forcing_cos(self) -> int:
        return self.n_coefficients + 2

    @property
    def forcing_sin(self) -> int:
        return self.n_coefficients + 3

    @property
    def n_state(self) -> int:
        return self.n_coefficients + 4


def evaluate(
    arrays: ModalArrays, grid: HarmonicGrid, y: np.ndarray, forcing_harmonic: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Residual ``(B, N·(2H+1))`` and its Jacobian ``(B, N·(2H+1), N·(2H+1)+4)`` at ``y``.

    Row ``(m, i)`` balances coefficient ``i`` of mode ``m``; the Jacobian's columns
    follow :class:`StateLayout`.
    """
    n_sets, n_modes, size = arrays.n_sets, arrays.n_modes, grid.size
    layout = StateLayout(n_modes, size)
    q_modal = y[:, : layout.n_coefficients].reshape(n_sets, n_modes, size)
    omega = y[:, layout.omega]
    xi = y[:, layout.xi]
    eta = q_modal @ grid.basis.T  # (B, N, T)
    eta_theta = q_modal @ grid.basis_theta.T
    force, slope_x, slope_v, history = _nonlinear_forces(
        arrays, grid, eta, omega[:, None, None] * eta_theta
    )

    # Linear part, closed form per harmonic.
    stiffness = arrays.omega[:, :, None] ** 2 - (grid.orders * omega[:, None, None]) ** 2
    damping = 2.0 * arrays.zeta * arrays.omega - xi[:, None]  # (B, N)
    rotated = q_modal @ grid.derivative.T  # coefficients of dη/dθ
    residual = stiffness * q_modal + damping[:, :, None] * omega[:, None, None] * rotated
    residual += force @ grid.projection.T
    k = forcing_harmonic
    residual[:, :, 2 * k - 1] += arrays.participation * y[:, [layout.forcing_cos]]
    residual[:, :, 2 * k] += arrays.participation * y[:, [layout.forcing_sin]]

    # ∂/∂Q: P (diag(∂F/∂η) E + ω diag(∂F/∂η̇) E_θ), blocks (mode row, mode column).
    blocks = slope_x.reshape(-1, grid.n_time) @ grid.tangent_basis
    if slope_v is not None:
        blocks += (omega[:, None, None, None] * slope_v).reshape(-1, grid.n_time) @ (
            grid.tangent_basis_theta
        )
    blocks = blocks.reshape(n_sets, n_modes, n_modes, size, size)
    if history is not None:
        blocks += grid.projection @ history
    linear = (
        stiffness[..., None] * np.eye(size)
        + (damping * omega[:, None])[:, :, None, None] * grid.derivative
    )
    for m in range(n_modes):
        blocks[:, m, m] += linear[:, m]
    # The last four columns: ∂/∂ω (the linear part's, and the velocity's through
    # η̇ = ω ∂η/∂θ), ∂/∂ξ and ∂/∂A_c, ∂/∂A_s (the participations at harmonic k).
    extra = np.zeros((n_sets, n_modes, size, 4))
    extra[..., 0] = -2.0 * grid.orders**2 * omega[:, None, None] * q_modal
    extra[..., 0] += damping[:, :, None] * rotated
    if slope_v is not None:
        extra[..., 0] += np.einsum("bmkt,bkt->bmt", slope_v, eta_theta) @ grid.projection.T
    extra[..., 1] = -omega[:, None, None] * rotated
    extra[:, :, 2 * k - 1, 2] = arrays.participation
    extra[:, :, 2 * k, 3] = arrays.participation
    n_rows = layout.n_coefficients
    jacobian = np.concatenate(
        [
            blocks.transpose(0, 1, 3, 2, 4).reshape(n_sets, n_rows, n_rows),
            extra.reshape(n_sets, n_rows, 4),
        ],
        axis=2,
    )
    return residual.reshape(n_sets, -1), jacobian


def _nonlinear_forces(
    arrays: ModalArrays, grid: HarmonicGrid, eta: np.ndarray, eta_dot: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """Modal forces ``(B, N, T)``, their tangents ``(B, N, N, T)`` and the history term.

    The velocity tangent is None when no element depends on the velocity.

    The history term (None without hysteretic elements) is the ``(B, N, N, T, 2H+1)``
    part of the sample Jacobian through earlier samples: a Jenkins element sticking
    since its last slip at sample ``s`` has ``g_n = ±F_s + k_t (q_n − q_s)``.
    """
    n_sets, n_modes, n_time = eta.shape
    force = np.zeros_like(eta)
    slope_x = np.zeros((n_sets, n_modes, n_modes, n_time))
    slope_v = None  # until an element depends on the velocity
    history = None
    shapes = arrays.joint_shapes  # (B, J, N)
    q = shapes @ eta  # (B, J, T)
    q_dot = shapes @ eta_dot
    for e, effect in enumerate(arrays.effects):
        j = arrays.element_joints[e]
        c = arrays.element_coefficients[:, e, None]
        phi = shapes[:, j, :]  # (B, N)
        outer = phi[:, :, None, None] * phi[:, None, :, None]
        shape = arrays.element_shapes[e]
        x, v = q[:, j], q_dot[:, j]
        if effect.hysteretic:
            k_t, f_s = effect.shape_values(**shape)
            g = np.empty_like(x)
            anchor = np.empty(x.shape, dtype=np.int64)
            _jenkins_steady(np.ascontiguousarray(x), k_t, f_s, g, anchor)
            gq = np.where(anchor != _SLIPPING, k_t, 0.0)
            earlier = np.where(
                (anchor >= 0)[..., None], -k_t * grid.basis[np.maximum(anchor, 0)], 0.0
            )
            term = outer[..., None] * (c[:, :, None] * earlier)[:, None, None]
            history = term if history is None else history + term
        else:
            hx = _TANGENT_STEP * np.max(np.abs(x), axis=1, keepdims=True) + 1e-300
            hv = _TANGENT_STEP * np.max(np.abs(v), axis=1, keepdims=True) + 1e-300
            g = effect.feature(x, v, **shape)
            gq = (effect.feature(x + hx, v, **shape) - effect.feature(x - hx, v, **shape)) / (
                2 * hx
            )
            gv = (effect.feature(x, v + hv, **shape) - effect.feature(x, v - hv, **shape)) / (
                2 * hv
            )
            if gv.any():  # stiffness effects do not depend on the velocity
                slope_v = 0.0 if slope_v is None else slope_v
                slope_v = slope_v + outer * (c * gv)[:, None, None, :]
        force += phi[:, :, None] * (c * g)[:, None, :]
        slope_x += outer * (c * gq)[:, None, None, :]
    for i, (m, powers) in enumerate(
        zip(arrays.coupling_modes, arrays.coupling_powers, strict=True)
    ):
        c = arrays.coupling_coefficients[:, i, None]
        factors = {k: eta[:, k] ** p for k, p in enumerate(powers) if p}
        force[:, m] += c * _product(factors.values())
        for k, p in enumerate(powers):
            if p:
                rest = [f for n, f in factors.items() if n != k]
                slope_x[:, m, k] += c * p * _product([eta[:, k] ** (p - 1), *rest])
    return force, slope_x, slope_v, history


def _product(factors) -> np.ndarray | float:
    """Product of arrays (1.0 for none)."""
    total = 1.0
    for factor in factors:
        total = total * factor
    return total


#: ``anchor`` value of a slipping Jenkins sample (no stiffness there).
_SLIPPING = -2


@numba.njit(cache=True)
def _jenkins_steady(q, k_t, f_s, force, anchor):
    """Steady Jenkins force along each row of ``q`` (one period of samples) and its state.

    Marches two periods from the unstressed state and keeps the second, as the
    one-mode balance does. ``anchor[b, n]`` is ``_SLIPPING`` (−2) while slipping,
    −1 while sticking since the unstressed start, ``s ≥ 0`` while sticking since
    the last slip at sample ``s``.
    """
    n_sets, n_time = q.shape
    for b in range(n_sets):
        x_anchor = 0.0
        f_anchor = 0.0
        last_slip = -1
        for i in range(2 * n_time):
            n = i % n_time
            f = jenkins_force(q[b, n], x_anchor, f_anchor, k_t, f_s)
            slipping = abs(f) >= f_s
            if slipping:
                last_slip = n
            x_anchor = q[b, n]
            f_anchor = f
            if i >= n_time:
                force[b, n] = f
                anchor[b, n] = -2 if slipping else last_slip
