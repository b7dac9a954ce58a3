"""``van_der_pol``: φ = x²·ẋ, amplitude-dependent (self-excited if negative) damping.

Describing function: c_eq = ¼a².
"""

from typing import Any

import numba

from identification.effects.base import ArrayNamespace, Effect, HiddenScenario


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return x * x * v


def _damping(xp: ArrayNamespace, a: Any, omega: Any, **_: Any) -> Any:
    return 0.25 * a**2


EFFECT = Effect(
    name="van_der_pol",
    term="x²·ẋ",
    units="1/(m²·s)",
    reading="amplitude-dependent (self-excited) damping",
    force=_force,
    polynomial=True,
    damping=_damping,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: 7.5e6,
        description=("x²·ẋ raises the damping from 0.3 % to about 0.9 % at 2 mm"),
        key_channel="damping_ratio",
    ),
)
