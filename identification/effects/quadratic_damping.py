"""``quadratic_damping``: φ = ẋ·|ẋ|, fluid or aerodynamic damping.

Describing function: c_eq = 8aω/(3π) (the x·|x| integral on the velocity).
"""

from typing import Any

import numba
import numpy as np

from identification.effects.base import ArrayNamespace, Effect, HiddenScenario


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return v * abs(v)


def _damping(xp: ArrayNamespace, a: Any, omega: Any, **_: Any) -> Any:
    return 8.0 * a * omega / (3.0 * np.pi)


EFFECT = Effect(
    name="quadratic_damping",
    term="ẋ·|ẋ|",
    units="1/m",
    reading="fluid / aerodynamic damping",
    force=_force,
    damping=_damping,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: 5.0,
        description=("ẋ|ẋ| raises the damping from 0.3 % to about 0.7 % at 2 mm"),
        key_channel="damping_ratio",
    ),
)
