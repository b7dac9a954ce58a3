"""The two-mode virtual TRC (identification.rig.modal_rig) and the acceptance of #26 on it.

* the panel's shapes are a plate's: bending of one sign, torsion antisymmetric across the
  centre line; ``--ratio`` sets the torsion frequency (checked on the linearised stiffness);
* the ground truth against the independent package (scipy's DOP853 on forces written
  without the library's kernels): the linear modes' frequency and damping from a
  small-amplitude ring-down, and one nonlinear amplitude of each mode's nonlinear mode;
* acceptance (#26): from a two-mode PLL campaign without drift, every other lab artefact on,
  ``pm-joint backbones --modes 2`` gives the locked mode's backbone within 0.05 % frequency
  and 2 % damping of the truth's phase-resonance backbone, and the other mode's
  participation (its largest harmonic there) within 5 % — one level fast, the whole
  campaign of each mode slow.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.interpolate import PchipInterpolator

from identification.rig import MODAL_RIG_PRESETS, ModalRig, plate_shapes, read_modal_ground_truth
from identification.rig.conditions import Drift
from identification.rig.modal_rig import lock_weights, reference_points
from independent.decays import (
    ModalSystem,
    PotentialTerm,
    modal_backbones,
    modal_forced_steady_state,
    modal_free_decay,
)
from independent.forces import CubicStiffness, Microslip
from pm_joint.cli import main as cli

#: #26's acceptance: frequency, damping, the other mode's participation (relative).
FREQUENCY_TOLERANCE, DAMPING_TOLERANCE, PARTICIPATION_TOLERANCE = 5e-4, 0.02, 0.05


# --------------------------------------------------------------------------- the panel


def test_plate_shapes_bend_and_twist_like_a_plate():
    shapes = plate_shapes()
    bending, torsion = shapes[:, 0], shapes[:, 1]
    assert np.all(bending > 0)  # one sign over the plate
    grid = torsion.reshape(5, 3)  # along the length × across the width
    np.testing.assert_allclose(grid[:, 1], 0.0, atol=1e-15)  # zero on the centre line
    np.testing.assert_allclose(grid[:, 0], -grid[:, 2])  # antisymmetric across it
    assert np.all(grid[:, 0] > 0)
    assert (reference_points(shapes) + 1).tolist() == [8, 7]
    assert bending[7] == 1.0 and torsion[6] == 1.0
    # The torsion lock (half the difference across the centre line) cancels bending and base.
    weights = lock_weights(shapes, 2)
    assert weights.sum() == 0.0
    np.testing.assert_allclose(weights @ shapes, [0.0, 1.0], atol=1e-15)
    np.testing.assert_array_equal(lock_weights(shapes, 1), np.eye(15)[7])


@pytest.mark.parametrize("ratio", [1.9, 1.94, 2.05])
def test_ratio_sets_the_torsion_frequency_of_the_linearised_panel(ratio):
    model = MODAL_RIG_PRESETS["two-mode"].model(ratio)
    omega = 2 * np.pi * np.array([m.frequency_hz for m in model.modes])
    phi = np.asarray(model.joint_shapes[0])
    k_t = next(e.shape["k_t"] for e in model.elements if e.shape)  # the stuck Jenkins spring
    stiffness = np.diag(omega**2) + k_t * np.outer(phi, phi)
    f = np.sqrt(np.linalg.eigvalsh(stiffness)) / (2 * np.pi)
    # 101 Hz bending; torsion at ratio × 101 Hz up to the stuck joint's coupling of the modes
    assert f[0] == pytest.approx(101.0, rel=2e-4)
    assert f[1] / f[0] == pytest.approx(ratio, rel=2e-4)


# ------------------------------------------------------------ truth against independent


def _independent_system(model) -> ModalSystem:
    """The truth's equations written for :mod:`independent` (its forces, its potential)."""
    by_effect = {e.effect: e for e in model.elements}
    slip, cubic = by_effect["microslip"], by_effect["cubic_stiffness"]
    kappa = next(c.coefficient for c in model.couplings if c.powers == (2, 0))
    # The 2κη₁η₂ and κη₁² forces are those of the potential κ η₁² η₂.
    assert {(c.mode, c.powers, c.coefficient) for c in model.couplings} == {
        (1, (1, 1), 2 * kappa),
        (2, (2, 0), kappa),
    }
    return ModalSystem(
        frequencies_hz=tuple(m.frequency_hz for m in model.modes),
        damping_ratios=tuple(m.damping_ratio for m in model.modes),
        joint_shape=model.joint_shapes[0],
        joint_terms=(
            Microslip(slip.coefficient, k_t=slip.shape["k_t"], F_s=slip.shape["F_s"]),
            CubicStiffness(cubic.coefficient),
        ),
        couplings=(PotentialTerm(kappa, (2, 1)),),
    )


