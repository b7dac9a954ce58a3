"""The catalogue of joint physics.

Every effect is one term of the mass-normalised restoring force of a 1-DOF
joint model, ``ẍ + Σ c_i φ_i(x, ẋ) = −a_base``. Each effect is one module of
this package holding every fact of it (see :class:`~identification.effects.base.Effect`):

* its name, the term as it reads in an equation, units, physical reading, parity;
* the force as a numba kernel ``force(x, v, p0, p1)`` for time simulation, and
  as a vectorised ``feature(x, v, **shape)``, the column SINDy regresses on;
* its single-harmonic describing function, written once against an array
  namespace: :meth:`Effect.describing` (numpy) and the pytensor graph of
  :mod:`pm_joint.forward` come from the same source;
* its shape parameters (names, defaults, units), their start grids and bounds
  in a fit, and what a fitted coefficient says in words.

``microslip`` is the one hysteretic effect (:data:`HYSTERETIC`): a Jenkins
element (spring ``k_t`` in series with a slider of slip force ``F_s``). Its
force depends on the loading history, so its ``feature`` needs the whole time
series and the integrators carry the element state (see :func:`jenkins_force`);
code outside this package reaches it through :data:`HYSTERETIC` and the
:class:`Effect` facts (``hysteretic``, ``stuck_stiffness``, ``term_text``),
never by its name.

Adding an effect is adding one module here that ends with ``EFFECT = Effect(...)``
(``docs/adding-an-effect.md``); this package finds it. Effect names are public:
reports, JSON files and the CLI use exactly these.
"""

from __future__ import annotations

import importlib
import pkgutil

import numba

from identification.effects.base import (
    ArrayNamespace,
    Effect,
    FitScale,
    HiddenScenario,
    ShapeParameter,
    catalogue_of,
    force_dispatcher,
)
from identification.effects.linear_stiffness import EFFECT as _LINEAR_STIFFNESS
from identification.effects.microslip import jenkins_force, jenkins_path
from identification.effects.special import DEFAULT_SIGN_VELOCITY
from identification.effects.viscous_damping import EFFECT as _VISCOUS_DAMPING

__all__ = [
    "CATALOGUE",
    "DEFAULT_SIGN_VELOCITY",
    "HYSTERETIC",
    "LINEAR_STIFFNESS",
    "MICROSLIP_INDEX",
    "VISCOUS_DAMPING",
    "ArrayNamespace",
    "Effect",
    "FitScale",
    "HiddenScenario",
    "ShapeParameter",
    "get_effect",
    "jenkins_force",
    "jenkins_path",
    "memoryless_force",
    "restoring_force",
]

#: Modules of this package that are not effects.
_INFRASTRUCTURE = ("base", "eq3", "special")
#: Catalogue order of docs/science.md §3 (reports, the CLI and the SINDy library list
#: effects in it); effect modules not named here follow in name order.
_ORDER = (
    "linear_stiffness",
    "viscous_damping",
    "quadratic_stiffness",
    "cubic_stiffness",
    "abs_stiffness",
    "quadratic_damping",
    "cubic_damping",
    "velocity_squared",
    "stiffness_damping_coupling",
    "displacement_velocity_squared",
    "van_der_pol",
    "coulomb_friction",
    "stribeck_friction",
    "tanh_saturation",
    "exponential",
    "microslip",
)


def _effect_modules() -> list[str]:
    """Names of the effect modules on this package's path, in catalogue order."""
    found = sorted(m.name for m in pkgutil.iter_modules(__path__) if m.name not in _INFRASTRUCTURE)
    return sorted(found, key=lambda n: _ORDER.index(n) if n in _ORDER else len(found))


def _discover() -> dict[str, Effect]:
    effects = []
    for name in _effect_modules():
        module = importlib.import_module(f"{__name__}.{name}")
        effect = getattr(module, "EFFECT", None)
        if not isinstance(effect, Effect):
            raise TypeError(f"{module.__name__} defines no EFFECT = Effect(...)")
        if effect.name != name:
            raise ValueError(
                f"{module.__name__} defines the effect {effect.name!r}; name them alike"
            )
        effects.append(effect)
    return catalogue_of(effects)


#: Every effect, by catalogue name, in a fixed order (``Effect.index``).
CATALOGUE: dict[str, Effect] = _discover()

#: Names of the linear pair every model has (the stiffness and the viscous damping).
LINEAR_STIFFNESS: str = _LINEAR_STIFFNESS.name
VISCOUS_DAMPING: str = _VISCOUS_DAMPING.name


def _hysteretic() -> Effect:
    hysteretic = [effect for effect in CATALOGUE.values() if effect.hysteretic]
    if len(hysteretic) != 1:
        # The integrators, the harmonic balance and the rig carry the state of one
        # Jenkins element (jenkins_force); a second needs state kernels of its own.
        raise ValueError(
            f"the kernels carry one hysteretic element, the catalogue has {len(hysteretic)}: "
            f"{[e.name for e in hysteretic]}"
        )
    return hysteretic[0]


#: The hysteretic effect, the Jenkins element whose state the time integrators, the
#: multi-harmonic balance and the rig carry (through :func:`jenkins_force`).
HYSTERETIC: Effect = _hysteretic()

#: Index of the hysteretic Jenkins element, for the numba kernels.
MICROSLIP_INDEX = HYSTERETIC.index

#: ``memoryless_force(index, x, v, p0, p1)``: the force kernel of the effect with
#: catalogue ``index`` (numba, inlined into its callers; see
#: :func:`~identification.effects.base.force_dispatcher`). The hysteretic
#: ``microslip`` gives 0 here; the integrators evaluate it through :func:`jenkins_force`.
memoryless_force = force_dispatcher(list(CATALOGUE.values()))


def get_effect(name: str) -> Effect:
    """The catalogue effect called ``name``; ValueError naming it if unknown."""
    try:
        return CATALOGUE[name]
    except KeyError:
        raise ValueError(
            f"unknown effect {name!r}; the catalogue has: {', '.join(CATALOGUE)}"
        ) from None


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
