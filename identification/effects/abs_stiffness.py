"""``abs_stiffness``: φ = x·|x|, one-sided contact or clearance.

Describing function: (1/πa)∫ a² cos θ |cos θ| cos θ dθ = 8a/(3π).
"""

from typing import Any

import numba
import numpy as np

from identification.effects.base import ArrayNamespace, Effect, HiddenScenario


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return x * abs(x)


def _stiffness(xp: ArrayNamespace, a: Any, **_: Any) -> Any:
    return 8.0 * a / (3.0 * np.pi)


EFFECT = Effect(
    name="abs_stiffness",
    term="x·|x|",
    units="1/(m·s²)",
    reading="one-sided contact / clearance",
    force=_force,
    stiffness=_stiffness,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: -2.4e7,
        description=("x|x| softens by 5 % at 2 mm"),
        key_channel="frequency_hz",
    ),
)
