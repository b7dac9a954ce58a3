"""``linear_stiffness``: the modal stiffness, φ = x."""

from typing import Any

import numba

from identification.effects.base import ArrayNamespace, Effect


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return x


def _stiffness(xp: ArrayNamespace, a: Any, **_: Any) -> Any:
    return xp.ones_like(a)


EFFECT = Effect(
    name="linear_stiffness",
    term="x",
    units="1/s²",
    reading="modal stiffness",
    force=_force,
    polynomial=True,
    stiffness=_stiffness,
)
