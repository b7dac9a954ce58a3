"""The default (paper's) library does no worse than the polynomial one (issue #16, item 6).

The joint terms of the paper's library (exp, tanh, friction, …) can imitate polynomials with wrong
ratios; the issue's finite-element panel decays got a backbone 28 % off that way while the
polynomial library was within 0.56 %. Here both libraries identify the same free decays of
several truths, simulated by :mod:`tests.independent_sim` (scipy's DOP853, no project kernels),
and each identified model's multi-harmonic backbone is compared with the truth's over the decay's
own amplitude range. The truths include one the polynomial library can represent exactly and
one it cannot (quadratic damping ``ẋ|ẋ|``).
"""

import warnings

import numpy as np
import pytest
from independent_sim import free_decay

from identification.analytical import harmonic
from identification.effects import CATALOGUE
from identification.model import JointModel
from identification.sindy import (
    PAPER_LIBRARY,
    POLYNOMIAL_LIBRARY,
    identify_kinematics,
    sensor_kinematics,
)

OMEGA = 2 * np.pi * 105.0
K1, C1 = OMEGA**2, 2 * 0.004 * OMEGA
NOISE_M = 2e-7
#: name: (catalogue coefficients beside k1 and c1, the same force as plain Python)
TRUTHS = {
    "asymmetric-softening": (
        {"quadratic_stiffness": -1.5e8, "cubic_stiffness": 3e10},
        lambda x, v: K1 * x + C1 * v - 1.5e8 * x * x + 3e10 * x**3,
    ),
    "hardening-cubic-damping": (
        {"cubic_stiffness": 8e10, "cubic_damping": 30.0},
        lambda x, v: K1 * x + C1 * v + 8e10 * x**3 + 30.0 * v**3,
    ),
    "quadratic-damping": (
        {"cubic_stiffness": 2e10, "quadratic_damping": 10.0},
        lambda x, v: K1 * x + C1 * v + 2e10 * x**3 + 10.0 * v * abs(v),
    ),
}


def test_polynomial_library_is_the_polynomial_effects_by_degree():
    # Derived from Effect.polynomial: the members and order it had when written by hand.
    assert POLYNOMIAL_LIBRARY == (
        "linear_stiffness", "viscous_damping", "quadratic_stiffness",
        "stiffness_damping_coupling", "velocity_squared", "cubic_stiffness", "van_der_pol",
        "displacement_velocity_squared", "cubic_damping",
    )  # fmt: skip
    assert set(POLYNOMIAL_LIBRARY) == {n for n, e in CATALOGUE.items() if e.polynomial}
    assert list(PAPER_LIBRARY) == [n for n in CATALOGUE if n != "microslip"]
    # Each is the monomial xⁱẋʲ, ordered by degree i + j, then by the power of x.
    x, v = np.array([0.3, -1.7, 2.2]), np.array([1.1, 0.4, -0.9])
    powers = [(1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (3, 0), (2, 1), (1, 2), (0, 3)]
    for name, (i, j) in zip(POLYNOMIAL_LIBRARY, powers, strict=True):
        np.testing.assert_allclose(CATALOGUE[name].feature(x, v), x**i * v**j, rtol=1e-15)


def backbone_error(truth: JointModel, force, library) -> float:
    """Largest relative frequency error of the identified model's backbone over the decay."""
    decay = free_decay(force, 1e-3, 0.0, duration_s=1.0)
    rng = np.random.default_rng(5)
    response = decay["displacement_m"] + NOISE_M * rng.standard_normal(decay["time_s"].size)
    kinematics = sensor_kinematics(decay["time_s"], response, "displacement")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # collinearity notes; the comparison judges the model
        model = identify_kinematics([kinematics], library).model
    # the decay's amplitude range (1 mm falls below 0.07 mm in 1 s for each truth)
    amplitudes = np.geomspace(1.5e-4, 8e-4, 12)
    expected = harmonic.backbone(truth, amplitudes, method="multi")
    found = harmonic.backbone(model, amplitudes, method="multi")
    if not np.all(found.converged):
        return np.inf
    return float(np.max(np.abs(found.frequency_hz / expected.frequency_hz - 1)))


@pytest.mark.parametrize(
    "name",
    [pytest.param(name, marks=[] if name == "quadratic-damping" else pytest.mark.slow)
     for name in TRUTHS],
)  # fmt: skip
def test_the_default_library_does_no_worse_than_the_polynomial_one(name):
    coefficients, force = TRUTHS[name]
    truth = JointModel({"linear_stiffness": K1, "viscous_damping": C1, **coefficients})
    default = backbone_error(truth, force, PAPER_LIBRARY)
    polynomial = backbone_error(truth, force, POLYNOMIAL_LIBRARY)
    print(f"{name}: default {default:.3%}, polynomial {polynomial:.3%}")
    # no worse: within a tenth of a percentage point of the polynomial library, and within the
    # issue's 1 % of the truth wherever the polynomial library itself is
    assert default <= polynomial + 1e-3
    assert default < 0.01 or polynomial >= 0.01
