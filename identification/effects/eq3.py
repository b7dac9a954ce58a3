"""The paper's Eq. 3 mapped onto the catalogue, written once.

Eq. 3 reads ẍ + k1 x + k2 ẋ − k3 x² − k4 xẋ + k5 ẋ² − k6 x³ − k7 xẋ² − k8 ẋ³
− k9 x|x| + k10 ẋ|ẋ| + k11 (1 − k12 x²) ẋ = f. Catalogue terms are added on
the left-hand side, so the minus signs go into the coefficients, and
k11 (1 − k12 x²) ẋ splits into viscous damping k11 and Van der Pol −k11 k12.
The excitation f is the base term −a_base. The ``pandey2025`` preset of
:mod:`identification.model` takes its values from here, and the SINDy reports
write each coefficient in the paper's symbols from here.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import NamedTuple

__all__ = ["EQ3", "EQ3_VALUES", "Eq3Coefficient", "eq3_coefficients"]

#: The paper's identified values of Eq. 3's k1 … k12 (SI, mass-normalised).
EQ3_VALUES: dict[str, float] = dict(
    k1=4.49e5, k2=1.85, k3=2.60e7, k4=2.95e4, k5=60.5, k6=3.32e9,
    k7=2.33e4, k8=9.50, k9=3.35e7, k10=11.6, k11=5.66, k12=5.10e5,
)  # fmt: skip


class Eq3Coefficient(NamedTuple):
    """How one catalogue coefficient reads in Eq. 3.

    Attributes
    ----------
    symbols
        The coefficient in the paper's symbols, e.g. ``"−k3"``.
    value
        ``(k) -> coefficient`` from the values of k1 … k12 by name.
    """

    symbols: str
    value: Callable[[Mapping[str, float]], float]


#: Eq. 3 on the catalogue: each effect's coefficient in the paper's symbols and its value.
EQ3: dict[str, Eq3Coefficient] = {
    "linear_stiffness": Eq3Coefficient("k1", lambda k: k["k1"]),
    "viscous_damping": Eq3Coefficient("k2 + k11", lambda k: k["k2"] + k["k11"]),
    "quadratic_stiffness": Eq3Coefficient("−k3", lambda k: -k["k3"]),
    "stiffness_damping_coupling": Eq3Coefficient("−k4", lambda k: -k["k4"]),
    "velocity_squared": Eq3Coefficient("k5", lambda k: k["k5"]),
    "cubic_stiffness": Eq3Coefficient("−k6", lambda k: -k["k6"]),
    "displacement_velocity_squared": Eq3Coefficient("−k7", lambda k: -k["k7"]),
    "cubic_damping": Eq3Coefficient("−k8", lambda k: -k["k8"]),
    "abs_stiffness": Eq3Coefficient("−k9", lambda k: -k["k9"]),
    "quadratic_damping": Eq3Coefficient("k10", lambda k: k["k10"]),
    "van_der_pol": Eq3Coefficient("−k11·k12", lambda k: -k["k11"] * k["k12"]),
}


def eq3_coefficients(values: Mapping[str, float] = EQ3_VALUES) -> dict[str, float]:
    """The catalogue coefficients of Eq. 3 with ``values`` of k1 … k12 (the paper's by default)."""
    return {effect: coefficient.value(values) for effect, coefficient in EQ3.items()}
