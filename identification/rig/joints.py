"""Joint physics outside the effects catalogue, for the lab rig.

Real joints do not read the catalogue. These forces let the lab rig
(:mod:`identification.rig.lab`) write records of structures whose physics no
catalogue term reproduces, so that model criticism can be tested on what it must
learn to call "not explained by the catalogue". They live here, in the rig, and
never in :mod:`identification.effects`.

Every force is mass-normalised (m/s²) and acts on the *joint displacement* ``u``
(m): the first modal coordinate, plus ``joint_shape`` times the second modal
coordinate when the rig has a :class:`SecondMode`. Each class owns its facts:
parameters with units, a one-line description, its numba force kernel and its
single-harmonic describing function (equivalent stiffness and viscous damping at
amplitude ``a``, used to place test levels and to show what a free-form
reference should find).

* :class:`IwanJoint` — Segalman's four-parameter Iwan element: ``N`` Jenkins
  sliders in parallel whose slip displacements follow a power-law density
  ``R φ^χ`` on ``(0, φ_max)`` plus a share ``β`` at ``φ_max``; χ = 0 is the
  uniform density. Below macroslip it dissipates ``4R a^(χ+3)/((χ+2)(χ+3))`` per
  cycle — a power law in amplitude with exponent 2.5–3 for bolted joints —
  which no single Jenkins element (exponent 3 only at the onset) follows.
* :class:`Clearance` — a symmetric gap: free within ``±gap_m``, a contact spring
  beyond (hardening that starts at the gap, not polynomial).
* :class:`PreloadedContact` — a one-sided contact closed at rest under a preload:
  stiff while it stays closed, it lifts off below ``−preload/contact_stiffness``
  (bilinear softening and a mean shift; the bilinear oscillator at zero preload).
* :class:`PowerLawDamping` — ``c·|u̇|^α·sign(u̇)`` with a non-integer ``α``
  (between viscous, Coulomb and quadratic; e.g. material or radiation damping).
* :class:`SecondMode` — not a force: a second modal degree of freedom a few to
  twenty per cent above the first, coupled through the measured response (its
  shape at the centre point) and through the joint (its share of the joint
  displacement).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from typing import Any, ClassVar

import numba
import numpy as np
from numpy.typing import ArrayLike
from scipy import special

from identification.effects import HYSTERETIC, jenkins_force

__all__ = [
    "JOINTS",
    "Clearance",
    "IwanJoint",
    "Joint",
    "PowerLawDamping",
    "PreloadedContact",
    "SecondMode",
    "iwan_force",
    "iwan_update",
    "joint_from_dict",
    "memoryless_joint_force",
]

#: numba dispatch codes of the memoryless joints (the Iwan element is hysteretic).
_CLEARANCE, _CONTACT, _POWER_LAW = 1, 2, 3


def _check(where: str, value: float, low: float = 0.0, strict: bool = True) -> float:
    value = float(value)
    ok = math.isfinite(value) and (value > low if strict else value >= low)
    if not ok:
        raise ValueError(f"{where} must be finite and {'>' if strict else '≥'} {low}, got {value}")
    return value


@dataclass(frozen=True)
class Joint:
    """A joint force outside the catalogue: its parameters, units and facts.

    Subclasses are frozen dataclasses whose float fields are the parameters
    (SI units in :attr:`units`).
    """

    name: ClassVar[str] = ""
    kind: ClassVar[int] = 0
    description: ClassVar[str] = ""
    units: ClassVar[Mapping[str, str]] = {}

    @property
    def parameters(self) -> dict[str, float]:
        """Parameter values by name (SI)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    @property
    def variable_parameters(self) -> list[str]:
        """Parameters an assembly may draw with a spread (the real-valued ones)."""
        return [f.name for f in fields(self) if isinstance(getattr(self, f.name), float)]

    def with_parameters(self, values: Mapping[str, float]) -> Joint:
        """A copy with the named parameters set."""
        unknown = set(values) - set(self.parameters)
        if unknown:
            raise ValueError(
                f"{self.name}: unknown parameter(s) {sorted(unknown)}; "
                f"it has {list(self.parameters)}"
            )
        return replace(self, **values)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description (``joint_from_dict`` reads it back)."""
        return {"joint": self.name, **self.parameters}

    def kernel_parameters(self) -> tuple[float, float, float]:
        """``(p0, p1, p2)`` for :func:`memoryless_joint_force`."""
        return 0.0, 0.0, 0.0

    def describing(self, a: ArrayLike, omega: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Equivalent stiffness (1/s²) and viscous damping (1/s) at amplitude ``a`` (m)."""
        raise NotImplementedError

    @property
    def small_amplitude_stiffness(self) -> float:
        """Equivalent stiffness at small amplitude (1/s²): the tangent at rest, or the
        describing function's limit where the force has a kink there."""
        return 0.0

    @property
    def stiffness_bound(self) -> float:
        """Largest tangent stiffness anywhere (1/s²), for the integrator's step."""
        return self.small_amplitude_stiffness

    @property
    def damping_slope_bound(self) -> float:
        """Largest ∂force/∂u̇ over the velocities of a test (1/s), for the integrator's step."""
        return 0.0


