"""``velocity_squared``: φ = ẋ², asymmetric damping.

Even: no single-harmonic describing function (see ``quadratic_stiffness``).
"""

import numba

from identification.effects.base import Effect, HiddenScenario


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
    hidden_scenario=HiddenScenario(
        truth=lambda k0: 130.0,
        description=("ẋ² (even) shifts the mean and leaves a 2nd harmonic; softens at 2 mm"),
        key_channel="harmonics",
    ),
)
