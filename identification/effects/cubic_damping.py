"""``cubic_damping``: φ = ẋ³, nonlinear viscous damping.

Describing function: c_eq = ¾(aω)².
"""

from typing import Any

import numba

from identification.effects.base import ArrayNamespace, Effect, HiddenScenario


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return v * v * v


def _damping(xp: ArrayNamespace, a: Any, omega: Any, **_: Any) -> Any:
    return 0.75 * (a * omega) ** 2


EFFECT = Effect(
    name="cubic_damping",
    term="ẋ³",
    units="s/m²",
    reading="nonlinear viscous damping",
    force=_force,
    polynomial=True,
    damping=_damping,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: 6.0,
        description=("ẋ³ raises the damping from 0.3 % to about 0.9 % at 2 mm"),
        key_channel="damping_ratio",
    ),
)
