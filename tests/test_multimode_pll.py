"""The PLL simulator with N modes (identification.multimode.pll) against independent answers.

* one mode: the one-mode PLL (:func:`identification.analytical.pll.simulate_pll`,
  :func:`~identification.analytical.pll.pll_backbones`) on the same model;
* two modes coupled through a cubic joint element, far from internal resonance: the
  multimode phase-resonant harmonic-balance backbone (``identification.multimode``);
* two modes near 1:2 with a quadratic coupling: the second mode's participation at
  harmonic 2 from the same harmonic balance.

Tolerances. With one mode the loop runs the same operations on the same numbers
except the order in which the linear terms are summed (``ω² η + 2ζω η̇`` as the
mode against ``k x + c ẋ`` as catalogue terms) and ``ω² = (√k)²``, so the results
differ by round-off only (measured ≤ 4e-15 relative), and every lock decision is
the same. Against the harmonic balance the PLL's holds carry two errors: the lock's
phase error ``δφ`` moves the frequency by about ``ζ δφ`` relative (≤ 5e-5 for
ζ = 0.3 % and the 1° lock tolerance; measured ≤ 1e-6), and the amplitude is measured
once its distance from the steady state is below ``settling_tolerance`` (0.5 %),
still growing, which biases the power-balance damping up by as much (measured
+0.3 %): hence 1e-4 on frequencies and 1 % on damping ratios. The participation of
the other mode is the steady state's to the same settling (measured ≤ 4e-5 relative
at harmonic 2 near 1:2, ≤ 0.2 % at harmonics 1 and 3 far from it).
"""

import numpy as np
import pytest

from identification.analytical.pll import PLLConfig, pll_backbones, simulate_pll
from identification.effects import CATALOGUE
from identification.model import JointModel
from identification.multimode import (
    Coupling,
    HarmonicSettings,
    JointElement,
    ModalModel,
    Mode,
    phase_resonance,
)
from identification.multimode.pll import (
    ModalPLLResult,
    modal_pll_backbones,
    simulate_modal_pll,
)

CUBIC = CATALOGUE["cubic_stiffness"].name
LINEAR = CATALOGUE["linear_stiffness"].name
VISCOUS = CATALOGUE["viscous_damping"].name
JENKINS = next(e.name for e in CATALOGUE.values() if e.hysteretic)
OMEGA0 = 2 * np.pi * 100.0
ZETA = 0.003
#: Base-acceleration levels giving about 0.02–1 mm on the 100 Hz modes below.
LEVELS = np.geomspace(0.05, 3.0, 4)
BALANCE = HarmonicSettings(harmonics=5)


def duffing_microslip() -> JointModel:
    """One mode: softening by microslip (slip from 0.05 mm), then Duffing hardening."""
    k = OMEGA0**2
    k_t = 0.1 * k
    return JointModel(
        {
            LINEAR: 0.9 * k,
            VISCOUS: 2 * ZETA * OMEGA0,
            CUBIC: 3.2e10,
            JENKINS: {"coefficient": 1.0, "k_t": k_t, "F_s": k_t * 5e-5},
        },
        name="duffing_microslip",
    )


def cubic_joint() -> ModalModel:
    """Modes at 100 and 243 Hz (no 1:2 or 1:3), a cubic element on q = η1 + 0.5 η2."""
    return ModalModel(
        modes=(Mode(100.0, ZETA, 1.0), Mode(243.0, 0.005, 0.6)),
        joint_shapes=((1.0, 0.5),),
        elements=(JointElement(CUBIC, 3.2e10),),
    )


#: Coupling potential V = κ η1² η2 (forces 2κ η1η2 on mode 1, κ η1² on mode 2).
KAPPA = 1.6e7


