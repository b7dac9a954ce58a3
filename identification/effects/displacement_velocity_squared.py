"""``displacement_velocity_squared``: φ = x·ẋ², a velocity-dependent (inertial) stiffness.

Describing function: k_eq = ¼a²ω², the catalogue's one stiffness that depends
on the frequency (affine in ω², so the backbone still has a closed form).
"""

from typing import Any

import numba

from identification.effects.base import ArrayNamespace, Effect, HiddenScenario


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return x * v * v


def _stiffness_per_omega_squared(xp: ArrayNamespace, a: Any, **_: Any) -> Any:
    return 0.25 * a**2


EFFECT = Effect(
    name="displacement_velocity_squared",
    term="x·ẋ²",
    units="1/m²",
    reading="velocity-dependent stiffness (inertial nonlinearity)",
    force=_force,
    polynomial=True,
    stiffness_per_omega_squared=_stiffness_per_omega_squared,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: -1e5,
        description=("x·ẋ² softens by 5 % at 2 mm"),
        key_channel="frequency_hz",
    ),
)
