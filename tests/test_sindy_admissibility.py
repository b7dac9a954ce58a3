"""Admissibility of driven records: the phase-resonant excitation must rise with the amplitude.

The model: 100 Hz, Coulomb friction F, viscous damping c and a negative quadratic damping
d·ẋ|ẋ|. By single-harmonic power balance at phase resonance its base acceleration is
``4F/π + c ω a + 8 d ω² a² / (3π)`` (closed form, not the code under test): it rises up to
``a* = −3π c / (16 d ω)`` and falls after, while the damping stays positive. A PLL test
could not hold amplitudes past ``a*`` at rising levels, so driven records that did exclude it.
"""

import numpy as np
import pytest

from identification.analytical import harmonic
from identification.model import JointModel
from identification.sindy import admissible

OMEGA = 2 * np.pi * 100.0
F, C, D = 1.0, 2 * 0.001 * OMEGA, -0.5
MODEL = JointModel({"linear_stiffness": OMEGA**2, "coulomb_friction": F,
                    "viscous_damping": C, "quadratic_damping": D})  # fmt: skip
PEAK_M = -3 * np.pi * C / (16 * D * OMEGA)  # 2.4 mm


def closed_form_level(amplitude_m):
    return 4 * F / np.pi + C * OMEGA * amplitude_m + 8 * D * OMEGA**2 * amplitude_m**2 / (3 * np.pi)


def test_closed_form_matches_the_harmonic_balance():
    amplitude_m = np.linspace(0.5e-3, 4e-3, 8)
    result = harmonic.backbone(MODEL, amplitude_m, method="single")
    np.testing.assert_allclose(result.base_acceleration, closed_form_level(amplitude_m), rtol=1e-3)
    assert np.all(result.damping_ratio > 0)


@pytest.mark.parametrize(("high_m", "rising"), [(0.9 * PEAK_M, True), (1.6 * PEAK_M, False)])
def test_a_falling_excitation_is_inadmissible_for_driven_records_only(high_m, rising):
    amplitude_m = np.geomspace(0.3e-3, high_m, 16)
    assert admissible(MODEL, amplitude_m)  # positive damping throughout: a decay may show it
    assert admissible(MODEL, amplitude_m, increasing_excitation=True) is rising
