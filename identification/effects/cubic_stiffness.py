"""``cubic_stiffness``: φ = x³, membrane stretching (hardening if positive).

Describing function: (1/πa)∫(a cos θ)³ cos θ dθ = ¾a².
"""

from collections.abc import Mapping
from typing import Any

import numba

from identification.effects.base import ArrayNamespace, Effect, FitScale, HiddenScenario


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return x * x * x


def _stiffness(xp: ArrayNamespace, a: Any, **_: Any) -> Any:
    return 0.75 * a**2


def _fitted_reading(coefficient: float, shape: Mapping[str, float], scale: FitScale) -> str:
    return " (hardening)" if coefficient > 0 else " (softening)"


EFFECT = Effect(
    name="cubic_stiffness",
    term="x³",
    units="1/(m²·s²)",
    reading="membrane stretching (hardening if positive)",
    force=_force,
    polynomial=True,
    stiffness=_stiffness,
    fitted_reading=_fitted_reading,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: 1.4e10,
        description=("x³ hardens by 5 % at 2 mm"),
        key_channel="frequency_hz",
    ),
)
