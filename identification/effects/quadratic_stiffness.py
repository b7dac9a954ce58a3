"""``quadratic_stiffness``: φ = x², the asymmetric stiffness of an arched panel.

Even: no first harmonic, so no single-harmonic describing function; it acts
through the mean offset and the 2nd harmonic (multi-harmonic balance).
"""

from collections.abc import Mapping

import numba

from identification.effects.base import Effect, FitScale, HiddenScenario


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    return x * x


def _fitted_reading(coefficient: float, shape: Mapping[str, float], scale: FitScale) -> str:
    return f" (x² coefficient {coefficient:.3g} 1/(m·s²))"


EFFECT = Effect(
    name="quadratic_stiffness",
    term="x²",
    units="1/(m·s²)",
    reading="asymmetric stiffness of the arched panel",
    force=_force,
    parity="even",
    polynomial=True,
    fitted_reading=_fitted_reading,
    hidden_scenario=HiddenScenario(
        truth=lambda k0: -5e7,
        description=("x² takes about 2 % off the 2 mm frequency (with a 2nd harmonic)"),
        key_channel="harmonics",
        on_hardening_base=True,
    ),
)
