"""``coulomb_friction``: φ = sign(ẋ), macroslip dry friction in the bolted joint.

The kernel smooths the sign over ``v_reg`` (a numerical device for the time
integrators, see :data:`~identification.effects.special.DEFAULT_SIGN_VELOCITY`).
The describing function is the ideal one: dry friction dissipates 4a per cycle
per unit force, c_eq = 4/(π a ω); the regularisation only rounds the reversal
and is left out on purpose.
"""

from collections.abc import Mapping
from typing import Any

import numba
import numpy as np

from identification.effects.base import (
    ArrayNamespace,
    Effect,
    FitScale,
    HiddenScenario,
    ShapeParameter,
)
from identification.effects.special import DEFAULT_SIGN_VELOCITY, smooth_sign


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return smooth_sign(v, p0)


def _damping(xp: ArrayNamespace, a: Any, omega: Any, **_: Any) -> Any:
    return 4.0 / (np.pi * a * omega)


def _fitted_reading(coefficient: float, shape: Mapping[str, float], scale: FitScale) -> str:
    return f" (slip force {abs(coefficient):.3g} m/s² per unit modal mass)"


EFFECT = Effect(
    name="coulomb_friction",
    term="sign(ẋ)",
    units="m/s²",
    reading="macroslip dry friction in the bolted joint",
    force=_force,
    shape_parameters=(ShapeParameter("v_reg", DEFAULT_SIGN_VELOCITY, "m/s"),),
    damping=_damping,
    fitted_reading=_fitted_reading,
    coefficient_sign=1,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: 0.2,
        description=("Coulomb friction triples the damping at 0.05 mm, fading as 1/amplitude"),
        key_channel="damping_ratio",
    ),
)
