"""``velocity_squared``: φ = ẋ², asymmetric damping.

Even: no single-harmonic describing function (see ``quadratic_stiffness``).
"""

import numba

from identification.effects.base import Effect


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return v * v


EFFECT = Effect(
    name="velocity_squared",
    term="ẋ²",
    units="1/m",
    reading="asymmetric damping",
    force=_force,
    parity="even",
    polynomial=True,
)
