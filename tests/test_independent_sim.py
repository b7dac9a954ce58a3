"""The independent ring-downs against closed forms: tests built on them stand on firm ground."""

import numpy as np
from independent_sim import forced_steady_state, free_decay

from independent.decays import (
    ModalSystem,
    PotentialTerm,
    modal_backbones,
    modal_free_decay,
    rounded_time_stamps,
)
from independent.forces import Clearance, Microslip, PowerLawDamping


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


# ---------------------------------------------------------------------------
# Several modes (independent.decays.modal_free_decay)


def _damped(omega0, zeta, q0, v0, t):
    """Free response of q̈ + 2ζω0 q̇ + ω0² q = 0 from (q0, v0)."""
    omega_d = omega0 * np.sqrt(1 - zeta**2)
    b = (v0 + zeta * omega0 * q0) / omega_d
    return np.exp(-zeta * omega0 * t) * (q0 * np.cos(omega_d * t) + b * np.sin(omega_d * t))


def test_two_uncoupled_modes_are_their_modal_superposition():
    system = ModalSystem((100.0, 230.0), (0.01, 0.02))
    shapes = np.array([[1.0, 0.5], [0.3, -1.0]])
    decay = modal_free_decay(system, [1e-3, 5e-4], [0.0, 0.1], sensor_shapes=shapes, duration_s=0.1)
    t = decay.time_s
    q = np.array(
        [_damped(w, z, q0, v0, t) for w, z, q0, v0 in
         zip(system.omega_rad_s, (0.01, 0.02), (1e-3, 5e-4), (0.0, 0.1), strict=True)]
    )  # fmt: skip
    assert np.max(np.abs(decay.displacement_m - shapes @ q)) < 1e-9 * 1e-3
    w = system.omega_rad_s[:, None]
    expected_acc = -(w**2) * q - 2 * np.array([[0.01], [0.02]]) * w * decay.modal_velocity
    assert (
        np.max(np.abs(decay.modal_acceleration - expected_acc)) < 1e-9 * np.abs(expected_acc).max()
    )


def test_a_linear_joint_couples_the_modes_through_its_shape():
    """A spring k and a damper c on u = φ·q are the matrices k φφᵀ and c φφᵀ: the decay is the
    matrix exponential of the first-order system."""
    from scipy.linalg import expm

    system = ModalSystem(
        (100.0, 180.0), (0.005, 0.005), joint_shape=(1.0, -0.6),
        joint_terms=(Clearance(0.0, 5e4), PowerLawDamping(2.0, 1.0)),
    )  # fmt: skip
    decay = modal_free_decay(system, [1e-3, 0.0], duration_s=0.05)
    w = system.omega_rad_s
    phi = np.array([1.0, -0.6])
    stiffness = np.diag(w**2) + 5e4 * np.outer(phi, phi)
    damping = np.diag(2 * 0.005 * w) + 2.0 * np.outer(phi, phi)
    a = np.block([[np.zeros((2, 2)), np.eye(2)], [-stiffness, -damping]])
    y0 = np.array([1e-3, 0.0, 0.0, 0.0])
    exact = np.array([expm(a * t) @ y0 for t in decay.time_s[::25]]).T
    assert np.max(np.abs(decay.modal_displacement[:, ::25] - exact[:2])) < 1e-9 * 1e-3


def test_a_q1_squared_q2_coupling_conserves_energy_and_exchanges_it_at_1_to_2():
    """Undamped modes at exactly 1:2 with the potential c q1² q2: the total energy is constant
    and mode 1's energy flows into mode 2 (the internal resonance)."""
    system = ModalSystem((120.0, 240.0), (0.0, 0.0), couplings=(PotentialTerm(1e8, (2, 1)),))
    decay = modal_free_decay(system, [1e-3, 0.0], duration_s=0.15, fs_hz=5000.0)
    energy = system.energy(decay.modal_displacement, decay.modal_velocity)
    assert np.ptp(energy) < 1e-8 * energy[0]
    w2 = system.omega_rad_s[1]
    mode2 = 0.5 * (decay.modal_velocity[1] ** 2 + (w2 * decay.modal_displacement[1]) ** 2)
    assert mode2.max() > 0.2 * energy[0]


