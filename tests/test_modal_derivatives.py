"""Derived channels of the modal path without the difference rules' frequency bias.

Independent expectations: the closed-form gains of the central difference (``sin θ/θ``) and
of the trapezoidal rule (``(θ/2) cot(θ/2)``), and a pure sinusoid of known frequency, whose
kinematics satisfy ``ẍ = −ω² x`` and ``ẋ = ω x`` in quadrature exactly.
"""

from __future__ import annotations

import numpy as np
import pytest

from identification.sindy.kinematics import sensor_kinematics
from identification.sindy.modal_derivatives import (
    central_difference_inverse_gain,
    trapezoid_inverse_gain,
    unbiased_kinematics,
)

RATE_HZ = 10_000.0
#: The asked bias at the modes' frequencies (the brief: below 1e-5).
BIAS = 1e-5


def test_the_series_invert_the_rules_gains():
    theta = np.linspace(1e-4, 0.5, 400)  # up to a twelfth of the sampling rate
    np.testing.assert_allclose(central_difference_inverse_gain(theta) * np.sin(theta) / theta,
                               1.0, atol=1e-8)  # fmt: skip
    np.testing.assert_allclose(trapezoid_inverse_gain(theta) * (theta / 2) / np.tan(theta / 2),
                               1.0, atol=1e-8)  # fmt: skip


@pytest.mark.parametrize("quantity", ["displacement", "velocity", "acceleration"])
@pytest.mark.parametrize("frequency_hz", [100.0, 201.0, 600.0])
def test_a_sinusoids_frequency_is_read_without_bias(quantity, frequency_hz):
    t = np.arange(int(0.5 * RATE_HZ)) / RATE_HZ
    omega = 2 * np.pi * frequency_hz
    # The measured quantity of x = sin(ωt) (its derivatives), from rest-free motion.
    signal = {"displacement": np.sin(omega * t), "velocity": omega * np.cos(omega * t),
              "acceleration": -(omega**2) * np.sin(omega * t)}[quantity]  # fmt: skip
    raw = sensor_kinematics(t, signal, quantity, band_hz=(30.0, 2000.0))
    fixed = unbiased_kinematics(raw, quantity)

    def frequency_errors(k):
        basis = np.column_stack([np.sin(omega * t), np.cos(omega * t)])[k.valid]

        def amplitude(channel):  # of the channel's sinusoid, whatever the window's length
            return np.hypot(*np.linalg.lstsq(basis, channel[k.valid], rcond=None)[0])

        x = amplitude(k.displacement)
        from_velocity = amplitude(k.velocity) / x / omega - 1
        from_acceleration = np.sqrt(amplitude(k.acceleration) / x) / omega - 1
        return np.array([from_acceleration, from_velocity])

    assert np.max(np.abs(frequency_errors(fixed))) < BIAS
    # The uncorrected rules are off by θ²/24 … θ²/6: the check above can fail.
    theta = omega / RATE_HZ
    assert np.max(np.abs(frequency_errors(raw))) > theta**2 / 30
