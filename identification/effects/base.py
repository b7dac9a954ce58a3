"""What an effect is: the :class:`Effect` record, array namespaces, the numba dispatch.

An effect module (one per catalogue entry, see :mod:`identification.effects`)
holds every fact of its effect and ends with ``EFFECT = Effect(...)``. Its
describing function is written once, as up to three parts, against an array
namespace ``xp`` (:class:`ArrayNamespace`) so that the same source gives the
numpy describing function of the fits and the pytensor graph of the PyMC
forward model::

    k_eq(a, ω) = stiffness(xp, a, **shape) + stiffness_per_omega_squared(xp, a, **shape) · ω²
    c_eq(a, ω) = damping(xp, a, omega, **shape)

(a missing part is zero). Every catalogue ``k_eq`` is affine in ω², which the
closed-form backbone graph relies on.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple

import numba
import numpy as np
from numpy.typing import ArrayLike
from scipy import special as scipy_special

from identification.effects import special

__all__ = [
    "NUMPY",
    "ArrayNamespace",
    "Effect",
    "FitScale",
    "HiddenScenario",
    "ShapeParameter",
    "catalogue_of",
    "force_dispatcher",
    "pytensor_namespace",
]

PARITIES = ("odd", "even", "mixed")
#: Shape parameters that are numerical devices, not physics (the friction terms'
#: regularising velocity): equations do not write their values in.
NUMERICAL_SHAPES = ("v_reg",)


# --------------------------------------------------------------------------
# Array namespaces of the describing functions.


@dataclass(frozen=True)
class ArrayNamespace:
    """The functions a describing function may call, for one array backend.

    Arithmetic (``+ − * / **``) and float constants work on both backends as
    they are; everything else goes through these attributes. ``where`` is
    ``numpy.where`` / ``pytensor.tensor.switch``.
    """

    name: str
    where: Callable
    sqrt: Callable
    exp: Callable
    sin: Callable
    cos: Callable
    arccos: Callable
    tanh: Callable
    abs: Callable
    i1: Callable
    ones_like: Callable
    zeros_like: Callable
    #: Dawson's integral D(x).
    dawsn: Callable
    #: Describing gain of tanh, g(u) = (2/u)⟨tanh(u cos θ) cos θ⟩ (see :mod:`.special`).
    tanh_gain: Callable


#: numpy backend (scipy for the special functions).
NUMPY = ArrayNamespace(
    name="numpy",
    where=np.where,
    sqrt=np.sqrt,
    exp=np.exp,
    sin=np.sin,
    cos=np.cos,
    arccos=np.arccos,
    tanh=np.tanh,
    abs=np.abs,
    i1=scipy_special.i1,
    ones_like=np.ones_like,
    zeros_like=np.zeros_like,
    dawsn=special.dawsn,
    tanh_gain=special.tanh_gain,
)


@functools.cache
def pytensor_namespace() -> ArrayNamespace:
    """pytensor backend (imports pytensor on first use; differentiable throughout)."""
    import pytensor.tensor as pt

    return ArrayNamespace(
        name="pytensor",
        where=pt.switch,
        sqrt=pt.sqrt,
        exp=pt.exp,
        sin=pt.sin,
        cos=pt.cos,
        arccos=pt.arccos,
        tanh=pt.tanh,
        abs=pt.abs,
        i1=pt.i1,
        ones_like=pt.ones_like,
        zeros_like=pt.zeros_like,
        dawsn=special.dawsn_graph,
        tanh_gain=special.tanh_gain_graph,
    )


# --------------------------------------------------------------------------
# What a fit knows of the test's scale.


@dataclass(frozen=True)
class FitScale:
    """Scale of a test, from which an effect sets its shape-parameter grids and bounds.

    Attributes
    ----------
    amplitude_m
        Smallest and largest measured fundamental amplitude (m).
    velocity_m_s
        Smallest and largest velocity amplitude, ``a_min·2π f_min`` and
        ``a_max·2π f_max`` (m/s).
    stiffness
        Small-amplitude stiffness of the model being fitted (1/s², mass-normalised);
        ``(2π f_median)²`` of the data where the model has none.
    """

    amplitude_m: tuple[float, float]
    velocity_m_s: tuple[float, float]
    stiffness: float

    @classmethod
    def from_measurements(
        cls, amplitude_m: ArrayLike, frequency_hz: ArrayLike, stiffness: float
    ) -> FitScale:
        """Scale of measured backbone points (amplitudes in m, frequencies in Hz)."""
        a = np.asarray(amplitude_m, dtype=float)
        f = np.asarray(frequency_hz, dtype=float)
        a_lo, a_hi = a.min(), a.max()
        return cls(
            amplitude_m=(a_lo, a_hi),
            velocity_m_s=(a_lo * 2 * np.pi * f.min(), a_hi * 2 * np.pi * f.max()),
            stiffness=stiffness,
        )


def _no_shape_grid(scale: FitScale) -> dict[str, np.ndarray]:
    return {}


def _no_shape_bounds(scale: FitScale) -> dict[str, tuple[float, float]]:
    return {}


def _no_fitted_reading(coefficient: float, shape: Mapping[str, float], scale: FitScale) -> str:
    return ""


# --------------------------------------------------------------------------
# What validating an effect needs.

#: Channels whose error a hidden effect must take down in the hidden-effect studies.
KEY_CHANNELS = ("frequency_hz", "damping_ratio", "harmonics")


@dataclass(frozen=True)
class HiddenScenario:
    """The lab scenario that hides an effect, and the channel it shows in.

    The rig builds the preset ``lab-hidden-<name with dashes>`` from it and the
    hidden-effect studies read :attr:`key_channel`, so a new effect module that
    carries one joins the studies without edits elsewhere.

    Attributes
    ----------
    truth
        ``(k0) -> coefficient`` or ``{"coefficient": c, **shape}`` of the hidden term,
        given the rig's small-amplitude stiffness ``k0`` (1/s², mass-normalised).
    description
        What the term does over the rig's 0.05–2 mm range, in words.
    key_channel
        The channel (:data:`KEY_CHANNELS`) whose error the found effect must take down.
    on_hardening_base
        The base model the effect hides from carries the rig's cubic hardening too.
    """

    truth: Callable[[float], float | Mapping[str, float]] = field(repr=False)
    description: str
    key_channel: str
    on_hardening_base: bool = False

    def __post_init__(self) -> None:
        if self.key_channel not in KEY_CHANNELS:
            raise ValueError(f"key_channel must be one of {KEY_CHANNELS}, got {self.key_channel!r}")


# --------------------------------------------------------------------------
# The effect record.


class ShapeParameter(NamedTuple):
    """A shape parameter of an effect: name, default value and unit (SI)."""

    name: str
    default: float
    unit: str


@dataclass(frozen=True)
class Effect:
    """One physical effect of the catalogue: every fact of it, from one module.

    Attributes
    ----------
    name
        Catalogue name (public interface: reports, JSON files and the CLI use it).
    term
        The term as it reads in an equation, e.g. ``"x·|x|"``.
    units
        Units of the coefficient of the mass-normalised term (SI).
    reading
        One-line physical reading.
    force
        numba kernel ``force(x, v, p0, p1) -> float`` with the shape parameters in
        declaration order (unused slots ignored).
    parity
        ``"odd"`` for forces with φ(−x, −v) = −φ(x, v) (they act on the
        fundamental harmonic), ``"even"`` for φ(−x, −v) = φ(x, v) (they act
        through the mean and even harmonics, invisible to a single-harmonic
        describing function), ``"mixed"`` for both parts (``exponential``).
    polynomial
        The force is a polynomial of degree ≤ 3 in (x, ẋ): the AFT sum of the
        multi-harmonic balance is exact for it with few samples.
    shape_parameters
        Shape parameters in the order the force kernel takes them (at most two).
    stiffness, stiffness_per_omega_squared, damping
        Parts of the single-harmonic describing function per unit coefficient,
        ``(xp, a, **shape)``, ``(xp, a, **shape)`` and ``(xp, a, omega, **shape)``
        (see the module notes); None is zero. They receive every shape parameter
        as a keyword.
    hysteretic
        The force depends on the loading history (``microslip``): its feature
        needs the whole path (:attr:`path_feature`), and the dispatcher
        :func:`force_dispatcher` gives 0 for it (the integrators carry its state,
        and a model's kernel arrays leave it out).
    coefficient_sign
        +1 where only a positive coefficient is physical (a friction or slip force
        opposes the motion), 0 where either sign is.
    path_feature
        Hysteretic effects only: ``(x, v, **shape) -> φ`` along a whole path
        starting unstressed (see :meth:`feature`).
    stuck_stiffness
        Hysteretic effects only: ``(coefficient, shape) -> k`` (1/s²), the stiffness
        the element adds while it sticks, which a model's small-amplitude stiffness
        includes. Takes and gives arrays alike (shape values by name).
    written_term
        ``(shape, precision) -> str``: the term as an equation writes it with these
        shape values; None writes each shape value in place of its name in
        :attr:`term` (see :meth:`term_text`).
    shape_grid
        ``(FitScale) -> {shape name: values}``: the values a fit scans for the
        start of a newly added effect ({} when the defaults do).
    shape_bounds
        ``(FitScale) -> {shape name: (low, high)}``: the range a fitted shape
        parameter may take ({} for no physical range).
    fitted_reading
        ``(coefficient, shape, FitScale) -> str``: what the fitted numbers say,
        appended to :attr:`reading` (e.g. ``" (hardening)"``; "" for nothing).
    hidden_scenario
        The lab scenario that hides the effect and its key channel
        (:class:`HiddenScenario`); None for the linear pair, which every model has.
    index
        Position in :data:`~identification.effects.CATALOGUE` (-1 until
        :func:`catalogue_of` registers the effect); the numba kernels dispatch on it.
    shape, defaults, shape_units
        Names, default values and units of :attr:`shape_parameters`.
    """

    name: str
    term: str
    units: str
    reading: str
    force: Callable[..., float] = field(repr=False)
    parity: str = "odd"
    polynomial: bool = False
    shape_parameters: tuple[ShapeParameter, ...] = ()
    stiffness: Callable[..., Any] | None = field(default=None, repr=False)
    stiffness_per_omega_squared: Callable[..., Any] | None = field(default=None, repr=False)
    damping: Callable[..., Any] | None = field(default=None, repr=False)
    hysteretic: bool = False
    coefficient_sign: int = 0
    path_feature: Callable[..., np.ndarray] | None = field(default=None, repr=False)
    stuck_stiffness: Callable[[Any, Mapping[str, Any]], Any] | None = field(
        default=None, repr=False
    )
    written_term: Callable[[Mapping[str, float], int], str] | None = field(default=None, repr=False)
    shape_grid: Callable[[FitScale], dict[str, np.ndarray]] = field(
        default=_no_shape_grid, repr=False
    )
    shape_bounds: Callable[[FitScale], dict[str, tuple[float, float]]] = field(
        default=_no_shape_bounds, repr=False
    )
    fitted_reading: Callable[[float, Mapping[str, float], FitScale], str] = field(
        default=_no_fitted_reading, repr=False
    )
    hidden_scenario: HiddenScenario | None = field(default=None, repr=False)
    index: int = -1
    shape: tuple[str, ...] = field(init=False)
    defaults: dict[str, float] = field(init=False)
    shape_units: dict[str, str] = field(init=False)

    def __post_init__(self) -> None:
        if not self.name.isidentifier():
            raise ValueError(f"effect name {self.name!r} must be a Python identifier")
        if self.parity not in PARITIES:
            raise ValueError(f"effect {self.name!r}: parity must be one of {PARITIES}")
        parameters = tuple(ShapeParameter(*p) for p in self.shape_parameters)
        if len(parameters) > 2:
            raise ValueError(f"effect {self.name!r}: force kernels take at most 2 shape parameters")
        if self.hysteretic != (self.path_feature is not None):
            raise ValueError(f"effect {self.name!r}: a path feature if and only if hysteretic")
        if self.hysteretic != (self.stuck_stiffness is not None):
            raise ValueError(f"effect {self.name!r}: a stuck stiffness if and only if hysteretic")
        object.__setattr__(self, "shape_parameters", parameters)
        object.__setattr__(self, "shape", tuple(p.name for p in parameters))
        object.__setattr__(self, "defaults", {p.name: float(p.default) for p in parameters})
        object.__setattr__(self, "shape_units", {p.name: p.unit for p in parameters})

    def shape_values(self, **shape: float) -> tuple[float, float]:
        """Shape parameters as the ``(p0, p1)`` pair the force kernel takes."""
        unknown = set(shape) - set(self.shape)
        if unknown:
            raise ValueError(
                f"effect {self.name!r} has no shape parameter(s) {sorted(unknown)}; "
                f"it takes {list(self.shape) or 'none'}"
            )
        values = [float(shape.get(n, self.defaults[n])) for n in self.shape]
        for n, v in zip(self.shape, values, strict=True):
            if not np.isfinite(v) or v <= 0:
                raise ValueError(f"shape parameter {self.name}.{n} must be finite and > 0, got {v}")
        values += [0.0] * (2 - len(values))
        return values[0], values[1]

    def term_text(self, shape: Mapping[str, float], precision: int = 4) -> str:
        """The term as it reads in an equation, with the shape values ``shape`` written in.

        Numerical devices among the shape parameters (:data:`NUMERICAL_SHAPES`)
        keep their names: they are not part of the physics.
        """
        if self.written_term is not None:
            return self.written_term(shape, precision)
        term = self.term
        for name, value in shape.items():
            if name not in NUMERICAL_SHAPES:
                term = term.replace(name, f"{value:.{precision}g}")
        return term

    def feature(self, x: ArrayLike, v: ArrayLike, **shape: float) -> np.ndarray:
        """φ(x, v) on arrays (numpy, broadcasting): the column SINDy regresses on.

        The force kernel, vectorised; a hysteretic effect's force along the
        path ``x`` (starting unstressed).
        """
        p0, p1 = self.shape_values(**shape)
        if self.path_feature is not None:
            return self.path_feature(x, v, **dict(zip(self.shape, (p0, p1), strict=False)))
        return _vectorised(self.force)(np.asarray(x, float), np.asarray(v, float), p0, p1)

    def describing(
        self, a: ArrayLike, omega: ArrayLike, **shape: ArrayLike
    ) -> tuple[np.ndarray, np.ndarray]:
        """Single-harmonic describing function ``(k_eq, c_eq)`` per unit coefficient (numpy).

        The equivalent stiffness and viscous damping such that
        ``φ(a cos θ, −aω sin θ) ≈ k_eq · x + c_eq · ẋ`` over one cycle.
        ``a`` (m) and ``omega`` (rad/s) broadcast, and so do shape values given
        as arrays (defaults for those not given).
        """
        unknown = set(shape) - set(self.shape)
        if unknown:
            raise ValueError(f"effect {self.name!r} has no shape parameter(s) {sorted(unknown)}")
        a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
        shape = {n: shape.get(n, default) for n, default in self.defaults.items()}
        k_eq, c_eq = self.describing_parts(NUMPY, a, omega, **shape)
        return (
            np.zeros(a.shape) if k_eq is None else k_eq,
            np.zeros(a.shape) if c_eq is None else c_eq,
        )

    def describing_parts(
        self, xp: ArrayNamespace, a: Any, omega: Any, **shape: Any
    ) -> tuple[Any | None, Any | None]:
        """``(k_eq, c_eq)`` in the namespace ``xp``, None for a part that is zero.

        ``shape`` must hold every shape parameter (the graph builders pass
        pytensor variables, :meth:`describing` fills in the defaults).
        """
        k_eq = None if self.stiffness is None else self.stiffness(xp, a, **shape)
        if self.stiffness_per_omega_squared is not None:
            k2 = self.stiffness_per_omega_squared(xp, a, **shape) * omega**2
            k_eq = k2 if k_eq is None else k_eq + k2
        c_eq = None if self.damping is None else self.damping(xp, a, omega, **shape)
        return k_eq, c_eq


@functools.cache
def _vectorised(force: Callable[..., float]) -> Callable[..., np.ndarray]:
    """numpy-broadcasting version of a scalar numba force kernel (built once per kernel)."""
    return numba.vectorize(["float64(float64, float64, float64, float64)"])(force.py_func)


# --------------------------------------------------------------------------
# The catalogue and its numba dispatcher.


def catalogue_of(effects: Iterable[Effect]) -> dict[str, Effect]:
    """The effects by name, each with its ``index`` (its position here) set."""
    catalogue: dict[str, Effect] = {}
    for effect in effects:
        if effect.name in catalogue:
            raise ValueError(f"two effects are called {effect.name!r}")
        catalogue[effect.name] = replace(effect, index=len(catalogue))
    return catalogue


def force_dispatcher(effects: Sequence[Effect]) -> Callable[..., float]:
    """``memoryless_force(index, x, v, p0, p1)``: the force kernel of effect ``index``.

    An if-chain over the effects, generated from the catalogue and inlined into
    its callers at numba-IR level (``inline="always"``): a caller that loops over
    samples with a fixed ``index`` gets the dispatch hoisted out of its loop, and
    a cached caller keeps its cache. (``numba.literal_unroll`` over a tuple of
    kernels does not type; a chain of one inlined closure per effect does, but
    about doubles the cold compile time of the harmonic-balance and PLL kernels.)
    Hysteretic effects give 0 (the
    integrators carry their state); an index beyond the catalogue gives NaN, so
    that a kernel compiled before an effect was added (a stale numba cache:
    ``make clean-cache``) fails loudly instead of dropping the term.
    """
    lines = ["def memoryless_force(index, x, v, p0, p1):"]
    kernels = {}
    for effect in effects:
        lines.append(f"    if index == {effect.index}:  # {effect.name}")
        if effect.hysteretic:
            lines.append("        return 0.0")
        else:
            kernels[f"force_{effect.name}"] = effect.force
            lines.append(f"        return force_{effect.name}(x, v, p0, p1)")
    lines.append("    return np.nan")
    namespace = {"np": np, **kernels}
    exec(compile("\n".join(lines), "<catalogue force dispatch>", "exec"), namespace)
    return numba.njit(inline="always")(namespace["memoryless_force"])