def test_time_stamps_are_written_with_seven_significant_digits():
    assert rounded_time_stamps([1.23456789, 0.000123456789, 0.1]).tolist() == [
        1.234568,
        0.0001234568,
        0.1,
    ]
    decay = modal_free_decay(
        ModalSystem((100.0,), (0.01,)), [1e-3], fs_hz=3000.0, duration_s=0.01, time_digits=7
    )
    assert all(float(f"{t:.6e}") == t for t in decay.time_s)
    assert np.max(np.abs(decay.time_s - np.arange(30) / 3000.0)) <= 5e-7 * decay.time_s.max()


def test_modal_backbones_of_linear_modes_are_their_frequency_and_damping():
    system = ModalSystem((100.0, 230.0), (0.01, 0.005))
    decay = modal_free_decay(
        system, [1e-3, 5e-4], sensor_shapes=[[1.0, 1.0]], duration_s=0.35, rtol=1e-8
    )
    for backbone, (f, zeta) in zip(
        modal_backbones(decay, [(60.0, 150.0), (180.0, 280.0)]), [(100.0, 0.01), (230.0, 0.005)],
        strict=True,
    ):  # fmt: skip
        middle = slice(backbone.time_s.size // 4, 3 * backbone.time_s.size // 4)
        np.testing.assert_allclose(
            backbone.frequency_hz[middle], f * np.sqrt(1 - zeta**2), rtol=1e-4
        )
        np.testing.assert_allclose(backbone.damping_ratio[middle], zeta, rtol=0.02)


def test_a_jenkins_joint_in_a_ring_down_dissipates_masings_energy_per_half_cycle():
    """One undamped mode with a Jenkins element on it. Between turning points x_i, x_{i+1} the
    element reverses elastically over 2 F_s/k_t and slips the rest, so the mode loses
    ½ω0²(x_i² − x_{i+1}²) = F_s (|x_i − x_{i+1}| − 2 F_s/k_t); and the energy (the element's
    spring included) never rises."""
    w0 = 2 * np.pi * 100.0
    k_t, f_s = 0.2 * w0**2, 0.2 * w0**2 * 2e-4
    system = ModalSystem(
        (100.0,), (0.0,), joint_shape=(1.0,), joint_terms=(Microslip(1.0, k_t, f_s),)
    )
    decay = modal_free_decay(system, [8e-4], fs_hz=20_000.0, duration_s=0.035, rtol=1e-9)
    q, v, acc = decay.modal_displacement[0], decay.modal_velocity[0], decay.modal_acceleration[0]
    element = -acc - w0**2 * q  # the element's force, from the equation of motion
    energy = 0.5 * v**2 + 0.5 * w0**2 * q**2 + element**2 / (2 * k_t)
    assert np.all(np.diff(energy) <= 1e-9 * energy[0])
    turns = np.flatnonzero(np.sign(v[1:]) != np.sign(v[:-1]))
    turns = np.where(np.abs(v[turns]) < np.abs(v[turns + 1]), turns, turns + 1)
    x = q[turns] - v[turns] ** 2 / (2 * acc[turns])  # the extreme, from the nearest sample
    x = x[1:]  # from the first turn on, the element arrives at each turn slipping (±F_s)
    lost = 0.5 * w0**2 * (x[:-1] ** 2 - x[1:] ** 2)
    masing = f_s * (np.abs(np.diff(x)) - 2 * f_s / k_t)
    assert len(x) >= 6 and np.all(masing > 0)
    np.testing.assert_allclose(lost, masing, rtol=1e-3)


def test_a_one_sensor_decay_of_two_modes_near_1_to_2_reads_back_as_written(tmp_path):
    """The record issue #26's acceptance reads: one sensor, two modes near 1:2 with a q1² q2
    coupling, 7-digit time stamps, a CSV file the column readers take."""
    system = ModalSystem((122.0, 243.0), (0.002, 0.003), couplings=(PotentialTerm(1e8, (2, 1)),))
    decay = modal_free_decay(
        system, [1e-3, 1e-4], sensor_shapes=[[1.0, 0.6]], fs_hz=5000.0, duration_s=0.05,
        time_digits=7,
    )  # fmt: skip
    path = decay.write_csv(tmp_path / "decay.csv", names=["tip"])
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    assert path.read_text().splitlines()[0] == "time,tip"
    assert np.array_equal(table[:, 0], decay.time_s)
    np.testing.assert_allclose(table[:, 1], decay.displacement_m[0], rtol=1e-11)
    np.testing.assert_allclose(
        decay.displacement_m[0], decay.modal_displacement[0] + 0.6 * decay.modal_displacement[1]
    )
