"""``tanh_saturation``: φ = tanh(x/x_s), a saturating stiffness.

Describing function: k_eq = g(a/x_s)/x_s with the one dimensionless gain
g(u) = (2/u)⟨tanh(u cos θ) cos θ⟩, which has no closed form (see
:mod:`identification.effects.special`).
"""

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


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return np.tanh(x / p0)


def _stiffness(xp: ArrayNamespace, a: Any, x_s: Any, **_: Any) -> Any:
    return xp.tanh_gain(a / x_s) / x_s


def _shape_grid(scale: FitScale) -> dict[str, np.ndarray]:
    a_lo, a_hi = scale.amplitude_m
    return {"x_s": np.geomspace(a_lo / 3, 10 * a_hi, 16)}


def _shape_bounds(scale: FitScale) -> dict[str, tuple[float, float]]:
    a_lo, a_hi = scale.amplitude_m
    return {"x_s": (a_lo / 10, 100 * a_hi)}


EFFECT = Effect(
    name="tanh_saturation",
    term="tanh(x/x_s)",
    units="m/s²",
    reading="saturating stiffness",
    force=_force,
    shape_parameters=(ShapeParameter("x_s", 1e-3, "m"),),
    stiffness=_stiffness,
    shape_grid=_shape_grid,
    shape_bounds=_shape_bounds,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: {"coefficient": 20.0, "x_s": 5e-4},
        description=(
            "a saturating spring (10 % of the stiffness at rest, x_s = 0.5 mm) softens by "
            "about 3.5 % at 2 mm"
        ),
        key_channel="frequency_hz",
    ),
)