@dataclass(frozen=True)
class IwanJoint(Joint):
    """Segalman's four-parameter Iwan element, discretised into ``n_sliders`` Jenkins sliders.

    Attributes
    ----------
    stiffness
        ``K_T``, stiffness of the stuck joint (1/s², mass-normalised).
    macroslip_force
        ``F_S``, force at which the whole joint slips (m/s²).
    chi
        Exponent χ of the slip-displacement density ``R φ^χ`` (−1 < χ ≤ 0; 0 is uniform).
    beta
        β ≥ 0, stiffness share of the sliders at ``φ_max`` relative to the power-law part.
    n_sliders
        Sliders of the discretisation (≥ 2).

    Notes
    -----
    With ``P = K_T/(1+β)`` the power-law part's stiffness,
    ``φ_max = F_S (1+β) / (K_T (β + (χ+1)/(χ+2)))`` and ``R = P (χ+1) / φ_max^(χ+1)``
    (Segalman 2005). The power-law part is cut into bins of equal stiffness, each
    slider at its bin's density-weighted mean slip displacement, so the
    discretisation keeps ``K_T`` and ``F_S`` exactly; with β > 0 one more slider
    carries ``S = βP`` at ``φ_max``.
    """

    stiffness: float
    macroslip_force: float
    chi: float = -0.5
    beta: float = 0.0
    n_sliders: int = 40

    name: ClassVar[str] = "iwan"
    description: ClassVar[str] = (
        "Iwan joint: Jenkins sliders in parallel with a power-law density of slip forces "
        "(microslip dissipation ∝ amplitude^(χ+3), then macroslip)"
    )
    units: ClassVar[Mapping[str, str]] = {
        "stiffness": "1/s²",
        "macroslip_force": "m/s²",
        "chi": "1",
        "beta": "1",
        "n_sliders": "1",
    }

    def __post_init__(self) -> None:
        object.__setattr__(self, "stiffness", _check("IwanJoint.stiffness", self.stiffness))
        object.__setattr__(
            self, "macroslip_force", _check("IwanJoint.macroslip_force", self.macroslip_force)
        )
        chi = float(self.chi)
        if not (-1.0 < chi <= 0.0):
            raise ValueError(f"IwanJoint.chi must be in (−1, 0], got {chi}")
        object.__setattr__(self, "chi", chi)
        object.__setattr__(self, "beta", _check("IwanJoint.beta", self.beta, strict=False))
        n = self.n_sliders
        if not isinstance(n, int | np.integer) or isinstance(n, bool) or n < 2:
            raise ValueError(f"IwanJoint.n_sliders must be an integer ≥ 2, got {n!r}")
        object.__setattr__(self, "n_sliders", int(n))

    @property
    def slip_displacement_max(self) -> float:
        """``φ_max`` (m): the largest slip displacement; macroslip beyond it."""
        chi, beta = self.chi, self.beta
        return self.macroslip_force * (1 + beta) / (self.stiffness * (beta + (chi + 1) / (chi + 2)))

    @property
    def density_coefficient(self) -> float:
        """``R`` of the density ``R φ^χ`` (1/s² per m^(χ+1))."""
        power_law_stiffness = self.stiffness / (1 + self.beta)
        return power_law_stiffness * (self.chi + 1) / self.slip_displacement_max ** (self.chi + 1)

    def sliders(self) -> tuple[np.ndarray, np.ndarray]:
        """Stiffness (1/s²) and slip force (m/s²) of each slider."""
        chi, phi_max = self.chi, self.slip_displacement_max
        power_law_stiffness = self.stiffness / (1 + self.beta)
        bins = self.n_sliders - (1 if self.beta > 0 else 0)
        edges = phi_max * (np.arange(bins + 1) / bins) ** (1 / (chi + 1))
        lo, hi = edges[:-1], edges[1:]
        # density-weighted mean slip displacement of each bin
        phi = (
            (chi + 1)
            / (chi + 2)
            * (hi ** (chi + 2) - lo ** (chi + 2))
            / (hi ** (chi + 1) - lo ** (chi + 1))
        )
        stiffness = np.full(bins, power_law_stiffness / bins)
        if self.beta > 0:
            stiffness = np.append(stiffness, self.beta * power_law_stiffness)
            phi = np.append(phi, phi_max)
        return stiffness, stiffness * phi

    def dissipation_per_cycle(self, amplitude_m: ArrayLike) -> np.ndarray:
        """Energy per unit mass dissipated in one cycle of amplitude ``a`` (m²/s²), discretised.

        A Jenkins slider of stiffness ``k`` and slip force ``F`` loaded between
        ±a > F/k dissipates ``4F(a − F/k)``, whatever the path between the turning points.
        """
        a = np.asarray(amplitude_m, float)[..., None]
        k, f = self.sliders()
        return np.sum(np.where(a > f / k, 4.0 * f * (a - f / k), 0.0), axis=-1)

    def describing(self, a: ArrayLike, omega: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Sum of the sliders' Masing describing functions (the catalogue's Jenkins element)."""
        a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
        jenkins = HYSTERETIC.describing
        k_eq, c_eq = np.zeros(a.shape), np.zeros(a.shape)
        for k_t, f_s in zip(*self.sliders(), strict=True):
            k_i, c_i = jenkins(a, omega, k_t=k_t, F_s=f_s)
            k_eq, c_eq = k_eq + k_i, c_eq + c_i
        return k_eq, c_eq

    @property
    def small_amplitude_stiffness(self) -> float:
        return self.stiffness


@dataclass(frozen=True)
class Clearance(Joint):
    """A symmetric clearance: no force within ``±gap_m``, a contact spring beyond.

    Attributes
    ----------
    gap_m
        Half-width of the free play (m).
    contact_stiffness
        Stiffness of the contact once closed (1/s²).
    """

    gap_m: float
    contact_stiffness: float

    name: ClassVar[str] = "clearance"
    kind: ClassVar[int] = _CLEARANCE
    description: ClassVar[str] = (
        "symmetric clearance: free within ±gap, contact spring beyond (hardening from the gap)"
    )
    units: ClassVar[Mapping[str, str]] = {"gap_m": "m", "contact_stiffness": "1/s²"}

    def __post_init__(self) -> None:
        object.__setattr__(self, "gap_m", _check("Clearance.gap_m", self.gap_m, strict=False))
        object.__setattr__(
            self, "contact_stiffness", _check("Clearance.contact_stiffness", self.contact_stiffness)
        )

    def kernel_parameters(self) -> tuple[float, float, float]:
        return self.gap_m, self.contact_stiffness, 0.0

    def describing(self, a: ArrayLike, omega: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Dead-zone describing function ``k_c (1 − (2/π)(asin r + r√(1 − r²)))``, r = gap/a."""
        a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
        r = np.clip(self.gap_m / np.where(a > 0, a, np.inf), 0.0, 1.0)
        k_eq = self.contact_stiffness * (
            1.0 - 2.0 / np.pi * (np.arcsin(r) + r * np.sqrt(1.0 - r * r))
        )
        return k_eq, np.zeros(a.shape)

    @property
    def small_amplitude_stiffness(self) -> float:
        return self.contact_stiffness if self.gap_m == 0 else 0.0

    @property
    def stiffness_bound(self) -> float:
        return self.contact_stiffness


