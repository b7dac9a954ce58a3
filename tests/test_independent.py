"""The independent simulator (:mod:`independent`) against analytical solutions, and the library's
harmonic balance against it.

Expectations here are closed forms (linear oscillators, the Duffing backbone's ¾ k3 a² law and
its third harmonic, dry friction's 4F/(π a ω), Masing's loop area, modal superposition, energy
conservation), never the simulator's own output; the last tests check the library, not the
simulator. Its import rule (numpy, scipy and the backbone record types only) is checked from
the sources.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from independent.campaigns import HoldNoise, phase_resonance_campaign
from independent.forces import (
    Clearance,
    CoulombFriction,
    CubicStiffness,
    Iwan,
    JointSpec,
    Microslip,
    PowerLawDamping,
    PreloadedContact,
    QuadraticDamping,
    QuadraticStiffness,
)
from independent.phase_resonance import BalanceSettings, phase_resonance_backbone

ROOT = Path(__file__).parents[1]
F0_HZ = 101.0
W0 = 2 * np.pi * F0_HZ
AMPLITUDES_M = np.geomspace(5e-5, 2e-3, 10)

#: What the independent package may import: the standard library, numpy, scipy, itself and
#: the library's backbone record types, nothing else of the library.
ALLOWED_LIBRARY_MODULES = {"identification.measurements.backbone"}


def foreign_imports(path: Path) -> list[str]:
    """Modules ``path`` imports that the independent package may not."""
    allowed_roots = {"numpy", "scipy", "independent", "__future__", "dataclasses", "typing",
                     "collections", "math", "functools", "itertools"}  # fmt: skip
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names = [node.module]
        else:
            continue
        for name in names:
            root = name.split(".")[0]
            if name in ALLOWED_LIBRARY_MODULES or root in allowed_roots:
                continue
            found.append(name)
    return found


def test_the_independent_package_imports_no_library_code():
    offenders = {
        str(path.relative_to(ROOT)): bad
        for path in (ROOT / "independent").rglob("*.py")
        if (bad := foreign_imports(path))
    }
    assert offenders == {}


def test_the_import_check_catches_a_kernel_import(tmp_path):
    module = tmp_path / "m.py"
    module.write_text(
        "import numpy as np\nfrom identification.measurements.backbone import Backbone\n"
        "def f():\n    from identification.effects.microslip import jenkins_force\n"
        "import numba\n"
    )
    assert sorted(foreign_imports(module)) == ["identification.effects.microslip", "numba"]


# ---------------------------------------------------------------------------
# Phase resonance against closed forms


def test_linear_viscous_joint_resonates_at_omega0_with_damping_zeta():
    backbone = phase_resonance_backbone(JointSpec(F0_HZ, 0.004), AMPLITUDES_M)
    assert backbone.converged.all()
    np.testing.assert_allclose(backbone.frequency_hz, F0_HZ, rtol=1e-12)
    np.testing.assert_allclose(backbone.damping_ratio, 0.004, rtol=1e-9)
    np.testing.assert_allclose(backbone.base_acceleration_m_s2, 2 * 0.004 * W0**2 * AMPLITUDES_M,
                               rtol=1e-9)  # fmt: skip
    assert np.abs(backbone.harmonics).max() < 1e-12


def test_cubic_stiffness_follows_the_duffing_backbone_at_small_amplitude():
    """ω² = ω0² + ¾ k3 a², the third harmonic of the single-term balance and D = ζ ω0/ω, while
    the shift is small (the next terms are of relative order the shift itself)."""
    k3, zeta = 1.4e10, 0.003
    a = np.geomspace(2e-5, 2.5e-4, 5)
    backbone = phase_resonance_backbone(JointSpec(F0_HZ, zeta, (CubicStiffness(k3),)), a)
    omega = 2 * np.pi * backbone.frequency_hz
    shift = 0.75 * k3 * a**2
    assert shift.max() / W0**2 < 2e-3
    np.testing.assert_allclose(omega**2 - W0**2, shift, rtol=3e-3)
    # The third harmonic of the single-term balance, with its damped phase:
    # (ω0² − 9ω² + 6iζω0ω)(C3 − iS3) = −k3 a³/4.
    third = -k3 * a**2 / 4 / (W0**2 - 9 * omega**2 + 6j * zeta * W0 * omega)
    np.testing.assert_allclose(backbone.harmonics[:, 1], third, rtol=5e-3)
    np.testing.assert_allclose(backbone.damping_ratio, zeta * W0 / omega, rtol=1e-7)
    assert np.abs(backbone.harmonics[:, 0]).max() < 1e-12  # an odd force: no 2nd harmonic


def test_coulomb_friction_adds_the_equivalent_damping_of_dry_friction():
    """The fundamental's power balance gives D = ζ + 4F/(π a ω)/(2ω) for weak friction
    (single-harmonic limit: the friction's harmonics are small beside the spring)."""
    friction, zeta = 0.2, 0.003
    a = AMPLITUDES_M[::3]
    backbone = phase_resonance_backbone(
        JointSpec(F0_HZ, zeta, (CoulombFriction(friction, v_reg=1e-7),)),
        a,
        BalanceSettings(samples_per_period=1024),
    )
    omega = 2 * np.pi * backbone.frequency_hz
    expected = zeta * W0 / omega + 4 * friction / (np.pi * a * omega) / (2 * omega)
    np.testing.assert_allclose(backbone.damping_ratio, expected, rtol=2e-4)
    # A sampled jump moves the frequency by O(1/N): 2e-5 of it at 1024 samples.
    np.testing.assert_allclose(backbone.frequency_hz, F0_HZ, rtol=5e-5)


def test_a_jenkins_loop_dissipates_masings_energy():
    """Over a cycle of amplitude a > F_s/k_t a Jenkins element dissipates 4 F_s (a − F_s/k_t)."""
    k_t, f_s = 4e4, 4.0
    element = Microslip(1.0, k_t=k_t, F_s=f_s)
    a = np.array([2e-4, 5e-4, 1e-3])[:, None]
    theta = 2 * np.pi * np.arange(4096) / 4096
    x = a * np.cos(theta)
    force = element.periodic(x)
    area = np.sum(force * np.gradient(np.cos(theta)) * a, axis=-1)  # ∮ f dx, x = a cos θ
    np.testing.assert_allclose(area, 4 * f_s * (a[:, 0] - f_s / k_t), rtol=1e-5)
    stuck = element.periodic(0.5 * f_s / k_t * np.cos(theta))
    np.testing.assert_allclose(stuck, 0.5 * f_s * np.cos(theta), rtol=0, atol=1e-12 * f_s)


def test_microslip_phase_resonance_damping_is_the_loop_energy():
    """D = E / (2π ω² a²): the energy the base puts in per cycle is what the slider dissipates,
    Masing's loop on the fundamental when the slider's harmonics are small."""
    k_t, f_s, zeta = 0.05 * W0**2, 0.05 * W0**2 * 2e-4, 0.003
    a = AMPLITUDES_M[::3]
    backbone = phase_resonance_backbone(
        JointSpec(F0_HZ, zeta, (Microslip(1.0, k_t=k_t, F_s=f_s),)),
        a,
        BalanceSettings(samples_per_period=1024),
    )
    omega = 2 * np.pi * backbone.frequency_hz
    slip_amplitude_m = f_s / k_t
    slipping = slip_amplitude_m < a
    energy = np.where(slipping, 4 * f_s * (a - slip_amplitude_m), 0.0)
    expected = zeta * W0 / omega + energy / (2 * np.pi * omega**2 * a**2)
    np.testing.assert_allclose(backbone.damping_ratio, expected, rtol=1e-2)
    # Stuck: the element is a spring k_t, so ω² = ω0² + k_t.
    np.testing.assert_allclose(omega[~slipping] ** 2, W0**2 + k_t, rtol=1e-9)


def test_out_of_catalogue_joints_in_their_closed_form_regimes():
    """Below its gap a clearance is not there; a preloaded contact that stays closed is a
    spring; an Iwan joint below its first slip is its stuck stiffness; power-law damping of
    exponent 1 is viscous and of exponent 2 dissipates like c ẋ|ẋ| (8 c a ω / 3π)."""
    k = 0.15 * W0**2
    small = np.array([1e-5, 1e-4, 2.9e-4])
    clearance = phase_resonance_backbone(JointSpec(F0_HZ, 0.003, (Clearance(3e-4, k),)), small)
    np.testing.assert_allclose(clearance.frequency_hz, F0_HZ, rtol=1e-12)
    contact = PreloadedContact(k, preload=k * 3e-4)
    closed = phase_resonance_backbone(JointSpec(F0_HZ, 0.003, (contact,)), small)
    np.testing.assert_allclose((2 * np.pi * closed.frequency_hz) ** 2, W0**2 + k, rtol=1e-12)
    iwan = Iwan(stiffness=k, macroslip_force=k * 1e-3, chi=-0.5, n_sliders=8)
    first_slip = np.min(iwan.sliders()[1] / iwan.sliders()[0])
    stuck = phase_resonance_backbone(JointSpec(F0_HZ, 0.003, (iwan,)), [0.9 * first_slip])
    np.testing.assert_allclose((2 * np.pi * stuck.frequency_hz) ** 2, W0**2 + k, rtol=1e-12)
    viscous = phase_resonance_backbone(JointSpec(F0_HZ, 0.0, (PowerLawDamping(3.0, 1.0),)), small)
    np.testing.assert_allclose(viscous.damping_ratio, 3.0 / (2 * W0), rtol=1e-9)
    square = phase_resonance_backbone(JointSpec(F0_HZ, 0.0, (PowerLawDamping(5.0, 2.0),)), small)
    omega = 2 * np.pi * square.frequency_hz
    np.testing.assert_allclose(
        square.damping_ratio, 8 * 5.0 * small * omega / (3 * np.pi) / (2 * omega), rtol=1e-3
    )


def test_an_iwan_joint_keeps_its_stuck_stiffness_and_macroslip_force():
    iwan = Iwan(stiffness=4e4, macroslip_force=4.0, chi=-0.5, n_sliders=12)
    k, f_slip = iwan.sliders()
    assert k.sum() == pytest.approx(4e4) and f_slip.sum() == pytest.approx(4.0)
    slip = f_slip / k
    assert np.all(np.diff(slip) > 0)  # χ < 0: more sliders at small slip than at large
    assert slip[1] - slip[0] < slip[-1] - slip[-2]


def test_the_periodic_state_is_a_periodic_solution_of_the_equation_of_motion():
    """Started at the balance's state, DOP853 on the equation of motion comes back to it after
    a period (the balance truncates at H harmonics: that is its error)."""
    from scipy.integrate import solve_ivp

    k3, zeta, a = 1.4e10, 0.003, 1.5e-3
    joint = JointSpec(F0_HZ, zeta, (CubicStiffness(k3),))
    point = phase_resonance_backbone(joint, [a])
    omega = 2 * np.pi * point.frequency_hz[0]
    big_a = point.base_acceleration_m_s2[0]
    h = np.arange(2, point.harmonics.shape[-1] + 2)
    c, s = point.harmonics[0].real * a, -point.harmonics[0].imag * a
    x0 = point.mean_offset_m[0] + a + c.sum()
    v0 = omega * np.sum(h * s)

    def rhs(t, y):
        return [y[1], -big_a * np.sin(omega * t) - joint.memoryless_force(y[0], y[1])]

    period = 2 * np.pi / omega
    end = solve_ivp(rhs, (0, period), [x0, v0], method="DOP853", rtol=1e-12, atol=1e-15).y[:, -1]
    assert abs(end[0] - x0) < 1e-8 * a and abs(end[1] - v0) < 1e-8 * a * omega


# ---------------------------------------------------------------------------
# Campaigns


def test_a_noise_free_campaign_is_the_backbone_of_each_drawn_assembly():
    joint = JointSpec(F0_HZ, 0.003, (CubicStiffness(1.4e10),))
    campaign = phase_resonance_campaign(joint, 3, seed=5, noise=HoldNoise(0.0, 0.0, 0.0))
    assert len(campaign) == 3
    for curve in campaign:
        assert curve.harmonics.shape == (10, 2) and np.all(np.diff(curve.amplitude_m) > 0)
        # Hardening from the linear frequency near F0 (stiffness scatter 0.5 %).
        assert abs(curve.frequency_hz[0] / F0_HZ - 1) < 0.02
        assert np.all(np.diff(curve.frequency_hz) > 0)
    noisy = phase_resonance_campaign(joint, 3, seed=5)
    spread = np.concatenate(
        [n.frequency_hz - c.frequency_hz for n, c in zip(noisy, campaign, strict=True)]
    )
    assert 0.001 < np.std(spread) < 0.02  # 3 mHz, twice that at the smallest level


# ---------------------------------------------------------------------------
# The library's harmonic balance against the independent one (this checks the library)


#: Library and independent balance agree within what the library's AFT promises for each kind
#: of force: polynomials are balanced exactly up to its truncation at 5 harmonics, whose
#: next harmonic is below 1e-7 of the fundamental here (rel. frequency, rel. damping, harmonics
#: as fractions of the fundamental); a kink (ẋ|ẋ|) aliases like 1/N³ and a hysteresis corner
#: like 1/N², about 1e-4 of the slip damping at its default samples (its docstring).
LIBRARY_CASES = {
    "cubic_stiffness": (1.4e10, CubicStiffness(1.4e10), (1e-9, 1e-9, 1e-9)),
    "quadratic_stiffness": (-5e7, QuadraticStiffness(-5e7), (1e-9, 1e-9, 1e-9)),
    "quadratic_damping": (5.0, QuadraticDamping(5.0), (1e-7, 1e-6, 1e-7)),
    "microslip": (
        {"coefficient": 1.0, "k_t": 0.1 * W0**2, "F_s": 0.1 * W0**2 * 2e-4},
        Microslip(1.0, k_t=0.1 * W0**2, F_s=0.1 * W0**2 * 2e-4),
        (1e-5, 2e-4, 1e-5),
    ),
}


@pytest.mark.parametrize("effect", sorted(LIBRARY_CASES))
def test_the_library_harmonic_balance_matches_the_independent_one(effect):
    from identification.analytical.harmonic import backbone
    from identification.model import JointModel

    coefficient, force, (f_tol, d_tol, h_tol) = LIBRARY_CASES[effect]
    model = JointModel(
        {"linear_stiffness": W0**2, "viscous_damping": 2 * 0.003 * W0, effect: coefficient}
    )
    library = backbone(model, AMPLITUDES_M, method="multi", harmonics=5)
    reference = phase_resonance_backbone(
        JointSpec(F0_HZ, 0.003, (force,)), AMPLITUDES_M, BalanceSettings(samples_per_period=1024)
    )
    assert library.converged.all() and reference.converged.all()
    np.testing.assert_allclose(library.frequency_hz, reference.frequency_hz, rtol=f_tol)
    np.testing.assert_allclose(library.damping_ratio, reference.damping_ratio, rtol=d_tol)
    harmonics = (library.harmonics_cos_m[:, 2:4] - 1j * library.harmonics_sin_m[:, 2:4]) / (
        AMPLITUDES_M[:, None]
    )
    assert np.abs(harmonics - reference.harmonics[:, :2]).max() < h_tol
    np.testing.assert_allclose(
        library.harmonics_cos_m[:, 0], reference.mean_offset_m, atol=h_tol * AMPLITUDES_M.max()
    )
