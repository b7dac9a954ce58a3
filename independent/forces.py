"""Joint forces written from their physical definitions in plain numpy, and the joint they make.

Every force is a frozen dataclass of its physical sizes whose :meth:`Force.force` (memoryless
forces) or :meth:`Hysteretic.periodic` (forces with a state) evaluates the mass-normalised force
(m/s²) on arrays of any shape; fields may themselves be arrays that broadcast against the
samples, which is how :mod:`independent.phase_resonance` evaluates many assemblies at once.
Nothing here is taken from the library: the catalogue's names (:data:`CATALOGUE_FORCES`) are
used only so that a study can build the same physics from a catalogue model's numbers.

The equation they enter is ``ẍ + ω0² x + 2 ζ ω0 ẋ + Σ f_i(x, ẋ) = −a_base(t)``
(:class:`JointSpec`), ``x`` the displacement relative to the base.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "CATALOGUE_FORCES",
    "AbsStiffness",
    "Clearance",
    "CoulombFriction",
    "CubicDamping",
    "CubicStiffness",
    "DisplacementVelocitySquared",
    "Exponential",
    "Force",
    "Hysteretic",
    "Iwan",
    "JointSpec",
    "Microslip",
    "PowerLawDamping",
    "PreloadedContact",
    "QuadraticDamping",
    "QuadraticStiffness",
    "StiffnessDampingCoupling",
    "StribeckFriction",
    "TanhSaturation",
    "VanDerPol",
    "VelocitySquared",
]

#: The sign's regularisation velocity of the friction forces (m/s): ``sign(v) ≈ tanh(v/v_reg)``,
#: the smoothing the project's docs state for its integrators.
SIGN_VELOCITY_M_S = 1e-4


@dataclass(frozen=True)
class Force:
    """A joint force term. Subclasses define :meth:`force` (or are :class:`Hysteretic`).

    Class facts: ``size_fields`` are the fields an assembly's population scatter draws
    (lognormal, :meth:`drawn`); ``smooth`` says whether the force is smooth enough in
    ``(x, ẋ)`` for few samples per period (kinks and jumps need more).
    """

    size_fields: ClassVar[tuple[str, ...]] = ("coefficient",)
    smooth: ClassVar[bool] = True
    hysteretic: ClassVar[bool] = False

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Force per unit mass (m/s²) at displacement ``x`` (m) and velocity ``v`` (m/s)."""
        raise NotImplementedError

    def drawn(self, rng: np.random.Generator, spread: float) -> Force:
        """This force with each of ``size_fields`` times ``exp(spread·N(0, 1))``."""
        return dataclasses.replace(
            self,
            **{
                name: getattr(self, name) * np.exp(spread * rng.standard_normal())
                for name in self.size_fields
            },
        )


# ---------------------------------------------------------------------------
# Memoryless forces of the catalogue: coefficient × shape function.


@dataclass(frozen=True)
class QuadraticStiffness(Force):
    """``c x²`` (1/(m·s²)): an asymmetric spring."""

    coefficient: float

    def force(self, x, v):
        return self.coefficient * x * x


@dataclass(frozen=True)
class CubicStiffness(Force):
    """``c x³`` (1/(m²·s²)): membrane stretching, hardening for c > 0."""

    coefficient: float

    def force(self, x, v):
        return self.coefficient * x * x * x


@dataclass(frozen=True)
class AbsStiffness(Force):
    """``c x|x|`` (1/(m·s²)): a spring that stiffens (or softens) with |x| alike both ways."""

    coefficient: float
    smooth: ClassVar[bool] = False

    def force(self, x, v):
        return self.coefficient * x * np.abs(x)


@dataclass(frozen=True)
class QuadraticDamping(Force):
    """``c ẋ|ẋ|`` (1/m): drag that grows as the velocity squared."""

    coefficient: float
    smooth: ClassVar[bool] = False

    def force(self, x, v):
        return self.coefficient * v * np.abs(v)


@dataclass(frozen=True)
class CubicDamping(Force):
    """``c ẋ³`` (s/m²): nonlinear viscous damping."""

    coefficient: float

    def force(self, x, v):
        return self.coefficient * v * v * v


