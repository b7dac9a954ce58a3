"""``stribeck_friction``: φ = sign(ẋ)·exp(−(ẋ/v_s)²), the static-to-kinetic friction drop.

Describing function: ∫₀^π sin θ exp(−b² sin²θ) dθ = 2 D(b)/b with D Dawson's
integral and b = aω/v_s, so c_eq = 4 D(b)/(π a ω b) (the sign's smoothing over
``v_reg`` left out, as for ``coulomb_friction``).
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
    r = v / p0
    return smooth_sign(v, p1) * np.exp(-r * r)


def _damping(xp: ArrayNamespace, a: Any, omega: Any, v_s: Any, **_: Any) -> Any:
    b = a * omega / v_s
    return 4.0 * xp.dawsn(b) / (np.pi * a * omega * b)


def _shape_grid(scale: FitScale) -> dict[str, np.ndarray]:
    # The friction drop can sit anywhere in the test's velocity range.
    v_lo, v_hi = scale.velocity_m_s
    return {"v_s": np.geomspace(v_lo / 3, 10 * v_hi, 16)}


def _shape_bounds(scale: FitScale) -> dict[str, tuple[float, float]]:
    # Far below the smallest response velocity the force spikes at each reversal,
    # faster than the harmonic balance's time grid resolves: numerics, not physics.
    v_lo, v_hi = scale.velocity_m_s
    return {"v_s": (v_lo / 10, 100 * v_hi)}


def _fitted_reading(coefficient: float, shape: Mapping[str, float], scale: FitScale) -> str:
    return f" (slip force {abs(coefficient):.3g} m/s² per unit modal mass)"


EFFECT = Effect(
    name="stribeck_friction",
    term="sign(ẋ)·exp(−(ẋ/v_s)²)",
    units="m/s²",
    reading="static-to-kinetic friction drop",
    force=_force,
    shape_parameters=(
        ShapeParameter("v_s", 1e-2, "m/s"),
        ShapeParameter("v_reg", DEFAULT_SIGN_VELOCITY, "m/s"),
    ),
    damping=_damping,
    shape_grid=_shape_grid,
    shape_bounds=_shape_bounds,
    fitted_reading=_fitted_reading,
    coefficient_sign=1,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: {"coefficient": 0.3, "v_s": 0.1},
        description=(
            "Stribeck friction (v_s = 0.1 m/s) lifts the damping at 0.05 mm from 0.3 % to 1.2 "
            "% and vanishes above 0.3 mm (faster than Coulomb)"
        ),
        key_channel="damping_ratio",
    ),
)
