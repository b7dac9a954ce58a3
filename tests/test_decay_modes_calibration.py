"""Calibration of the second-mode warning on held-out seeds (slow: about 40 simulated decays).

Outcome rules, fixed before the study ran: over ``N`` one-mode decays of random nonlinearity
(a 2nd harmonic up to 5 %, a cubic frequency shift up to ±3 %, random damping, frequency,
noise and sensor quantity; the independent one-mode simulator) at most one warning (a
false-alarm rate whose 95 % Clopper–Pearson interval then stays below 25 %); over ``N``
two-mode decays near 1:2 (detuning up to ±5 Hz, mode 1 with a random 2nd harmonic, mode 2
carrying 10–50 % of the energy at the sensor; the independent two-mode simulator) at least
``N − 1`` warnings, each naming mode 2's frequency within 1 Hz. The rule was chosen on the
decays of ``test_decay_modes.py`` (seeds 0–6); its first run on the held-out block 1 000 000
gave 0 of 20 and 20 of 20; the peak picking then learnt to leave out peaks with fewer than a
window's periods in the decay (the slow mean of a displacement), so the study moved to the
fresh block 2 000 000.
"""

import numpy as np
import pytest
from independent_sim import free_decay
from two_modes import TwoModes, two_mode_decay

from identification.measurements.decay_modes import second_mode

HELD_OUT_SEED = 2_000_000
N = 20
AMPLITUDE_M = 1e-3


def _one_mode(seed):
    rng = np.random.default_rng(seed)
    omega = 2 * np.pi * rng.uniform(90.0, 160.0)
    zeta = rng.uniform(0.002, 0.008)
    k2 = rng.uniform(0.0, 0.05) * 6 * omega**2 / AMPLITUDE_M * rng.choice([-1, 1])
    k3 = rng.uniform(-0.03, 0.03) * 8 * omega**2 / (3 * AMPLITUDE_M**2)

    def force(x, v):
        return omega**2 * x + 2 * zeta * omega * v + k2 * x * x + k3 * x**3

    decay = free_decay(force, AMPLITUDE_M, 0.0, duration_s=1.0)
    quantity = str(rng.choice(["displacement", "velocity"]))
    key = {"displacement": "displacement_m", "velocity": "velocity_m_s"}[quantity]
    scale = 1.0 if quantity == "displacement" else omega
    noise = rng.uniform(1e-8, 1e-7) * scale
    return decay["time_s"], decay[key] + rng.normal(0, noise, decay["time_s"].size), quantity


def _two_modes(seed):
    rng = np.random.default_rng(seed)
    f1 = rng.uniform(90.0, 160.0)
    f2 = 2 * f1 + rng.uniform(-5.0, 5.0)
    zeta = rng.uniform(0.002, 0.006, 2)
    w1 = 2 * np.pi * f1
    k2 = rng.uniform(0.0, 0.05) * 6 * w1**2 / AMPLITUDE_M
    share = rng.uniform(0.1, 0.5)
    # ∫E dt = ωA²/(4ζ) per mode at the sensor: the amplitude of mode 2 for that share
    a2 = np.sqrt(share / (1 - share) * f1 * AMPLITUDE_M**2 / zeta[0] * zeta[1] / f2)
    modes = TwoModes((f1, f2), tuple(zeta), quadratic_mode1=k2)
    decay = two_mode_decay(modes, (AMPLITUDE_M, a2), np.array([[1.0, 1.0]]), duration_s=1.0)
    y = decay["displacement_m"][:, 0] + rng.normal(0, rng.uniform(1e-8, 1e-7), len(decay["time_s"]))
    return decay["time_s"], y, f2 * np.sqrt(1 - zeta[1] ** 2)


@pytest.mark.slow
def test_one_mode_decays_are_rarely_warned():
    warned = 0
    for seed in range(HELD_OUT_SEED, HELD_OUT_SEED + N):
        t, y, quantity = _one_mode(seed)
        found = second_mode(t, y, quantity=quantity)
        warned += found is not None
        print(f"one-mode seed {seed}: {found}")
    print(f"one-mode decays warned: {warned} of {N}")
    assert warned <= 1, f"{warned} of {N} one-mode decays warned"


@pytest.mark.slow
def test_two_mode_decays_are_warned_with_the_second_frequency():
    hits = 0
    for seed in range(HELD_OUT_SEED + N, HELD_OUT_SEED + 2 * N):
        t, y, f2 = _two_modes(seed)
        found = second_mode(t, y, quantity="displacement")
        hits += found is not None and abs(found[0] - f2) < 1.0
        print(f"two-mode seed {seed}: mode 2 at {f2:.2f} Hz, warned {found}")
    print(f"two-mode decays warned with their second frequency: {hits} of {N}")
    assert hits >= N - 1, f"{hits} of {N} two-mode decays warned with their second frequency"
