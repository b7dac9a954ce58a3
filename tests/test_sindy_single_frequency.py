"""SINDy on records held at one excitation frequency: the drive's frequency is not the structure's.

Data: the exact steady state of a linear oscillator (100 Hz, ζ = 1 %) under a base
acceleration at 90 Hz (the closed-form complex amplitude, nothing of pm-joint), 2 s at
10 kHz, 1e-4 m/s of noise on the velocity. With the base channel, the regression target
``ẍ + a_base`` pins the inertia and the 100 Hz is identified; without it (a shaker whose
force was not recorded, as in the issue's bolted beam) ``ẍ = −ω² x`` at the one
frequency and the fit returns 90 Hz as the "natural" frequency: SINDy must say so.
"""

import warnings

import numpy as np
import pytest

from identification.sindy import DriveFrequencyWarning, identify_arrays

FS = 10_000.0
NATURAL_HZ, DRIVE_HZ, ZETA, LEVEL = 100.0, 90.0, 0.01, 5.0
LIBRARY = ["linear_stiffness", "viscous_damping", "cubic_stiffness", "coulomb_friction"]


def steady_state():
    """Time, relative velocity (noisy), base velocity and frequency of the steady response."""
    t = np.arange(0.0, 2.0, 1 / FS)
    wn, w = 2 * np.pi * NATURAL_HZ, 2 * np.pi * DRIVE_HZ
    # ẍ + 2ζωₙẋ + ωₙ²x = −a_b, a_b = A cos ωt: x = Re(X e^{iωt}).
    amplitude = -LEVEL / (wn**2 - w**2 + 2j * ZETA * wn * w)
    velocity = np.real(1j * w * amplitude * np.exp(1j * w * t))
    base_velocity = LEVEL / w * np.sin(w * t)
    noise = 1e-4 * np.random.default_rng(3).standard_normal(t.size)
    return t, velocity + noise, base_velocity, np.full(t.size, DRIVE_HZ)


# Without the excitation the steady response does not decay either: no admissible model, said.
@pytest.mark.filterwarnings("ignore:no candidate model has positive damping")
def test_one_frequency_without_the_excitation_is_flagged():
    t, velocity, _, frequency = steady_state()
    with pytest.warns(DriveFrequencyWarning, match="one excitation frequency"):
        identification = identify_arrays(t, velocity, np.zeros_like(t), frequency, LIBRARY)
    assert identification.model.linear_frequency_hz == pytest.approx(DRIVE_HZ, rel=1e-2)


def test_one_frequency_with_the_excitation_measured_gives_the_natural_frequency():
    t, velocity, base_velocity, frequency = steady_state()
    with warnings.catch_warnings():
        warnings.simplefilter("error", DriveFrequencyWarning)
        identification = identify_arrays(t, velocity, base_velocity, frequency, LIBRARY)
    assert identification.model.linear_frequency_hz == pytest.approx(NATURAL_HZ, rel=1e-2)
