"""The equations a prediction integrates: a one-mode or N-mode model as first-order ODEs.

Both kinds of model read as N modal oscillators with joint elements and polynomial
couplings (:mod:`identification.multimode.model`)::

    η̈_m = −ω_m² η_m − 2ζ_m ω_m η̇_m − Σ_j φ_jm Σ_e c_e φ_e(q_j, q̇_j) − couplings_m − Γ_m a_base(t)

A :class:`~identification.model.JointModel` is one mode with ``ω = ζ = 0``, unit shape and
participation, every term (its linear stiffness and viscous damping included) a joint
element: its equation ``ẍ + Σ c_i φ_i(x, ẋ) = −a_base`` as it stands, whatever the signs of
its coefficients (a negative damping is kept, and diverges). The hysteretic Jenkins element
is carried in its differential form, as :meth:`JointModel.rhs` does: its slider force ``z``
is a state, ``ż = k_t q̇`` while it sticks and 0 while it slips.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from identification.effects import CATALOGUE, VISCOUS_DAMPING
from identification.model import JointModel
from identification.multimode.model import ModalModel

__all__ = ["ModelEquations", "model_equations"]


@dataclass(frozen=True)
class _Element:
    """A memoryless joint element: ``coefficient · φ(q_joint, q̇_joint)``."""

    joint: int
    coefficient: float
    effect: str
    shape: dict[str, float]

    @property
    def kernel(self) -> tuple[Callable[..., float], float, float]:
        """``(force kernel, p0, p1)``: the catalogue's scalar force of the effect."""
        effect = CATALOGUE[self.effect]
        return (effect.force, *effect.shape_values(**self.shape))


@dataclass(frozen=True)
class _Slider:
    """A Jenkins element on a joint: force ``coefficient · z``, stiffness ``k_t``, slip ``f_s``."""

    joint: int
    coefficient: float
    k_t: float
    f_s: float


@dataclass(frozen=True, eq=False)
class ModelEquations:
    """First-order equations of a model, state ``[η (N), η̇ (N), z (H)]``.

    Attributes
    ----------
    frequencies_hz
        ``(N,)`` linear frequency of each mode (joint elements' linear stiffness included
        for a one-mode JointModel), the basis of the initial-state fit and of the delay
        embedding's length.
    decay_rates
        ``(N,)`` linear decay rate ``ζω`` of each mode (1/s; negative: the mode grows).
    stiffness, damping, participation
        ``(N,)`` ``ω_m²``, ``2ζ_m ω_m`` and ``Γ_m`` of the modal oscillators.
    joint_shapes
        ``(J, N)`` shapes of the joint coordinates.
    elements, sliders
        The memoryless and the hysteretic joint elements.
    couplings
        ``(equation, powers, coefficient)`` of every polynomial coupling.
    """

    frequencies_hz: np.ndarray
    decay_rates: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    participation: np.ndarray
    joint_shapes: np.ndarray
    elements: tuple[_Element, ...]
    sliders: tuple[_Slider, ...]
    couplings: tuple[tuple[int, np.ndarray, float], ...]

    @property
    def n_modes(self) -> int:
        return self.stiffness.size

    @property
    def state_size(self) -> int:
        return 2 * self.n_modes + len(self.sliders)

    def initial_state(self, eta: np.ndarray, eta_dot: np.ndarray) -> np.ndarray:
        """The state at modal displacements and velocities: each slider stuck since the origin
        (its force ``k_t q`` up to the slip force), so the joint starts centred."""
        q = self.joint_shapes @ eta
        z = [np.clip(s.k_t * q[s.joint], -s.f_s, s.f_s) for s in self.sliders]
        return np.concatenate([eta, eta_dot, z])

    def accelerations(self, state: np.ndarray, base_acceleration: np.ndarray | float) -> np.ndarray:
        """``η̈`` of states ``(state_size, …)`` under the base acceleration (broadcast)."""
        n = self.n_modes
        eta, eta_dot, z = state[:n], state[n : 2 * n], state[2 * n :]
        column = (slice(None),) + (None,) * (eta.ndim - 1)
        acc = -self.stiffness[column] * eta - self.damping[column] * eta_dot
        acc = acc - self.participation[column] * base_acceleration
        q = np.tensordot(self.joint_shapes, eta, axes=1)
        q_dot = np.tensordot(self.joint_shapes, eta_dot, axes=1)
        for e in self.elements:
            force = e.coefficient * CATALOGUE[e.effect].feature(
                q[e.joint], q_dot[e.joint], **e.shape
            )
            acc = acc - self.joint_shapes[e.joint][column] * force
        for i, s in enumerate(self.sliders):
            acc = acc - self.joint_shapes[s.joint][column] * (s.coefficient * z[i])
        for mode, powers, coefficient in self.couplings:
            acc[mode] = acc[mode] - coefficient * np.prod(
                [eta[k] ** p for k, p in enumerate(powers)], axis=0
            )
        return acc

    def derivative(self) -> Callable[[np.ndarray, float], np.ndarray]:
        """``dstate/dt`` as a function of the state and the base acceleration (m/s²)."""
        n = self.n_modes
        # Scalar kernels in the integrator's loop: the vectorised features cost ~10× per call.
        kernels = [(e.joint, e.coefficient, *e.kernel) for e in self.elements]
        shapes = self.joint_shapes
        stiffness, damping, participation = self.stiffness, self.damping, self.participation
        couplings = [(mode, [(k, p) for k, p in enumerate(powers) if p], c)
                     for mode, powers, c in self.couplings]  # fmt: skip

        def derivative(state: np.ndarray, a: float) -> np.ndarray:
            eta, eta_dot = state[:n], state[n : 2 * n]
            acc = -stiffness * eta - damping * eta_dot - participation * a
            q, q_dot = shapes @ eta, shapes @ eta_dot
            for joint, c, force, p0, p1 in kernels:
                acc -= shapes[joint] * (c * force(q[joint], q_dot[joint], p0, p1))
            out = np.empty_like(state)
            for i, s in enumerate(self.sliders):
                z = state[2 * n + i]
                acc -= shapes[s.joint] * (s.coefficient * z)
                v = q_dot[s.joint]
                sticking = abs(z) < s.f_s or z * v < 0
                out[2 * n + i] = s.k_t * v if sticking else 0.0
            for mode, factors, c in couplings:
                term = c
                for k, p in factors:
                    term *= eta[k] ** p
                acc[mode] -= term
            out[:n] = eta_dot
            out[n : 2 * n] = acc
            return out

        return derivative