@dataclass(frozen=True)
class VelocitySquared(Force):
    """``c ẋ²`` (1/m): a force that pushes one way whichever way the joint moves."""

    coefficient: float

    def force(self, x, v):
        return self.coefficient * v * v


@dataclass(frozen=True)
class StiffnessDampingCoupling(Force):
    """``c x ẋ`` (1/(m·s)): damping that changes sign with the displacement."""

    coefficient: float

    def force(self, x, v):
        return self.coefficient * x * v


@dataclass(frozen=True)
class DisplacementVelocitySquared(Force):
    """``c x ẋ²`` (1/m²): a stiffness that grows with the velocity squared."""

    coefficient: float

    def force(self, x, v):
        return self.coefficient * x * v * v


@dataclass(frozen=True)
class VanDerPol(Force):
    """``c x² ẋ`` (1/(m²·s)): damping that grows with the displacement squared."""

    coefficient: float

    def force(self, x, v):
        return self.coefficient * x * x * v


@dataclass(frozen=True)
class CoulombFriction(Force):
    """``F sign(ẋ)``, the sign smoothed to ``tanh(ẋ/v_reg)``: dry friction, slip force F (m/s²)."""

    coefficient: float
    v_reg: float = SIGN_VELOCITY_M_S
    smooth: ClassVar[bool] = False

    def force(self, x, v):
        return self.coefficient * np.tanh(v / self.v_reg)


@dataclass(frozen=True)
class StribeckFriction(Force):
    """``F sign(ẋ) exp(−(ẋ/v_s)²)``: friction that falls from F at rest over velocities ~ v_s."""

    coefficient: float
    v_s: float = 1e-2
    v_reg: float = SIGN_VELOCITY_M_S
    smooth: ClassVar[bool] = False

    def force(self, x, v):
        return self.coefficient * np.tanh(v / self.v_reg) * np.exp(-((v / self.v_s) ** 2))


@dataclass(frozen=True)
class TanhSaturation(Force):
    """``c tanh(x/x_s)`` (m/s²): a spring of stiffness c/x_s at rest that saturates at c."""

    coefficient: float
    x_s: float = 1e-3

    def force(self, x, v):
        return self.coefficient * np.tanh(x / self.x_s)


@dataclass(frozen=True)
class Exponential(Force):
    """``c (exp(x/x_s) − 1)`` (m/s²): a spring of stiffness c/x_s at rest, stiffer one way."""

    coefficient: float
    x_s: float = 1e-3

    def force(self, x, v):
        return self.coefficient * np.expm1(x / self.x_s)


# ---------------------------------------------------------------------------
# Forces with a state: banks of Jenkins sliders.


