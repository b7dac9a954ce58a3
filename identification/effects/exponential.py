"""``exponential``: φ = exp(x/x_s) − 1, the growth/decay term of the paper's library.

Mixed parity: its odd part sinh(x/x_s) gives the describing function
(1/πa)∫ e^{z cos θ} cos θ dθ = 2 I₁(z)/a with z = a/x_s; its even part acts
through the mean and even harmonics only.
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
    return np.expm1(x / p0)


def _stiffness(xp: ArrayNamespace, a: Any, x_s: Any, **_: Any) -> Any:
    return 2.0 * xp.i1(a / x_s) / a


def _shape_grid(scale: FitScale) -> dict[str, np.ndarray]:
    a_hi = scale.amplitude_m[1]
    return {"x_s": np.geomspace(a_hi / 3, 30 * a_hi, 16)}


def _shape_bounds(scale: FitScale) -> dict[str, tuple[float, float]]:
    a_hi = scale.amplitude_m[1]
    return {"x_s": (a_hi / 10, 1e3 * a_hi)}


EFFECT = Effect(
    name="exponential",
    term="exp(x/x_s) − 1",
    units="m/s²",
    reading="growth/decay term from the paper's library",
    force=_force,
    parity="mixed",
    shape_parameters=(ShapeParameter("x_s", 1e-3, "m"),),
    stiffness=_stiffness,
    shape_grid=_shape_grid,
    shape_bounds=_shape_bounds,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: {"coefficient": 40.0, "x_s": 1e-3},
        description=("exp(x/x_s) − 1 (x_s = 1 mm) hardens and leaves even harmonics"),
        key_channel="frequency_hz",
    ),
)