def _decay_backbones(model, amplitude_m: float, duration_s: float, point: int = 9):
    """Each mode's backbone of an independent ring-down after the rig's hammer hit at ``point``."""
    rig = ModalRig(model, test="free-decay", decay_amplitude_m=amplitude_m, decay_point=point)
    _, velocity = rig._initial_state(model)
    decay = modal_free_decay(_independent_system(model), np.zeros(2), velocity,
                             duration_s=duration_s)  # fmt: skip
    f = [m.frequency_hz for m in model.modes]
    bands = [(0.8 * f[0], 1.2 * f[0]), (0.85 * f[1], 1.15 * f[1])]
    return rig, modal_backbones(decay, bands)


def test_linear_modes_of_the_truth_match_an_independent_ring_down():
    model = MODAL_RIG_PRESETS["two-mode"].model(None)
    rig, measured = _decay_backbones(model, 2e-6, 0.6)  # the joint stuck: linear
    for decay, truth in zip(measured, rig.truth_backbones(model), strict=True):
        assert truth.problem == "nonlinear_modes"
        a = np.median(decay.amplitude)
        frequency = np.interp(a, truth.amplitude_mm / 1e3, truth.frequency_hz)
        damping = np.interp(a, truth.amplitude_mm / 1e3, truth.damping_ratio)
        assert np.median(decay.frequency_hz) == pytest.approx(frequency, rel=1e-4)
        assert np.median(decay.damping_ratio) == pytest.approx(damping, rel=0.02)


def test_rig_decay_matches_an_independent_ring_down_at_a_nonlinear_amplitude():
    """Hit at point 9 to 1.2 mm of bending and 0.6 mm of torsion: the joint slips by both."""
    model = MODAL_RIG_PRESETS["two-mode"].model(None)
    rig = ModalRig(model, test="free-decay", decay_amplitude_m=1.2e-3, decay_s=0.2,
                   noise_m_s=1e-12)  # fmt: skip
    eta, _ = rig._decay(model)
    head = rig._decay_head()
    _, velocity = rig._initial_state(model)
    independent = modal_free_decay(_independent_system(model), np.zeros(2), velocity,
                                   duration_s=0.2)  # fmt: skip
    mine = eta[:, head:]
    scale = np.max(np.abs(independent.modal_displacement), axis=1)
    error = np.max(np.abs(mine - independent.modal_displacement), axis=1) / scale
    assert np.all(error < 1e-3), error


@pytest.mark.slow
def test_phase_resonance_of_the_truth_matches_an_independent_steady_state():
    """Bending held at 0.6 mm by the truth's base acceleration at the truth's frequency: the
    independent steady state has that amplitude, lags the base by 90° and carries torsion's
    2ω participation as the truth says."""
    model = MODAL_RIG_PRESETS["two-mode"].model(None)
    truth = ModalRig.for_amplitudes(model, [6e-4]).truth_backbones(model)[0]
    i = int(np.argmin(np.abs(truth.amplitude_mm - 0.6)))
    f, level = truth.frequency_hz[i], truth.base_acceleration_m_s2[i]
    omega = 2 * np.pi * f
    steady = modal_forced_steady_state(
        _independent_system(model), lambda t: level * np.sin(omega * t), 1 / f, (1.0, 1.0),
        settle_periods=150, record_periods=10, rtol=1e-8,
    )  # fmt: skip
    t = steady.time_s
    basis = np.column_stack([np.ones_like(t)] + [g(k * omega * t) for k in (1, 2, 3)
                                                 for g in (np.cos, np.sin)])  # fmt: skip
    coefficients = np.linalg.lstsq(basis, steady.modal_displacement.T, rcond=None)[0]
    bending, torsion = coefficients[:, 0], coefficients[:, 1]
    a = np.hypot(bending[1], bending[2])
    assert 1e3 * a == pytest.approx(truth.amplitude_mm[i], rel=2e-3)
    # η₁ = a cos θ against the base A sin θ: the sine part is the phase error (0.3° here is
    # 0.004 % of frequency at this damping)
    assert abs(np.degrees(np.arctan2(bending[2], bending[1]))) < 0.3
    participation = 1e3 * np.hypot(torsion[3], torsion[4])
    assert participation == pytest.approx(truth.participation_mm[i, 1, 1], rel=0.01)


# ---------------------------------------------------------------------------- the CLI


