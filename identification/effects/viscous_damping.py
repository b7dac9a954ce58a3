"""``viscous_damping``: linear modal damping, φ = ẋ."""

from typing import Any

import numba

from identification.effects.base import ArrayNamespace, Effect


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return v


def _damping(xp: ArrayNamespace, a: Any, omega: Any, **_: Any) -> Any:
    return xp.ones_like(a)


EFFECT = Effect(
    name="viscous_damping",
    term="ẋ",
    units="1/s",
    reading="linear modal damping",
    force=_force,
    polynomial=True,
    damping=_damping,
)