def model_equations(model: JointModel | ModalModel) -> ModelEquations:
    """The equations of a one-mode :class:`JointModel` or an N-mode :class:`ModalModel`."""
    if isinstance(model, JointModel):
        k = model.linear_stiffness
        if not k > 0:
            raise ValueError(f"the model has no positive linear stiffness (k = {k}): no mode")
        omega = np.sqrt(k)
        damping = model.coefficient(VISCOUS_DAMPING)
        elements = tuple(
            _Element(0, t.coefficient, t.effect, dict(t.shape))
            for t in model.terms
            if not t.hysteretic
        )
        sliders = tuple(_slider(0, t.coefficient, t.effect, t.shape) for t in model.stateful_terms)
        return ModelEquations(
            frequencies_hz=np.array([omega / (2 * np.pi)]),
            decay_rates=np.array([0.5 * damping]),
            stiffness=np.zeros(1),
            damping=np.zeros(1),
            participation=np.ones(1),
            joint_shapes=np.ones((1, 1)),
            elements=elements,
            sliders=sliders,
            couplings=(),
        )
    if not isinstance(model, ModalModel):
        raise ValueError(f"a prediction needs a JointModel or a ModalModel, got {type(model)}")
    omega = 2 * np.pi * np.array([m.frequency_hz for m in model.modes])
    zeta = np.array([m.damping_ratio for m in model.modes])
    elements, sliders = [], []
    for e in model.elements:
        if CATALOGUE[e.effect].hysteretic:
            sliders.append(_slider(e.joint - 1, e.coefficient, e.effect, e.shape))
        else:
            elements.append(_Element(e.joint - 1, e.coefficient, e.effect, dict(e.shape)))
    return ModelEquations(
        frequencies_hz=omega / (2 * np.pi),
        decay_rates=zeta * omega,
        stiffness=omega**2,
        damping=2 * zeta * omega,
        participation=np.array([m.participation for m in model.modes]),
        joint_shapes=np.array(model.joint_shapes, dtype=float).reshape(-1, omega.size),
        elements=tuple(elements),
        sliders=tuple(sliders),
        couplings=tuple((c.mode - 1, np.array(c.powers), c.coefficient) for c in model.couplings),
    )


def _slider(joint: int, coefficient: float, effect: str, shape) -> _Slider:
    k_t, f_s = CATALOGUE[effect].shape_values(**dict(shape))
    return _Slider(joint, coefficient, k_t, f_s)
