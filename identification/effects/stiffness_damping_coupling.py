"""``stiffness_damping_coupling``: φ = x·ẋ, displacement-dependent damping, asymmetric in x.

Even: no single-harmonic describing function (see ``quadratic_stiffness``).
"""

import numba

from identification.effects.base import Effect, HiddenScenario


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return x * v


EFFECT = Effect(
    name="stiffness_damping_coupling",
    term="x·ẋ",
    units="1/(m·s)",
    reading="displacement-dependent damping, asymmetric in x",
    force=_force,
    parity="even",
    polynomial=True,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: 1.6e5,
        description=("x·ẋ (even) leaves a 2nd harmonic and softens at 2 mm"),
        key_channel="harmonics",
    ),
)