def near_one_to_two() -> ModalModel:
    """Modes at 100 and 210 Hz (5 % from 1:2) with the quadratic coupling of V = κ η1² η2."""
    return ModalModel(
        modes=(Mode(100.0, ZETA, 1.0), Mode(210.0, 0.01, 0.3)),
        joint_shapes=((1.0, 0.0),),
        couplings=(Coupling(1, (1, 1), 2 * KAPPA), Coupling(2, (2, 0), KAPPA)),
    )


def assert_same_backbone(one, many: ModalPLLResult) -> None:
    assert np.array_equal(one.locked, many.locked) and many.locked.all()
    for name in ("amplitude_m", "frequency_hz", "damping_ratio"):
        np.testing.assert_allclose(getattr(many, name), getattr(one, name), rtol=1e-12)
    np.testing.assert_allclose(many.phase_error_deg, one.phase_error_deg, atol=1e-9)


# --------------------------------------------------------------------------
# (a) One mode: the one-mode PLL.


@pytest.mark.parametrize("name", ["pandey2025", "duffing_microslip"])
def test_one_mode_reproduces_the_one_mode_pll(name):
    joint = duffing_microslip() if name == "duffing_microslip" else JointModel.preset(name)
    result = simulate_modal_pll(ModalModel.from_joint_model(joint), LEVELS)
    assert_same_backbone(simulate_pll(joint, LEVELS), result)
    # The fundamental's coefficients give the reported amplitude; the lock puts it at cos θ.
    c1, s1 = result.coefficients[:, 0, 1], result.coefficients[:, 0, 2]
    np.testing.assert_allclose(np.hypot(c1, s1), result.amplitude_m, rtol=1e-12)
    assert np.all(np.abs(s1) < 0.02 * c1)


def test_one_mode_batch_reproduces_the_one_mode_batch():
    joint = duffing_microslip()
    model = ModalModel.from_joint_model(joint)
    cubic = np.array([[1.0e10], [3.2e10]])
    one = pll_backbones(joint, LEVELS, cubic, [CUBIC], progress=False)
    many = modal_pll_backbones(model, LEVELS, cubic, [f"joint1.{CUBIC}"])
    assert many.amplitude_m.shape == (2, LEVELS.size)
    assert_same_backbone(one, many)


# --------------------------------------------------------------------------
# (b) Two modes, cubic joint, far from internal resonance: the harmonic balance.


def test_two_modes_match_the_phase_resonant_balance():
    model = cubic_joint()
    result = simulate_modal_pll(model, LEVELS)
    assert result.locked.all()
    assert result.amplitude_m[0] < 3e-5 and result.amplitude_m[-1] > 1e-3
    reference = phase_resonance(model, result.amplitude_m, mode=1, settings=BALANCE)
    assert reference.converged.all()
    assert reference.frequency_hz[-1] > 1.02 * reference.frequency_hz[0]  # hardening shows
    np.testing.assert_allclose(result.frequency_hz, reference.frequency_hz, rtol=1e-4)
    np.testing.assert_allclose(result.damping_ratio, reference.damping_ratio, rtol=0.01)
    # Mode 2 follows through the joint at harmonics 1 and 3 (driven by the base and the
    # cubic element); its amplitudes are the balance's.
    coefficients = reference.coefficients[..., 1, :7]
    expected = np.hypot(coefficients[..., 1::2], coefficients[..., 2::2])
    measured = result.participation_amplitude_m[:, 1]
    for k in (0, 2):
        np.testing.assert_allclose(measured[:, k], expected[:, k], rtol=0.01)