@dataclass(frozen=True)
class PreloadedContact(Joint):
    """A one-sided contact, closed at rest under a preload, that lifts off.

    The force ``k_c · max(u, −P/k_c)``: the closed contact adds ``k_c`` while
    ``u > −P/k_c``; below, it has opened and carries nothing (relative to rest it
    gives back its preload ``−P``). With ``P = 0`` this is the bilinear oscillator.

    Attributes
    ----------
    contact_stiffness
        ``k_c``, stiffness of the closed contact (1/s²).
    preload
        ``P``, the contact force at rest (m/s², mass-normalised; ≥ 0).
    """

    contact_stiffness: float
    preload: float

    name: ClassVar[str] = "preloaded_contact"
    kind: ClassVar[int] = _CONTACT
    description: ClassVar[str] = (
        "one-sided contact closed under a preload: stiff until it lifts off (bilinear softening "
        "and a mean shift above the lift-off amplitude)"
    )
    units: ClassVar[Mapping[str, str]] = {"contact_stiffness": "1/s²", "preload": "m/s²"}

    def __post_init__(self) -> None:
        object.__setattr__(
            self,
            "contact_stiffness",
            _check("PreloadedContact.contact_stiffness", self.contact_stiffness),
        )
        object.__setattr__(
            self, "preload", _check("PreloadedContact.preload", self.preload, strict=False)
        )

    @property
    def lift_off_m(self) -> float:
        """Displacement below which the contact is open (m, ≤ 0)."""
        return -self.preload / self.contact_stiffness

    def kernel_parameters(self) -> tuple[float, float, float]:
        return self.contact_stiffness, self.preload, 0.0

    def describing(self, a: ArrayLike, omega: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``k_c (θ₀ + (δ/a) sin θ₀)/π`` with ``cos θ₀ = −δ/a``, δ = P/k_c (``k_c`` for a ≤ δ).

        The fundamental of ``k_c max(a cos θ, −δ)`` for an oscillation centred at
        rest; the mean shift it causes is left out (enough to place test levels).
        """
        a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
        ratio = np.clip(-self.lift_off_m / np.where(a > 0, a, np.inf), 0.0, 1.0)
        theta0 = np.arccos(-ratio)
        k_eq = self.contact_stiffness * (theta0 + ratio * np.sin(theta0)) / np.pi
        return k_eq, np.zeros(a.shape)

    @property
    def small_amplitude_stiffness(self) -> float:
        return self.contact_stiffness if self.preload > 0 else 0.5 * self.contact_stiffness

    @property
    def stiffness_bound(self) -> float:
        return self.contact_stiffness


@dataclass(frozen=True)
class PowerLawDamping(Joint):
    """Power-law damping ``c · u̇ · (u̇² + v_reg²)^((α−1)/2)`` ≈ ``c |u̇|^α sign u̇``.

    Attributes
    ----------
    coefficient
        ``c`` (m^(1−α)·s^(α−2), so that the force is in m/s²).
    exponent
        ``α`` > 0 (1 is viscous, 0 Coulomb, 2 quadratic; lab joints show values between).
    v_reg
        Regularising velocity (m/s); required > 0 when α < 1 (the slope at rest is
        infinite otherwise), 0 (exact) allowed for α ≥ 1.
    """

    coefficient: float
    exponent: float
    v_reg: float = 0.0

    name: ClassVar[str] = "power_law_damping"
    kind: ClassVar[int] = _POWER_LAW
    description: ClassVar[str] = (
        "power-law damping c·|v|^α·sign(v) with a non-integer exponent (damping ratio ∝ (aω)^(α−1))"
    )
    units: ClassVar[Mapping[str, str]] = {
        "coefficient": "m^(1−α)·s^(α−2)",
        "exponent": "1",
        "v_reg": "m/s",
    }

    def __post_init__(self) -> None:
        object.__setattr__(
            self, "coefficient", _check("PowerLawDamping.coefficient", self.coefficient)
        )
        object.__setattr__(self, "exponent", _check("PowerLawDamping.exponent", self.exponent))
        object.__setattr__(self, "v_reg", _check("PowerLawDamping.v_reg", self.v_reg, strict=False))
        if self.exponent < 1 and self.v_reg == 0:
            raise ValueError(
                f"PowerLawDamping with exponent {self.exponent} < 1 needs v_reg > 0 "
                "(its slope at rest is infinite)"
            )

    def kernel_parameters(self) -> tuple[float, float, float]:
        return self.coefficient, self.exponent, self.v_reg

    def describing(self, a: ArrayLike, omega: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``c_eq = c (aω)^(α−1) · 2Γ((α+2)/2) / (√π Γ((α+3)/2))`` (v_reg neglected).

        From the energy per cycle ``c (aω)^(α+1) ∫|sin θ|^(α+1) dθ / ω``.
        """
        a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
        alpha = self.exponent
        gain = (
            2.0
            * special.gamma((alpha + 2) / 2)
            / (math.sqrt(math.pi) * special.gamma((alpha + 3) / 2))
        )
        return np.zeros(a.shape), self.coefficient * (a * omega) ** (alpha - 1) * gain

    @property
    def damping_slope_bound(self) -> float:
        # α·c·|v|^(α−1) at 1 m/s above 1 (beyond a test's velocities), c·v_reg^(α−1) below
        if self.exponent >= 1:
            return self.exponent * self.coefficient
        return self.coefficient * self.v_reg ** (self.exponent - 1)


#: The joints by name (as in ``ground_truth.json``).
JOINTS: dict[str, type[Joint]] = {
    cls.name: cls for cls in (IwanJoint, Clearance, PreloadedContact, PowerLawDamping)
}


def joint_from_dict(data: Mapping[str, Any]) -> Joint:
    """A joint from :meth:`Joint.to_dict` output."""
    values = dict(data)
    name = values.pop("joint", None)
    if name not in JOINTS:
        raise ValueError(f"unknown joint {name!r}; the rig knows {', '.join(JOINTS)}")
    return JOINTS[name](**values)


@dataclass(frozen=True)
class SecondMode:
    """A second mode near the first: a modal degree of freedom ``q`` of its own.

    ``q̈ + 2ζ₂ω₂ q̇ + ω₂² q + b·F_joint = −Γ₂ a_base``, with the joint forces acting
    on ``u = x + b q``; panel point ``j`` moves with ``φ₁ⱼ ẋ + φ₂ⱼ q̇``.

    Attributes
    ----------
    frequency_ratio
        ``ω₂/ω₁``, against the first mode's small-amplitude frequency (1).
    damping_ratio
        ``ζ₂`` (1).
    participation
        ``Γ₂``, its base-excitation participation relative to the first mode's (1).
    centre_shape
        Its shape at the centre point, where the first mode's is 1: coupling through
        the measured response (1).
    joint_shape
        ``b``, its share of the joint displacement: coupling through the joint (1).
    """

    frequency_ratio: float
    damping_ratio: float = 0.003
    participation: float = 0.5
    centre_shape: float = 0.3
    joint_shape: float = 0.0

    description: ClassVar[str] = (
        "a second mode nearby, coupled through the measured response and the joint"
    )
    units: ClassVar[Mapping[str, str]] = {
        "frequency_ratio": "1",
        "damping_ratio": "1",
        "participation": "1",
        "centre_shape": "1",
        "joint_shape": "1",
    }

    def __post_init__(self) -> None:
        for f in fields(self):
            value = float(getattr(self, f.name))
            if not math.isfinite(value):
                raise ValueError(f"SecondMode.{f.name} must be finite, got {value}")
            object.__setattr__(self, f.name, value)
        _check("SecondMode.frequency_ratio", self.frequency_ratio)
        _check("SecondMode.damping_ratio", self.damping_ratio)

    @property
    def parameters(self) -> dict[str, float]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def with_parameters(self, values: Mapping[str, float]) -> SecondMode:
        return replace(self, **values)

    def to_dict(self) -> dict[str, float]:
        return self.parameters

    def panel_shape(self, positions: ArrayLike) -> np.ndarray:
        """Its shape at panel points at ``positions`` ξ along the length (0…1).

        A third-bending pattern ``−sin(3πξ)``, uniform across the width, scaled to
        :attr:`centre_shape` at mid-length.
        """
        return -self.centre_shape * np.sin(3 * np.pi * np.asarray(positions, float))


# --------------------------------------------------------------------------
# numba kernels (mass-normalised forces, m/s²).


@numba.njit(cache=True, inline="always")
def _clearance_force(u, gap, stiffness):
    if u > gap:
        return stiffness * (u - gap)
    if u < -gap:
        return stiffness * (u + gap)
    return 0.0


@numba.njit(cache=True, inline="always")
def _contact_force(u, stiffness, preload):
    return max(stiffness * u, -preload)


@numba.njit(cache=True, inline="always")
def _power_law_force(du, coefficient, exponent, v_reg):
    size = du * du + v_reg * v_reg
    if size == 0.0:
        return 0.0
    return coefficient * du * size ** (0.5 * (exponent - 1.0))


@numba.njit(cache=True, inline="always")
def memoryless_joint_force(kind, u, du, p0, p1, p2):
    """Force of a memoryless joint of dispatch code ``kind`` (see ``Joint.kind``)."""
    if kind == _CLEARANCE:
        return _clearance_force(u, p0, p1)
    if kind == _CONTACT:
        return _contact_force(u, p0, p1)
    if kind == _POWER_LAW:
        return _power_law_force(du, p0, p1, p2)
    return 0.0


@numba.njit(cache=True, inline="always")
def iwan_force(u, u_anchor, slider_forces, slider_stiffness, slip_forces):
    """Σ of the Jenkins sliders' forces at ``u``, from their forces at the anchor ``u_anchor``."""
    total = 0.0
    for i in range(slider_forces.size):
        total += jenkins_force(u, u_anchor, slider_forces[i], slider_stiffness[i], slip_forces[i])
    return total


@numba.njit(cache=True, inline="always")
def iwan_update(u, u_anchor, slider_forces, slider_stiffness, slip_forces):
    """Move every slider's anchor to the accepted displacement ``u`` (in place)."""
    for i in range(slider_forces.size):
        slider_forces[i] = jenkins_force(
            u, u_anchor, slider_forces[i], slider_stiffness[i], slip_forces[i]
        )