def test_cli_writes_a_two_mode_free_decay_with_its_truth(tmp_path, capsys):
    out = tmp_path / "decay"
    assert cli(["rig", "--preset", "two-mode", "--out", str(out), "--test", "free-decay",
                "--assemblies", "1", "--ratio", "1.9"]) == 0  # fmt: skip
    assert "free decays" in capsys.readouterr().out
    data = np.loadtxt(out / "Config1_PRT_Assemb1")
    assert data.shape[1] == 20
    modes = np.loadtxt(out / "Config1_linear_complex_modes", dtype=str)
    assert modes.shape == (16, 2)
    truth = read_modal_ground_truth(out)["Config1_PRT_Assemb1"]
    assert [b.mode for b in truth.backbones] == [1, 2]
    assert all(b.problem == "nonlinear_modes" for b in truth.backbones)
    f = np.array([complex(z).real for z in modes[-1]])  # the modes file's frequencies
    assert f[1] / f[0] == pytest.approx(1.9, rel=1e-3)
    # Both modes ring in the record: the torsion points (7 and 9) move against each other.
    torsion = data[:, 7] - data[:, 9]
    assert np.std(torsion) > 10 * truth.noise_m_s


def test_cli_refuses_modal_options_on_a_one_mode_preset(tmp_path, capsys):
    assert cli(["rig", "trc-like", "--out", str(tmp_path / "x"), "--ratio", "2"]) == 2
    assert "--ratio" in capsys.readouterr().err


# ---------------------------------------------------------------------------- acceptance


def _other_participation(truth, other: int) -> tuple[int, np.ndarray]:
    """The harmonic (from 1) where the other mode participates most, and its amplitudes (mm)."""
    participation = truth.participation_mm[:, other - 1, :]
    harmonic = int(np.argmax(participation[-1])) + 1
    return harmonic, participation[:, harmonic - 1]


def _acceptance(folder: Path, mode: int) -> None:
    table = folder.with_suffix(".csv")
    assert cli(["backbones", str(folder), "--modes", "2", "--out", str(table)]) == 0
    rows = pd.read_csv(table)
    truths = read_modal_ground_truth(folder)
    other = 3 - mode
    for name, truth in truths.items():
        (curve,) = [b for b in truth.backbones if b.mode == mode]
        mine = rows[(rows["mode"] == mode) & rows["curve"].astype(str).str.endswith(name)]
        assert len(mine) > 0
        log_a = np.log(curve.amplitude_mm)
        at = np.log(mine["amplitude_mm"].to_numpy())
        assert np.all((at > log_a[0]) & (at < log_a[-1])), "outside the truth's range"
        frequency = PchipInterpolator(log_a, curve.frequency_hz)(at)
        damping = PchipInterpolator(log_a, curve.damping_ratio)(at)
        harmonic, participation = _other_participation(curve, other)
        expected = PchipInterpolator(log_a, participation)(at)
        measured = mine[f"mode{other}_h{harmonic}_amplitude_mm"].to_numpy()
        np.testing.assert_allclose(mine["frequency_hz"], frequency, rtol=FREQUENCY_TOLERANCE)
        np.testing.assert_allclose(mine["damping_ratio"], damping, rtol=DAMPING_TOLERANCE)
        np.testing.assert_allclose(measured, expected, rtol=PARTICIPATION_TOLERANCE)


def _campaign(folder: Path, mode: int, amplitudes_mm, hold_s: float) -> Path:
    """A two-mode PLL campaign of one assembly, every lab artefact but drift, levels stepped up."""
    preset = MODAL_RIG_PRESETS["two-mode"]
    lab = {**preset.lab, "drift": Drift(), "schedule": "up"}
    rig = ModalRig.for_amplitudes(preset.model(None), 1e-3 * np.asarray(amplitudes_mm),
                                  mode=mode, hold_s=hold_s, variability=preset.variability,
                                  **lab)  # fmt: skip
    rig.write_campaign(folder, assemblies=1, seed=11)
    return folder


def test_one_hold_of_a_two_mode_campaign_reads_back_as_the_truth(tmp_path):
    """Bending at 0.8 mm, where torsion carries 8 % of its amplitude at 2ω."""
    _acceptance(_campaign(tmp_path / "one", 1, [0.8], 3.0), 1)


@pytest.mark.slow
@pytest.mark.parametrize(("mode", "amplitudes_mm"), [(1, (0.05, 2.0)), (2, (0.02, 0.5))])
def test_two_mode_campaign_backbones_match_the_truth(tmp_path, mode, amplitudes_mm):
    amplitudes = np.geomspace(*amplitudes_mm, 6)
    _acceptance(_campaign(tmp_path / f"mode{mode}", mode, amplitudes, 3.0), mode)