def test_sensors_record_and_drive():
    """Sensors are Σ φ_sm η_m; recording changes nothing; a driving point with shapes −Γ
    is the base excitation; a sensor lock holds the same backbone to the lock's accuracy."""
    model = cubic_joint()
    sensors = np.array([[1.0, 0.8], [-0.7, 0.4], [0.2, -1.0]])
    levels = LEVELS[[0, -1]]
    plain = simulate_modal_pll(model, levels)
    recorded = simulate_modal_pll(model, levels, sensors=sensors, record=True)
    series = recorded.time_series
    assert_same_backbone(plain, recorded)
    np.testing.assert_allclose(series.sensors, sensors @ series.eta, rtol=1e-12, atol=0)
    start, stop = series.measurements[-1]
    assert 0 < start < stop == series.t.size and np.all(series.level[start:stop] == levels[-1])
    driven = simulate_modal_pll(model, levels, drive=[-1.0, -0.6])
    assert_same_backbone(plain, driven)
    # Sensor 1 sees mode 1 with a negative shape: the loop flips its target by 180°.
    by_sensor = simulate_modal_pll(model, levels, sensors=sensors, lock_sensor=1)
    assert by_sensor.locked.all()
    np.testing.assert_allclose(by_sensor.frequency_hz, plain.frequency_hz, rtol=1e-4)
    np.testing.assert_allclose(by_sensor.damping_ratio, plain.damping_ratio, rtol=0.02)


def test_bad_inputs_raise():
    model = cubic_joint()
    with pytest.raises(ValueError, match="mode must be"):
        simulate_modal_pll(model, LEVELS, mode=3)
    with pytest.raises(ValueError, match="sensors must be"):
        simulate_modal_pll(model, LEVELS, sensors=np.ones((3, 3)))
    with pytest.raises(ValueError, match="lock_sensor"):
        simulate_modal_pll(model, LEVELS, sensors=np.ones((2, 2)), lock_sensor=2)
    with pytest.raises(ValueError, match="does not see mode"):
        simulate_modal_pll(model, LEVELS, sensors=[[0.0, 1.0]], lock_sensor=0)
    with pytest.raises(ValueError, match="not excited"):
        simulate_modal_pll(model, LEVELS, drive=[0.0, 1.0])
    with pytest.raises(ValueError, match="excitation_m_s2"):
        simulate_modal_pll(model, [1.0, -1.0])


# --------------------------------------------------------------------------
# (c) Near 1:2 with a quadratic coupling: mode 2's harmonic 2.


def test_second_harmonic_participation_near_one_to_two():
    model = near_one_to_two()
    result = simulate_modal_pll(model, LEVELS)
    assert result.locked.all()
    reference = phase_resonance(model, result.amplitude_m, mode=1, settings=BALANCE)
    assert reference.converged.all()
    measured = result.participation_amplitude_m[:, 1, 1]
    expected = np.hypot(reference.coefficients[:, 1, 3], reference.coefficients[:, 1, 4])
    # κ a² / 2 over ω2² − 4ω²: it grows with the square of mode 1's amplitude, to
    # about 5 % of it at the top level.
    share = measured / result.amplitude_m
    assert np.all(np.diff(share) > 0) and share[0] < 2e-3 and share[-1] > 0.04
    np.testing.assert_allclose(measured, expected, rtol=1e-3)
    np.testing.assert_allclose(result.frequency_hz, reference.frequency_hz, rtol=1e-4)
    np.testing.assert_allclose(result.damping_ratio, reference.damping_ratio, rtol=0.01)
    # Its phase against twice the fundamental's: the balance's.
    phase = np.degrees(
        np.arctan2(-reference.coefficients[:, 1, 4], reference.coefficients[:, 1, 3])
    )
    np.testing.assert_allclose(result.participation_phase_deg[:, 1, 1], phase, atol=0.5)


@pytest.mark.slow
def test_two_modes_match_the_balance_over_41_levels():
    model = cubic_joint()
    result = simulate_modal_pll(model, np.geomspace(0.05, 3.0, 41), config=PLLConfig(n_periods=70))
    assert result.locked.all()
    reference = phase_resonance(model, result.amplitude_m, mode=1, settings=BALANCE)
    np.testing.assert_allclose(result.frequency_hz, reference.frequency_hz, rtol=1e-4)
    np.testing.assert_allclose(result.damping_ratio, reference.damping_ratio, rtol=0.01)