@dataclass(frozen=True)
class Hysteretic(Force):
    """A bank of Jenkins elements (spring ``k_i`` in series with a slider of slip force ``F_i``)
    in parallel, acting on the joint displacement; subclasses give :meth:`sliders`.

    Each element's force ``f_i`` follows ``ḟ_i = k_i ẋ`` while ``|f_i| < F_i`` or the motion
    unloads it, and stays at ``±F_i`` while it slips; the joint force is ``Σ f_i``. Rate
    independent, so a displacement path fixes it (:meth:`along`).
    """

    smooth: ClassVar[bool] = False
    hysteretic: ClassVar[bool] = True

    def sliders(self) -> tuple[np.ndarray, np.ndarray]:
        """Stiffness ``k_i`` (1/s²) and slip force ``F_i`` (m/s²) of every element, on the
        last axis: fields shaped to broadcast against samples ``(..., n_t)`` give elements
        ``(..., n_elements)`` (their time axis of length 1 becomes the elements' axis)."""
        raise NotImplementedError

    def along(
        self, x: np.ndarray, state: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Force along the displacement path ``x`` (last axis: time), from ``state``.

        ``state`` is the elements' forces where the path starts (default: unstressed at
        ``x = 0``, loaded straight to the path's first sample). Between samples the path is
        taken as monotonic, where the element's return map is exact. Returns the force
        ``(..., n_t)`` and the elements' forces at the last sample.
        """
        k, f_slip = self.sliders()
        x = np.asarray(x, dtype=float)
        if state is None:
            state = np.clip(k * x[..., :1], -f_slip, f_slip)
        shape = np.broadcast_shapes((*x.shape[:-1], 1), k.shape, state.shape)
        state = np.array(np.broadcast_to(state, shape))
        low = np.array(np.broadcast_to(-f_slip, shape))
        high = -low
        # Time first, so that each step reads and writes contiguous memory.
        steps = np.moveaxis(np.diff(x, axis=-1), -1, 0)[..., None]
        out = np.empty((x.shape[-1], *shape[:-1]))
        out[0] = state.sum(-1)
        increment = np.empty(shape)
        for j, dx in enumerate(steps, start=1):
            np.multiply(k, dx, out=increment)
            state += increment
            np.minimum(state, high, out=state)
            np.maximum(state, low, out=state)
            out[j] = state.sum(-1)
        return np.moveaxis(out, 0, -1), state

    def periodic(self, x: np.ndarray, max_periods: int = 8) -> np.ndarray:
        """Force along one period of the periodic path ``x`` once the loop has closed.

        Each path is marched from its largest displacement, where an element that slips
        over the cycle (``k_i (x_max − x_min) ≥ 2 F_i``) carries ``+F_i`` and one that
        sticks carries what loading from rest (``x = 0``, unstressed) gave it, ``k_i x_max``
        (within ``±F_i``); the march repeats until the elements' forces at the period's end
        are those at its start (to 1e-12 of the slip forces).
        """
        x = np.asarray(x, dtype=float)
        k, f_slip = self.sliders()
        n = x.shape[-1]
        top = np.argmax(x, axis=-1)[..., None]
        order = (top + np.arange(n + 1)) % n
        rolled = np.take_along_axis(x, order, axis=-1)  # from the maximum back to it
        x_max = rolled[..., :1]
        span = x_max - np.min(x, axis=-1, keepdims=True)
        state = np.where(k * span >= 2 * f_slip, f_slip, np.clip(k * x_max, -f_slip, f_slip))
        for _ in range(max_periods):
            force, end = self.along(rolled, state)
            if np.all(np.abs(end - state) <= 1e-12 * np.max(f_slip)):
                out = np.empty((*force.shape[:-1], n))
                np.put_along_axis(out, np.broadcast_to(order[..., :n], out.shape), force[..., :n],
                                  axis=-1)  # fmt: skip
                return out
            state = end
        raise RuntimeError("the hysteresis loop did not close: is the path periodic?")

    def rate(self, state: np.ndarray, v: np.ndarray) -> np.ndarray:
        """``ḟ_i`` of the elements at forces ``state`` and joint velocity ``v`` (for an ODE)."""
        k, f_slip = self.sliders()
        slipping = (np.abs(state) >= f_slip) & (state * v[..., None] > 0)
        return np.where(slipping, 0.0, k * v[..., None])

    def from_state(self, state: np.ndarray) -> np.ndarray:
        """Joint force of the elements' forces ``state`` (clipped to the slip forces)."""
        _, f_slip = self.sliders()
        return np.clip(state, -f_slip, f_slip).sum(-1)


@dataclass(frozen=True)
class Microslip(Hysteretic):
    """``c`` times a Jenkins element of stiffness ``k_t`` (1/s²) and slip force ``F_s`` (m/s²):
    a joint that sticks below ``F_s/k_t`` and slips beyond (the catalogue's microslip)."""

    coefficient: float
    k_t: float = 1e5
    F_s: float = 1.0
    size_fields: ClassVar[tuple[str, ...]] = ("coefficient", "F_s")

    def sliders(self):
        one = np.ones(1)
        return self.coefficient * self.k_t * one, self.coefficient * self.F_s * one


@dataclass(frozen=True)
class Iwan(Hysteretic):
    """An Iwan joint: ``n_sliders`` Jenkins elements of equal stiffness whose slip
    displacements are spread with density ∝ ``φ^chi`` on ``(0, φ_max]``.

    Attributes
    ----------
    stiffness
        Stiffness of the stuck joint, the elements' sum (1/s²).
    macroslip_force
        Force at which every element slips, the slip forces' sum (m/s²).
    chi
        Exponent of the slip-displacement density (−1 < chi; 0 is uniform, negative puts
        more elements at small slip: the microslip regime of bolted joints).
    n_sliders
        Elements; element ``i`` sits at the ``(i − ½)/n`` quantile of the density.
    """

    stiffness: float
    macroslip_force: float
    chi: float = -0.5
    n_sliders: int = 12
    size_fields: ClassVar[tuple[str, ...]] = ("macroslip_force",)

    def sliders(self):
        quantiles = (np.arange(self.n_sliders) + 0.5) / self.n_sliders
        # The density ∝ φ^chi has the CDF (φ/φ_max)^(chi+1).
        relative_slip = quantiles ** (1.0 / (self.chi + 1.0))
        k = self.stiffness / self.n_sliders * np.ones(self.n_sliders)
        phi_max = self.macroslip_force / (k * relative_slip).sum(-1, keepdims=True)
        return k, k * phi_max * relative_slip


# ---------------------------------------------------------------------------
# Memoryless forces outside the catalogue.


@dataclass(frozen=True)
class Clearance(Force):
    """A symmetric free play of half-width ``gap_m`` closing on a spring ``contact_stiffness``
    (1/s²): no force while ``|x| < gap_m``, ``k (|x| − gap) sign(x)`` beyond."""

    gap_m: float
    contact_stiffness: float
    size_fields: ClassVar[tuple[str, ...]] = ("gap_m",)
    smooth: ClassVar[bool] = False

    def force(self, x, v):
        return self.contact_stiffness * np.sign(x) * np.maximum(np.abs(x) - self.gap_m, 0.0)


@dataclass(frozen=True)
class PreloadedContact(Force):
    """A one-sided contact of stiffness ``contact_stiffness`` (1/s²) closed at rest under the
    preload ``preload`` (m/s²): it adds ``k x`` while closed and lifts off at ``x = −P/k``,
    where it has given back its preload and carries nothing more."""

    contact_stiffness: float
    preload: float
    size_fields: ClassVar[tuple[str, ...]] = ("preload",)
    smooth: ClassVar[bool] = False

    def force(self, x, v):
        return self.contact_stiffness * np.maximum(x, -self.preload / self.contact_stiffness)


@dataclass(frozen=True)
class PowerLawDamping(Force):
    """``c |ẋ|^p sign(ẋ)``; with ``v_reg > 0`` rounded to ``c ẋ (ẋ² + v_reg²)^((p−1)/2)``."""

    coefficient: float
    exponent: float
    v_reg: float = 0.0
    smooth: ClassVar[bool] = False

    def force(self, x, v):
        return self.coefficient * v * (v * v + self.v_reg**2) ** ((self.exponent - 1) / 2)


#: The library catalogue's nonlinear effects, by their public names, as forces of this module
#: with the same coefficient and shape-parameter names (``coefficient``, ``v_reg``, ``v_s``,
#: ``x_s``, ``k_t``, ``F_s``). The linear terms are :class:`JointSpec`'s own fields.
CATALOGUE_FORCES: dict[str, type[Force]] = {
    "quadratic_stiffness": QuadraticStiffness,
    "cubic_stiffness": CubicStiffness,
    "abs_stiffness": AbsStiffness,
    "quadratic_damping": QuadraticDamping,
    "cubic_damping": CubicDamping,
    "velocity_squared": VelocitySquared,
    "stiffness_damping_coupling": StiffnessDampingCoupling,
    "displacement_velocity_squared": DisplacementVelocitySquared,
    "van_der_pol": VanDerPol,
    "coulomb_friction": CoulombFriction,
    "stribeck_friction": StribeckFriction,
    "tanh_saturation": TanhSaturation,
    "exponential": Exponential,
    "microslip": Microslip,
}


@dataclass(frozen=True)
class JointSpec:
    """A base-excited joint: ``ẍ + ω0² x + 2 ζ ω0 ẋ + Σ terms = −a_base``, mass-normalised.

    Attributes
    ----------
    natural_frequency_hz
        Linear natural frequency ``ω0/2π`` of the linear spring alone (Hz). Terms that
        stiffen the joint at rest (a stuck slider, a closed contact) add to it.
    damping_ratio
        Viscous damping ratio ``ζ`` of the linear part.
    terms
        The nonlinear force terms, each with its sizes.
    """

    natural_frequency_hz: float
    damping_ratio: float
    terms: tuple[Force, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "terms", tuple(self.terms))
        if not np.all(np.asarray(self.natural_frequency_hz) > 0):
            raise ValueError(f"natural_frequency_hz must be > 0, got {self.natural_frequency_hz}")

    @property
    def omega0_rad_s(self) -> np.ndarray | float:
        """Linear natural angular frequency (rad/s)."""
        return 2 * np.pi * self.natural_frequency_hz

    @property
    def hysteretic(self) -> bool:
        """Whether a term has a state (a periodic path needs :meth:`periodic_force`)."""
        return any(t.hysteretic for t in self.terms)

    @property
    def smooth(self) -> bool:
        """Whether every term is smooth (few samples per period resolve it)."""
        return all(t.smooth for t in self.terms)

    def memoryless_force(self, x: ArrayLike, v: ArrayLike) -> np.ndarray:
        """Linear and memoryless terms' force (m/s²) at ``(x, ẋ)``."""
        w0 = self.omega0_rad_s
        total = w0 * w0 * np.asarray(x) + 2 * self.damping_ratio * w0 * np.asarray(v)
        for term in self.terms:
            if not term.hysteretic:
                total = total + term.force(x, v)
        return total

    def periodic_force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Total force along one period of a periodic motion (last axis: time), hysteresis
        loops closed (:meth:`Hysteretic.periodic`)."""
        total = self.memoryless_force(x, v)
        for term in self.terms:
            if term.hysteretic:
                total = total + term.periodic(x)
        return total

    def drawn(
        self,
        rng: np.random.Generator,
        stiffness_spread: float,
        damping_spread: float,
        size_spread: float,
    ) -> JointSpec:
        """An assembly around this joint: ``ω0²`` times ``exp(stiffness_spread·N)``, ``ζ``
        times ``exp(damping_spread·N)`` and every term's sizes times ``exp(size_spread·N)``
        (drawn in that order)."""
        stiffness = np.exp(stiffness_spread * rng.standard_normal())
        damping = np.exp(damping_spread * rng.standard_normal())
        return JointSpec(
            self.natural_frequency_hz * np.sqrt(stiffness),
            self.damping_ratio * damping,
            tuple(t.drawn(rng, size_spread) for t in self.terms),
        )


def stacked(joints: list[JointSpec], shape: tuple[int, ...]) -> JointSpec:
    """One joint whose numbers are arrays, joint ``j``'s on row ``j`` reshaped to ``shape``
    (e.g. ``(-1, 1, 1)``) so that they broadcast against samples of many joints at once.

    The joints must have the same kinds of terms in the same order, and equal integer fields.
    """
    kinds = [tuple(type(t) for t in j.terms) for j in joints]
    if any(k != kinds[0] for k in kinds):
        raise ValueError("joints evaluated together need the same kinds of terms in one order")

    def column(values: list) -> np.ndarray | int:
        if isinstance(values[0], int | np.integer):
            if any(v != values[0] for v in values):
                raise ValueError("integer fields (slider counts) must agree across joints")
            return values[0]
        return np.asarray(values, dtype=float).reshape(shape)

    terms = tuple(
        type(first)(
            **{
                f.name: column([getattr(j.terms[i], f.name) for j in joints])
                for f in dataclasses.fields(first)
            }
        )
        for i, first in enumerate(joints[0].terms)
    )
    return JointSpec(
        column([j.natural_frequency_hz for j in joints]),
        column([j.damping_ratio for j in joints]),
        terms,
    )
