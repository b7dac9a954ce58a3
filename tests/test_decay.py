"""Backbones from free decays, against harmonic balance and the Hilbert transform.

The decays come from the independent simulator (scipy's DOP853 on a force written
here; nothing of pm-joint): an asymmetric panel ẍ + k₁x + k₂x² + k₃x³ + cẋ = 0 that
softens by 5 % over its decay, with a 2nd harmonic of up to 7 % and a mean offset,
sampled at 10 kHz with sensor noise. The truth is its multi-harmonic balance
backbone (pm-joint's, a different method from the decay's local fits); the
reference of the field is the Hilbert transform of the band-passed fundamental.
"""

from types import SimpleNamespace

import numpy as np
import pytest
from independent_sim import free_decay, hilbert_backbone

from identification.analytical import harmonic
from identification.measurements.columns import ColumnRecord
from identification.measurements.decay import extract_decay_backbone
from identification.measurements.extraction import extract_backbone
from identification.model import JointModel

FS = 10_000.0
OMEGA0 = 2 * np.pi * 105.0
K1, K2, K3 = OMEGA0**2, -2.0e8, 4.0e10
C = 2 * 0.004 * OMEGA0
#: Sensor zero 0.2 mm off the equilibrium: the mean offset is measured from the equilibrium.
SENSOR_ZERO_M = 2e-4
#: Noise of 0.1 µm of displacement, and the same at 105 Hz for velocity and acceleration.
NOISE = {"displacement": 1e-7, "velocity": 1e-7 * OMEGA0, "acceleration": 1e-7 * OMEGA0**2}
KEYS = {"displacement": "displacement_m", "velocity": "velocity_m_s",
        "acceleration": "acceleration_m_s2"}  # fmt: skip


def _force(x, v):
    return K1 * x + C * v + K2 * x * x + K3 * x**3


TRUTH = JointModel({"linear_stiffness": K1, "viscous_damping": C, "quadratic_stiffness": K2,
                    "cubic_stiffness": K3})  # fmt: skip


@pytest.fixture(scope="module")
def decay():
    return free_decay(_force, 1.2e-3, 0.0, fs_hz=FS, duration_s=1.0)


def _record(decay, quantity, seed=0, **options):
    rng = np.random.default_rng(seed)
    values = decay[KEYS[quantity]] + rng.normal(0.0, NOISE[quantity], decay["time_s"].size)
    if quantity == "displacement":
        values = values + SENSOR_ZERO_M
    return ColumnRecord(decay["time_s"], values, quantity, f"decay-{quantity}",
                        test="free-decay", **options)  # fmt: skip


@pytest.mark.parametrize("quantity", ["displacement", "velocity", "acceleration"])
def test_decay_backbone_is_the_harmonic_balance_backbone(decay, quantity):
    curve = extract_backbone(_record(decay, quantity))
    truth = harmonic.backbone(TRUTH, curve.amplitude_m, method="multi", harmonics=8)
    assert truth.converged.all()
    # the decay spans the softening: from 100.5 Hz at 0.95 mm to 105 Hz in the noise
    assert curve.amplitude_m.max() > 0.9e-3 and curve.amplitude_m.min() < 1e-4
    assert curve.frequency_hz.min() < 101.0 and curve.frequency_hz.max() > 104.9
    # acceptance of the issue: within 0.3 % of the harmonic-balance truth in frequency
    np.testing.assert_allclose(curve.frequency_hz, truth.frequency_hz, rtol=3e-3)
    # power-balance damping: c⟨ẋ²⟩/(ω³a²), harmonics' share included (4 % of it at the top)
    np.testing.assert_allclose(curve.damping_ratio, truth.damping_ratio, rtol=0.03)
    second = (truth.harmonics_cos_m[:, 2] - 1j * truth.harmonics_sin_m[:, 2]) / curve.amplitude_m
    large = np.abs(second) > 0.01
    np.testing.assert_allclose(np.abs(curve.harmonics[large, 0]), np.abs(second[large]), rtol=0.03)
    if quantity == "displacement":  # the mean about the equilibrium, the sensor's zero taken off
        np.testing.assert_allclose(curve.mean_offset_m, truth.harmonics_cos_m[:, 0],
                                   rtol=0.03, atol=1e-6)  # fmt: skip
    else:  # velocity and acceleration sensors do not observe it
        assert curve.mean_offset_m is None


