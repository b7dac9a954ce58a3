"""The catalogue of joint physics.

Every effect is one term of the mass-normalised restoring force of a 1-DOF
joint model, ``ẍ + Σ c_i φ_i(x, ẋ) = −a_base``. An :class:`Effect` knows

* ``feature(x, v, **shape)``: φ evaluated on arrays (numpy, vectorised), the
  column SINDy regresses on;
* ``force``: the same function as a numba ``njit`` scalar kernel for time
  simulation, called as ``force(x, v, p0, p1)`` with the shape parameters in
  declaration order (unused slots are ignored);
* ``describing(a, omega, **shape)``: its single-harmonic describing function,
  i.e. the equivalent stiffness and viscous damping per unit coefficient such
  that ``φ(a cos θ, −aω sin θ) ≈ k_eq · x + c_eq · ẋ`` over one cycle;
* its units, a physical reading and the term as it reads in an equation.

``microslip`` is the one hysteretic effect: a Jenkins element (spring ``k_t``
in series with a slider of slip force ``F_s``). Its force depends on the
loading history, so its ``feature`` needs the whole time series and its
``force`` kernel takes the element state (see :func:`jenkins_force`).

Effect names are public: reports, JSON files and the CLI use exactly these.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass, field

import numba
import numpy as np
from scipy import interpolate, special

__all__ = [
    "CATALOGUE",
    "Effect",
    "get_effect",
    "jenkins_force",
    "jenkins_path",
]

#: Regularising velocity of the smoothed sign (tanh(v/v_reg)) in ``coulomb_friction`` and
#: ``stribeck_friction`` (m/s). Well below the velocities of a joint test
#: (1e-2 to 1e-1 m/s), so the smoothing only rounds the velocity reversals, and
#: large enough that an explicit 10 kHz integrator stays stable for friction
#: levels up to a few m/s² (the slope F/v_reg acts as a viscous damper).
DEFAULT_SIGN_VELOCITY = 1e-4


@dataclass(frozen=True)
class Effect:
    """One physical effect of the catalogue.

    Attributes
    ----------
    name
        Catalogue name (public interface).
    index
        Position in :data:`CATALOGUE`; the numba kernels dispatch on it.
    term
        The term as it reads in an equation, e.g. ``"x·|x|"``.
    units
        Units of the coefficient of the mass-normalised term (SI).
    reading
        One-line physical reading.
    shape
        Names of shape parameters in the order the force kernel takes them.
    defaults
        Default value of each shape parameter (SI).
    shape_units
        Units of each shape parameter.
    feature
        Vectorised numpy feature ``φ(x, v, **shape)``.
    force
        numba kernel ``force(x, v, p0, p1) -> float``.
    describing
        ``(a, omega, **shape) -> (k_eq, c_eq)`` per unit coefficient.
    hysteretic
        True when the force depends on the loading history (``microslip``).
    parity
        ``"odd"`` for forces with φ(−x, −v) = −φ(x, v) (they act on the
        fundamental harmonic), ``"even"`` for φ(−x, −v) = φ(x, v) (they act
        through the mean and even harmonics, invisible to a single-harmonic
        describing function), ``"mixed"`` for both parts (``exponential``).
    """

    name: str
    index: int
    term: str
    units: str
    reading: str
    feature: Callable[..., np.ndarray] = field(repr=False)
    force: Callable[..., float] = field(repr=False)
    describing: Callable[..., tuple[np.ndarray, np.ndarray]] = field(repr=False)
    shape: tuple[str, ...] = ()
    defaults: dict[str, float] = field(default_factory=dict)
    shape_units: dict[str, str] = field(default_factory=dict)
    hysteretic: bool = False
    parity: str = "odd"

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


# --------------------------------------------------------------------------
# numba force kernels. Signature (x, v, p0, p1) for all, so a single
# dispatcher can call any of them.


@numba.njit(cache=True, inline="always")
def _smooth_sign(v, v_reg):
    return np.tanh(v / v_reg)


@numba.njit(cache=True)
def _f_linear_stiffness(x, v, p0, p1):
    return x


@numba.njit(cache=True)
def _f_viscous_damping(x, v, p0, p1):
    return v


@numba.njit(cache=True)
def _f_quadratic_stiffness(x, v, p0, p1):
    return x * x


@numba.njit(cache=True)
def _f_cubic_stiffness(x, v, p0, p1):
    return x * x * x


@numba.njit(cache=True)
def _f_abs_stiffness(x, v, p0, p1):
    return x * abs(x)


@numba.njit(cache=True)
def _f_quadratic_damping(x, v, p0, p1):
    return v * abs(v)


@numba.njit(cache=True)
def _f_cubic_damping(x, v, p0, p1):
    return v * v * v


@numba.njit(cache=True)
def _f_velocity_squared(x, v, p0, p1):
    return v * v


@numba.njit(cache=True)
def _f_stiffness_damping_coupling(x, v, p0, p1):
    return x * v


@numba.njit(cache=True)
def _f_displacement_velocity_squared(x, v, p0, p1):
    return x * v * v


@numba.njit(cache=True)
def _f_van_der_pol(x, v, p0, p1):
    return x * x * v


@numba.njit(cache=True)
def _f_coulomb_friction(x, v, p0, p1):
    return _smooth_sign(v, p0)


@numba.njit(cache=True)
def _f_stribeck_friction(x, v, p0, p1):
    r = v / p0
    return _smooth_sign(v, p1) * np.exp(-r * r)


@numba.njit(cache=True)
def _f_tanh_saturation(x, v, p0, p1):
    return np.tanh(x / p0)


@numba.njit(cache=True)
def _f_exponential(x, v, p0, p1):
    return np.expm1(x / p0)


@numba.njit(cache=True)
def jenkins_force(x, x_anchor, f_anchor, k_t, f_s):
    """Force of a Jenkins element at displacement ``x``.

    The element last had force ``f_anchor`` at displacement ``x_anchor``; from
    there it loads elastically with stiffness ``k_t`` until the slider carries
    ``±f_s``. Exact for a monotonic path between anchor and ``x`` (the return
    mapping of rate-independent plasticity), so a time integrator moves the
    anchor to the accepted state after each step.
    """
    f = f_anchor + k_t * (x - x_anchor)
    if f > f_s:
        return f_s
    if f < -f_s:
        return -f_s
    return f


@numba.njit(cache=True)
def _f_microslip(x, v, p0, p1):
    # Virgin loading curve from the unstressed state; history-dependent use goes
    # through `jenkins_force` with the integrator's anchor state.
    return jenkins_force(x, 0.0, 0.0, p0, p1)


@numba.njit(cache=True)
def jenkins_path(x, k_t, f_s):
    """Jenkins force along a displacement history ``x`` (starting unstressed)."""
    out = np.empty_like(x)
    x_anchor = 0.0
    f_anchor = 0.0
    for i in range(x.size):
        f_anchor = jenkins_force(x[i], x_anchor, f_anchor, k_t, f_s)
        x_anchor = x[i]
        out[i] = f_anchor
    return out


# --------------------------------------------------------------------------
# Describing functions: (a, omega, **shape) -> (k_eq, c_eq) per unit coefficient,
# closed forms from single-harmonic balance with x = a cos θ, ẋ = −aω sin θ.


def _zeros(a, omega):
    a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
    return np.zeros(a.shape), np.zeros(a.shape)


def _df_stiffness(gain: Callable[[np.ndarray, np.ndarray], np.ndarray]):
    def describing(a, omega, **_):
        a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
        return gain(a, omega), np.zeros(a.shape)

    return describing


def _df_damping(gain: Callable[[np.ndarray, np.ndarray], np.ndarray]):
    def describing(a, omega, **_):
        a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
        return np.zeros(a.shape), gain(a, omega)

    return describing


def _df_coulomb(a, omega, v_reg=DEFAULT_SIGN_VELOCITY):
    # Ideal dry friction: dissipates 4|a| per cycle per unit force, c_eq = 4/(π a ω).
    # The regularisation only rounds the reversal and is left out on purpose.
    a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
    return np.zeros(a.shape), 4.0 / (np.pi * a * omega)


def _df_stribeck(a, omega, v_s=1e-2, v_reg=DEFAULT_SIGN_VELOCITY):
    # ∫₀^π sin θ exp(−b² sin²θ) dθ = 2 D(b)/b with D Dawson's integral, b = aω/v_s.
    a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
    b = a * omega / v_s
    return np.zeros(a.shape), 4.0 * special.dawsn(b) / (np.pi * a * omega * b)


def _df_exponential(a, omega, x_s=1e-3):
    # (1/πa)∫ e^{z cos θ} cos θ dθ = 2 I₁(z)/a with z = a/x_s.
    a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
    return 2.0 * special.i1(a / x_s) / a, np.zeros(a.shape)


def _df_tanh(a, omega, x_s=1e-3):
    # k_eq = g(a/x_s)/x_s with one dimensionless curve g (see _tanh_gain).
    a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
    x_s = np.asarray(x_s, float)
    return _tanh_gain(a / x_s) / x_s, np.zeros(a.shape)


#: Where the tabulated tanh gain hands over to its series (below) and asymptote (above).
_TANH_SMALL, _TANH_LARGE = 1e-3, 1e3


@functools.cache
def _tanh_gain_spline() -> interpolate.BSpline:
    """Quintic spline of ln g over ln u on [_TANH_SMALL, _TANH_LARGE], built once.

    Each node is an exact periodic trapezoid sum: tanh(u cos θ) has its nearest
    complex singularity at distance ≈ π/(2u) from the real θ axis, so 40u + 256
    points put the quadrature error below 1e-16. The spline's own error is
    below 1e-12 (node spacing 0.013 in ln u).
    """
    log_u = np.linspace(np.log(_TANH_SMALL), np.log(_TANH_LARGE), 1200)
    gain = np.empty_like(log_u)
    for i, u in enumerate(np.exp(log_u)):
        n = 256 + int(40 * u)
        theta = 2.0 * np.pi * (np.arange(n) + 0.5) / n
        gain[i] = 2.0 * np.mean(np.tanh(u * np.cos(theta)) * np.cos(theta)) / u
    return interpolate.make_interp_spline(log_u, np.log(gain), k=5)


def _tanh_gain(u: np.ndarray) -> np.ndarray:
    """Describing gain g(u) = (2/u)⟨tanh(u cos θ) cos θ⟩ of tanh, u = a/x_s > 0.

    There is no elementary closed form, and a quadrature per call made tanh the
    slowest term of every harmonic-balance fit; g is one smooth curve of u, so
    it is tabulated once. Outside the table: the Taylor series 1 − u²/4 + u⁴/12
    (small u) and the asymptote 4/(πu) − π/(6u³) (large u; the tanh − sign
    correction near the zero crossings), both exact to rounding there.
    """
    u = np.asarray(u, float)
    gain = np.exp(_tanh_gain_spline()(np.log(np.clip(u, _TANH_SMALL, _TANH_LARGE))))
    gain = np.where(u < _TANH_SMALL, 1.0 - u**2 / 4.0 + u**4 / 12.0, gain)
    with np.errstate(divide="ignore", over="ignore"):
        return np.where(u > _TANH_LARGE, 4.0 / (np.pi * u) - np.pi / (6.0 * u**3), gain)


def _df_microslip(a, omega, k_t=1e5, F_s=1.0):
    """Masing / elastic-perfectly-plastic loop of the Jenkins element.

    Below the slip amplitude a_s = F_s/k_t the element sticks (k_eq = k_t). Above
    it, with cos φ* = 1 − 2 a_s / a (Caughey's bilinear hysteresis):
    k_eq = k_t (φ* − ½ sin 2φ*)/π and the dissipated energy per cycle
    4 F_s (a − a_s) gives c_eq = 4 F_s (a − a_s)/(π a² ω).
    """
    a, omega = np.broadcast_arrays(np.asarray(a, float), np.asarray(omega, float))
    a_s = F_s / k_t
    slipping = a > a_s
    cos_phi = np.clip(1.0 - 2.0 * a_s / np.where(slipping, a, 1.0), -1.0, 1.0)
    phi = np.arccos(cos_phi)
    k_eq = np.where(slipping, k_t * (phi - 0.5 * np.sin(2.0 * phi)) / np.pi, k_t)
    c_eq = np.where(slipping, 4.0 * F_s * (a - a_s) / (np.pi * a * a * omega), 0.0)
    return k_eq, c_eq


_VECTORISED: dict[Callable, Callable] = {}


def _vectorised_kernel(force: Callable[..., float]) -> Callable[..., np.ndarray]:
    """numpy-broadcasting version of a scalar numba force kernel (cached)."""
    if force not in _VECTORISED:
        _VECTORISED[force] = numba.vectorize(["float64(float64, float64, float64, float64)"])(
            force.py_func
        )
    return _VECTORISED[force]


# --------------------------------------------------------------------------
# Vectorised features for SINDy.


def _feature_from_kernel(kernel: Callable, shape: tuple[str, ...]):
    def feature(x, v, **params):
        p = [params[n] for n in shape] + [0.0] * (2 - len(shape))
        return _vectorised_kernel(kernel)(np.asarray(x, float), np.asarray(v, float), p[0], p[1])

    return feature


def _feature_microslip(x, v, k_t=1e5, F_s=1.0):
    # Hysteretic: the feature is the element force along the measured path.
    return jenkins_path(np.ascontiguousarray(x, dtype=float), float(k_t), float(F_s))


_SPECS = [
    # name, term, units of coefficient, reading, kernel, describing, shape, defaults,
    # shape units, parity
    ("linear_stiffness", "x", "1/s²", "modal stiffness", _f_linear_stiffness,
     _df_stiffness(lambda a, w: np.ones_like(a)), (), {}, {}, "odd"),
    ("viscous_damping", "ẋ", "1/s", "linear modal damping", _f_viscous_damping,
     _df_damping(lambda a, w: np.ones_like(a)), (), {}, {}, "odd"),
    ("quadratic_stiffness", "x²", "1/(m·s²)", "asymmetric stiffness of the arched panel",
     _f_quadratic_stiffness, _zeros, (), {}, {}, "even"),
    ("cubic_stiffness", "x³", "1/(m²·s²)", "membrane stretching (hardening if positive)",
     _f_cubic_stiffness, _df_stiffness(lambda a, w: 0.75 * a**2), (), {}, {}, "odd"),
    ("abs_stiffness", "x·|x|", "1/(m·s²)", "one-sided contact / clearance",
     _f_abs_stiffness, _df_stiffness(lambda a, w: 8.0 * a / (3.0 * np.pi)), (), {}, {}, "odd"),
    ("quadratic_damping", "ẋ·|ẋ|", "1/m", "fluid / aerodynamic damping", _f_quadratic_damping,
     _df_damping(lambda a, w: 8.0 * a * w / (3.0 * np.pi)), (), {}, {}, "odd"),
    ("cubic_damping", "ẋ³", "s/m²", "nonlinear viscous damping", _f_cubic_damping,
     _df_damping(lambda a, w: 0.75 * (a * w) ** 2), (), {}, {}, "odd"),
    ("velocity_squared", "ẋ²", "1/m", "asymmetric damping", _f_velocity_squared, _zeros,
     (), {}, {}, "even"),
    ("stiffness_damping_coupling", "x·ẋ", "1/(m·s)",
     "displacement-dependent damping, asymmetric in x", _f_stiffness_damping_coupling, _zeros,
     (), {}, {}, "even"),
    ("displacement_velocity_squared", "x·ẋ²", "1/m²",
     "velocity-dependent stiffness (inertial nonlinearity)", _f_displacement_velocity_squared,
     _df_stiffness(lambda a, w: 0.25 * (a * w) ** 2), (), {}, {}, "odd"),
    ("van_der_pol", "x²·ẋ", "1/(m²·s)", "amplitude-dependent (self-excited) damping",
     _f_van_der_pol, _df_damping(lambda a, w: 0.25 * a**2), (), {}, {}, "odd"),
    ("coulomb_friction", "sign(ẋ)", "m/s²", "macroslip dry friction in the bolted joint",
     _f_coulomb_friction, _df_coulomb, ("v_reg",), {"v_reg": DEFAULT_SIGN_VELOCITY},
     {"v_reg": "m/s"}, "odd"),
    ("stribeck_friction", "sign(ẋ)·exp(−(ẋ/v_s)²)", "m/s²",
     "static-to-kinetic friction drop", _f_stribeck_friction, _df_stribeck,
     ("v_s", "v_reg"), {"v_s": 1e-2, "v_reg": DEFAULT_SIGN_VELOCITY},
     {"v_s": "m/s", "v_reg": "m/s"}, "odd"),
    ("tanh_saturation", "tanh(x/x_s)", "m/s²", "saturating stiffness", _f_tanh_saturation,
     _df_tanh, ("x_s",), {"x_s": 1e-3}, {"x_s": "m"}, "odd"),
    ("exponential", "exp(x/x_s) − 1", "m/s²", "growth/decay term from the paper's library",
     _f_exponential, _df_exponential, ("x_s",), {"x_s": 1e-3}, {"x_s": "m"}, "mixed"),
    ("microslip", "Jenkins(x; k_t, F_s)", "1",
     "partial slip in the joint: softening and damping that rises with amplitude",
     _f_microslip, _df_microslip, ("k_t", "F_s"), {"k_t": 1e5, "F_s": 1.0},
     {"k_t": "1/s²", "F_s": "m/s²"}, "odd"),
]  # fmt: skip


def _build_catalogue() -> dict[str, Effect]:
    catalogue = {}
    for index, spec in enumerate(_SPECS):
        name, term, units, reading, kernel, describing, shape, defaults, shape_units, parity = spec
        feature = _feature_microslip if name == "microslip" else _feature_from_kernel(kernel, shape)
        catalogue[name] = Effect(
            name=name,
            index=index,
            term=term,
            units=units,
            reading=reading,
            feature=feature,
            force=kernel,
            describing=describing,
            shape=shape,
            defaults=defaults,
            shape_units=shape_units,
            hysteretic=name == "microslip",
            parity=parity,
        )
    return catalogue


#: Every effect, by catalogue name, in a fixed order (``Effect.index``).
CATALOGUE: dict[str, Effect] = _build_catalogue()

#: Index of the hysteretic Jenkins element, for the numba kernels.
MICROSLIP_INDEX = CATALOGUE["microslip"].index


def get_effect(name: str) -> Effect:
    """The catalogue effect called ``name``; ValueError naming it if unknown."""
    try:
        return CATALOGUE[name]
    except KeyError:
        raise ValueError(
            f"unknown effect {name!r}; the catalogue has: {', '.join(CATALOGUE)}"
        ) from None


# Inlined at numba-IR level so that callers looping over samples with a fixed
# ``index`` get the dispatch hoisted out of the loop (≈4× faster AFT force sums).
@numba.njit(cache=True, inline="always")
def memoryless_force(index, x, v, p0, p1):
    """Dispatch to the force kernel of the effect with catalogue ``index``.

    The hysteretic ``microslip`` is not memoryless and returns 0 here; the
    integrators evaluate it through :func:`jenkins_force`.
    """
    if index == 0:
        return _f_linear_stiffness(x, v, p0, p1)
    if index == 1:
        return _f_viscous_damping(x, v, p0, p1)
    if index == 2:
        return _f_quadratic_stiffness(x, v, p0, p1)
    if index == 3:
        return _f_cubic_stiffness(x, v, p0, p1)
    if index == 4:
        return _f_abs_stiffness(x, v, p0, p1)
    if index == 5:
        return _f_quadratic_damping(x, v, p0, p1)
    if index == 6:
        return _f_cubic_damping(x, v, p0, p1)
    if index == 7:
        return _f_velocity_squared(x, v, p0, p1)
    if index == 8:
        return _f_stiffness_damping_coupling(x, v, p0, p1)
    if index == 9:
        return _f_displacement_velocity_squared(x, v, p0, p1)
    if index == 10:
        return _f_van_der_pol(x, v, p0, p1)
    if index == 11:
        return _f_coulomb_friction(x, v, p0, p1)
    if index == 12:
        return _f_stribeck_friction(x, v, p0, p1)
    if index == 13:
        return _f_tanh_saturation(x, v, p0, p1)
    if index == 14:
        return _f_exponential(x, v, p0, p1)
    return 0.0


@numba.njit(cache=True)
def restoring_force(indices, coefficients, shapes, x, v):
    """Σ c_i φ_i(x, v) over the memoryless terms of a model (numba scalar kernel).

    ``indices``, ``coefficients`` and ``shapes`` are the arrays of
    :meth:`identification.model.JointModel.kernel_arrays`.
    """
    total = 0.0
    for i in range(indices.size):
        total += coefficients[i] * memoryless_force(indices[i], x, v, shapes[i, 0], shapes[i, 1])
    return total
