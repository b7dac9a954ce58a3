"""The independent test simulator against closed forms: tests built on it stand on firm ground."""

import numpy as np
from independent_sim import forced_steady_state, free_decay


def test_linear_free_decay_is_the_closed_form():
    omega0, zeta, x0 = 2 * np.pi * 100.0, 0.01, 1e-3
    decay = free_decay(lambda x, v: omega0**2 * x + 2 * zeta * omega0 * v, x0, 0.0, duration_s=0.2)
    t = decay["time_s"]
    omega_d = omega0 * np.sqrt(1 - zeta**2)
    exact = (
        x0
        * np.exp(-zeta * omega0 * t)
        * (np.cos(omega_d * t) + zeta * omega0 / omega_d * np.sin(omega_d * t))
    )
    assert np.max(np.abs(decay["displacement_m"] - exact)) < 1e-9 * x0


def test_linear_forced_response_is_the_frf():
    omega0, zeta, frequency_hz = 2 * np.pi * 100.0, 0.02, 95.0
    omega = 2 * np.pi * frequency_hz
    steady = forced_steady_state(
        lambda x, v: omega0**2 * x + 2 * zeta * omega0 * v,
        lambda t: np.cos(omega * t),
        1 / frequency_hz,
        settle_periods=300,
        record_periods=20,
    )
    expected = 1 / abs(omega0**2 - omega**2 + 2j * zeta * omega0 * omega)
    x = steady["displacement_m"]
    assert abs(0.5 * (x.max() - x.min()) / expected - 1) < 1e-4