def test_decay_backbone_agrees_with_the_hilbert_transform(decay):
    curve = extract_backbone(_record(decay, "displacement"))
    amplitude, frequency = hilbert_backbone(decay["time_s"], decay["displacement_m"], (60, 160))
    order = np.argsort(amplitude)
    common = (curve.amplitude_m > amplitude.min()) & (curve.amplitude_m < amplitude.max())
    reference = np.interp(curve.amplitude_m[common], amplitude[order], frequency[order])
    assert common.sum() >= 20
    # The period-averaged Hilbert frequency carries the band-pass's and the transform's end
    # effects (several 1e-4 of the frequency near both ends of the decay); inside, both
    # agree to the 1e-4 the harmonic-balance test asks of the decay fits.
    np.testing.assert_allclose(curve.frequency_hz[common], reference, rtol=1e-3)
    n = reference.size
    middle = slice(n // 4, 3 * n // 4)
    np.testing.assert_allclose(curve.frequency_hz[common][middle], reference[middle], rtol=1e-4)


def test_a_ring_down_after_the_excitation_stops_starts_at_the_switch_off():
    # forced at resonance with a measured base acceleration for 0.5 s, then switched off
    omega = OMEGA0 * np.sqrt(1 - 0.004**2)
    t = np.arange(int(1.2 * FS)) / FS
    on = t < 0.5
    response = np.where(on, 1e-3 * np.sin(omega * t),
                        1e-3 * np.exp(-0.004 * OMEGA0 * (t - 0.5)) * np.sin(omega * t))  # fmt: skip
    base = np.where(on, 2 * 0.004 * OMEGA0**2 * 1e-3 * np.cos(omega * t), 0.0)
    record = ColumnRecord(t, response, "displacement", "switch-off", test="free-decay",
                          excitation=base, excitation_kind="base-acceleration",
                          relative=True)  # fmt: skip
    curve = extract_decay_backbone(record)
    # The first window is centred half a window (3 periods) after the decay's start, which
    # the switch-off's detection (a one-period envelope of the base) puts within a period
    # and a half of 0.5 s: its amplitude is 1 mm decayed over 3 to 4.5 periods.
    f = omega / (2 * np.pi)
    decayed = 1e-3 * np.exp(-0.004 * OMEGA0 * np.array([4.5, 3.0]) / f)
    assert decayed[0] <= curve.amplitude_m[0] <= decayed[1]
    np.testing.assert_allclose(curve.frequency_hz, omega / (2 * np.pi), rtol=1e-4)
    np.testing.assert_allclose(curve.damping_ratio, 0.004, rtol=0.02)


def test_a_steady_response_is_not_a_decay():
    t = np.arange(int(0.8 * FS)) / FS
    steady = ColumnRecord(t, 1e-3 * np.sin(2 * np.pi * 97.0 * t), "velocity", "beam",
                          test="free-decay")  # fmt: skip
    with pytest.raises(ValueError, match=r"does not decay.*at 97 Hz.*--excitation"):
        extract_backbone(steady)


def test_too_few_periods_are_refused(decay):
    short = SimpleNamespace(**vars(_record(decay, "velocity")))
    cut = slice(0, int(0.04 * FS))  # four periods
    record = ColumnRecord(short.time_s[cut], short.response[cut], "velocity", "short",
                          test="free-decay")  # fmt: skip
    with pytest.raises(ValueError, match="too few periods"):
        extract_backbone(record)


def test_a_driven_test_without_its_excitation_is_refused():
    t = np.arange(int(0.5 * FS)) / FS
    with pytest.raises(ValueError, match="needs its excitation measured"):
        ColumnRecord(t, np.sin(2 * np.pi * 97.0 * t), "velocity", "beam")
    with pytest.raises(ValueError, match=r"zero throughout.*--test free-decay"):
        ColumnRecord(t, np.sin(2 * np.pi * 97.0 * t), "velocity", "beam",
                     excitation=np.zeros_like(t), excitation_kind="base-acceleration")  # fmt: skip
