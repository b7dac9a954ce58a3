"""Multi-point records read mode by mode: the modal filter, phase-aligned shapes, estimated
shapes, per-mode PLL backbones (``pm-joint backbones --modes N``) and the second-mode warning.

Expectations are analytical (superpositions of known modes, known complex rotations) or the
linear modal parameters put into the N-mode PLL simulator (:mod:`identification.multimode`,
which shares no code with the hold fits): at phase resonance of a linear mode the PLL holds
its undamped frequency, and the power balance gives its damping ratio; another linear mode
answers the hold at the hold's frequency with its receptance.
"""

from __future__ import annotations

import io
import json
import math
import os
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from identification.analytical.pll import PLLConfig
from identification.measurements.columns import ColumnRecord, write_columns
from identification.measurements.modal_backbones import mode_backbones, sidecar_path
from identification.measurements.modal_filter import (
    SECOND_MODE_SHARE,
    ModalFilter,
    estimate_shapes,
    mac,
    real_shapes,
    second_mode_warning,
)
from identification.measurements.records import Modes, Record, read_record, write_record
from identification.measurements.steps import StepSchedule
from identification.multimode import ModalModel, Mode, simulate_modal_pll
from pm_joint.cli import main

ROOT = Path(__file__).resolve().parents[1]
#: Stored reference tables (tests/data/README.md says where each came from).
DATA = ROOT / "tests" / "data"

# Two plate modes at the 5 × 3 grid of the TRC layout: bending (symmetric across the width)
# and torsion (antisymmetric), numbered row by row.
_XI = np.arange(1, 6) / 6
_ETA = np.arange(1, 4) / 4
BENDING = np.outer(np.sin(np.pi * _XI), 1 - 0.1 * (2 * _ETA - 1) ** 2).ravel()
BENDING /= BENDING.max()
TORSION = np.outer(np.sin(2 * np.pi * _XI) + 0.3 * np.sin(np.pi * _XI), 2 * _ETA - 1).ravel()
TORSION /= np.abs(TORSION).max()
SHAPES = np.column_stack([BENDING, TORSION])
SENSORS = tuple(f"panel{p:02d}_m_s" for p in range(1, 16))

FS = 10_000.0
HOLD_S, RAMP_S = 2.0, 0.1
LEVELS = (0.5, 1.0, 2.0)  # base acceleration (m/s²): small amplitudes of a linear model


# --------------------------------------------------------------------------------------
# The modal filter on analytical superpositions


def _superposition(n: int = 20_000, seed: int = 0):
    """Two modes at 15 points: a sine at 105 Hz and a decaying one at 198 Hz (η, y, t)."""
    t = np.arange(n) / FS
    eta = np.column_stack(
        [1e-3 * np.sin(2 * np.pi * 105 * t + 0.3),
         4e-4 * np.exp(-8 * t) * np.cos(2 * np.pi * 198 * t - 1.1)]
    )  # fmt: skip
    return t, eta, eta @ SHAPES.T


def test_modal_filter_recovers_two_known_modes_exactly():
    _, eta, y = _superposition()
    modal_filter = ModalFilter(SHAPES, [105.0, 198.0], SENSORS)
    np.testing.assert_allclose(modal_filter.coordinates(y), eta, rtol=0, atol=1e-15)
    assert modal_filter.reconstruction_error(y).max() < 1e-12
    # each mode's contribution at the sensor where its shape is largest
    reference = modal_filter.reference_sensor
    assert SENSORS[reference[0]] == "panel08_m_s"  # the centre, where bending is 1
    np.testing.assert_allclose(
        modal_filter.scaled_coordinates(y), eta * SHAPES[reference, [0, 1]], atol=1e-15
    )


def test_reconstruction_error_with_noise_is_the_noise_the_modes_cannot_explain():
    _, _, y = _superposition()
    sigma = 2e-5
    noisy = y + np.random.default_rng(1).normal(0.0, sigma, y.shape)
    error = ModalFilter(SHAPES, [105.0, 198.0], SENSORS).reconstruction_error(noisy)
    # Noise left after projecting out the two shapes: σ² (1 − P_ss), P = Φ Φ⁺.
    projector = SHAPES @ np.linalg.pinv(SHAPES)
    expected = sigma * np.sqrt(1 - np.diag(projector)) / np.sqrt(np.mean(y**2, 0) + sigma**2)
    np.testing.assert_allclose(error, expected, rtol=0.03)


def test_modal_filter_refuses_shapes_the_sensors_cannot_tell_apart():
    with pytest.raises(ValueError, match="at least one sensor per mode"):
        ModalFilter(SHAPES[:1], [105.0, 198.0], SENSORS[:1])
    with pytest.raises(ValueError, match="cannot tell the 2 modes apart"):
        ModalFilter(np.column_stack([BENDING, 2 * BENDING]), [105.0, 198.0], SENSORS)


def test_phase_alignment_undoes_a_known_complex_rotation():
    angles = np.radians([35.0, -120.0])
    aligned = real_shapes(SHAPES * np.exp(1j * angles))
    # the largest entry of each shape positive: bending's is +1, torsion's first largest is
    sign = np.sign(SHAPES[np.argmax(np.abs(SHAPES), axis=0), [0, 1]])
    np.testing.assert_allclose(aligned.shapes, SHAPES * sign, atol=1e-14)
    assert aligned.error.max() < 1e-14
    turned = np.exp(1j * np.radians(aligned.rotation_deg))
    np.testing.assert_allclose(turned * sign, np.exp(1j * angles), atol=1e-12)


def test_phase_alignment_reports_the_part_a_real_shape_leaves_out():
    # A shape with an imaginary part orthogonal to its real part: Σφ² is real, no turn, and
    # the part left out is ε‖ψ‖/‖φ‖.
    psi = TORSION - BENDING * (TORSION @ BENDING) / (BENDING @ BENDING)
    eps = 0.05
    aligned = real_shapes(BENDING + 1j * eps * psi)
    expected = (
        eps * np.linalg.norm(psi) / np.hypot(np.linalg.norm(BENDING), eps * np.linalg.norm(psi))
    )
    assert aligned.error[0] == pytest.approx(expected, rel=1e-12)
    np.testing.assert_allclose(aligned.shapes[:, 0], BENDING, atol=1e-14)


def test_shapes_estimated_from_a_two_mode_decay():
    t = np.arange(40_000) / FS
    eta = np.column_stack(
        [1e-3 * np.exp(-3 * t) * np.sin(2 * np.pi * 105 * t),
         5e-4 * np.exp(-4 * t) * np.sin(2 * np.pi * 198 * t + 0.7)]
    )  # fmt: skip
    y = eta @ SHAPES.T + np.random.default_rng(2).normal(0, 1e-6, (t.size, 15))
    estimated = estimate_shapes(t, y, 2, SENSORS)
    np.testing.assert_allclose(estimated.frequencies_hz, [105.0, 198.0], atol=0.3)
    for m in range(2):
        assert mac(estimated.shapes[:, m], SHAPES[:, m]) > 0.9999
    assert "estimated" in estimated.source
    with pytest.raises(ValueError, match="found 2 distinct mode shape"):
        estimate_shapes(t, y, 3, SENSORS)


def test_second_mode_warning_wording():
    line = second_mode_warning("rec.csv", 243.1, 0.12)
    assert line.startswith("rec.csv: ") and "243.1 Hz" in line and "12 %" in line
    assert "\n" not in line and "--modes 2" in line
    assert second_mode_warning("rec.csv", 243.1, SECOND_MODE_SHARE) is None


# --------------------------------------------------------------------------------------
# Two-mode PLL records from the N-mode simulator


def _two_mode_record(f2: float, zeta2: float, gamma2: float, name="Config1_PRT_Assemb1") -> Record:
    """A TRC record of a linear two-mode plate whose PLL locks mode 1 (105 Hz, ζ = 1 %).

    Mode 1's base participation is 1 at its reference sensor (the centre, shape 1), so the
    power balance of its coordinate scaled there gives its damping ratio. The modes file
    carries the shapes turned by complex angles (undone by the phase alignment).
    """
    model = ModalModel(
        (Mode(105.0, 0.01, 1.0), Mode(f2, zeta2, gamma2)), joint_shapes=((1.0, 0.5),)
    )
    # A fixed-time schedule, as the virtual TRC rig runs it: a lock criterion that cannot be
    # met keeps every hold its full length while the PI controller tracks the resonance.
    config = PLLConfig(
        fs=FS, sensing="velocity", reference="base_velocity", n_periods=1,
        lock_tolerance_deg=1e-300, lock_periods=int(0.5 * HOLD_S * 105) - 1,
        max_hold_s=HOLD_S, ramp_s=RAMP_S, bandwidth_ratio=1e3,
    )  # fmt: skip
    series = simulate_modal_pll(
        model, LEVELS, mode=1, sensors=SHAPES, config=config, record=True
    ).time_series
    data = np.empty((series.t.size, 20))
    data[:, 0] = series.t
    data[:, 1:16] = series.sensors.T + series.base_velocity[:, None]
    data[:, 16:18] = series.base_velocity[:, None]
    data[:, 18] = series.frequency_hz
    data[:, 19] = np.degrees(np.angle(np.exp(1j * series.phase)))
    ramp, hold = round(RAMP_S * FS), round(HOLD_S * FS)
    assert series.t.size == len(LEVELS) * (ramp + hold)
    time, level = [0.0], [0.0]
    for j, value in enumerate(LEVELS):
        start = j * (ramp + hold) + ramp
        time += [start / FS, (start + hold - 1) / FS]
        level += [value, value]
    modes = Modes(SHAPES * np.exp(1j * np.radians([20.0, -70.0])), [105.0, f2])
    return Record(data, StepSchedule(time, level), name, modes=modes)


def _receptance(level: float, f: float, f_m: float, zeta_m: float, gamma_m: float) -> complex:
    """Steady modal displacement of a linear mode under base acceleration ``level sin ωt``."""
    w, w_m = 2 * math.pi * f, 2 * math.pi * f_m
    return -gamma_m * level / (w_m**2 - w**2 + 2j * zeta_m * w_m * w)


@pytest.fixture(scope="module")
def two_mode_folder(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("two_mode")
    write_record(_two_mode_record(198.0, 0.005, 0.8), folder)
    return folder


def test_pll_backbones_per_mode_against_the_linear_modes_put_in(two_mode_folder, tmp_path):
    out = tmp_path / "backbones.csv"
    assert main(["backbones", str(two_mode_folder), "--modes", "2", "--out", str(out)]) == 0
    table = pd.read_csv(out)
    assert table["mode"].dtype.kind == "i" and sorted(set(table["mode"])) == [1, 2]
    for m in (1, 2):
        for k in (1, 2, 3):
            assert {f"mode{m}_h{k}_amplitude_mm", f"mode{m}_h{k}_phase_deg"} <= set(table)
        assert f"mode{m}_energy_share" in table
    side = json.loads(sidecar_path(out).read_text())["curves"][0]
    assert side["locked_mode"] == 1 and side["reference_sensor"][0] == "panel08_m_s"
    # the files keep 9 digits: what is left is their rounding
    assert max(side["reconstruction_error"].values()) < 1e-8
    assert max(side["alignment_error"]) < 1e-8
    # Mode 1 locked: its frequency and damping are the linear mode's.
    locked = table[table["mode"] == 1]
    np.testing.assert_allclose(locked["frequency_hz"], 105.0, rtol=5e-4)
    np.testing.assert_allclose(locked["damping_ratio"], 0.01, rtol=0.02)
    amplitude_1 = [abs(_receptance(a, 105.0, 105.0, 0.01, 1.0)) for a in LEVELS]
    np.testing.assert_allclose(locked["amplitude_mm"], 1e3 * np.array(amplitude_1), rtol=0.01)
    # Mode 2 answers at the hold's frequency: participation only.
    other = table[table["mode"] == 2]
    assert other["frequency_hz"].isna().all() and other["damping_ratio"].isna().all()
    reference = SENSORS.index(side["reference_sensor"][1])
    x2 = np.array([_receptance(a, 105.0, 198.0, 0.005, 0.8) for a in LEVELS])
    x2 *= TORSION[reference]
    x1 = np.array([_receptance(a, 105.0, 105.0, 0.01, 1.0) for a in LEVELS])
    np.testing.assert_allclose(other["amplitude_mm"], 1e3 * np.abs(x2), rtol=0.01)
    np.testing.assert_allclose(other["mode2_h1_amplitude_mm"], 1e3 * np.abs(x2), rtol=0.01)
    phase = np.degrees(np.angle(x2 / x1))
    np.testing.assert_allclose(other["mode2_h1_phase_deg"], phase, atol=0.5)
    omega = 2 * np.pi * np.array([105.0, 198.0])
    energy = 0.25 * ((2 * np.pi * 105.0) ** 2 + omega**2) * np.abs(np.column_stack([x1, x2])) ** 2
    share = energy[:, 1] / energy.sum(axis=1)
    np.testing.assert_allclose(other["mode2_energy_share"], share, rtol=0.03)
    # the locked rows read back as one-mode backbones
    curves = mode_backbones(table, 1, source=str(out))
    assert len(curves) == 1 and len(curves[0]) == len(LEVELS)
    assert len(mode_backbones(table, 2)) == 0


def test_column_file_with_several_responses_and_a_mode_shape_file(two_mode_folder, tmp_path):
    trc = read_record(next(two_mode_folder.glob("Config1_PRT_Assemb1*")))
    chosen = (7, 0, 5, 9, 14)  # 0-based panel points: the centre first, then points off-axis
    names = [f"v{p + 1}" for p in chosen]
    column = ColumnRecord(
        time_s=trc.time_s, response=trc.sensor_responses[:, chosen[0]], quantity="velocity",
        name="two_mode", response_name=names[0], excitation=trc.excitation,
        excitation_kind="base-velocity", excitation_name="base_velocity",
        frequency_channel=trc.frequency_hz, steps=trc.steps, relative=True,
        extra_responses=tuple(trc.sensor_responses[:, p] for p in chosen[1:]),
        extra_response_names=tuple(names[1:]),
    )  # fmt: skip
    path = write_columns(column, tmp_path / "two_mode.h5")
    shapes = tmp_path / "shapes.txt"
    shapes.write_text(Modes(SHAPES[list(chosen)], [105.0, 198.0]).to_text())
    out = tmp_path / "bb.csv"
    argv = ["backbones", str(path), "--response", ",".join(names), "--relative-response",
            "--quantity", "velocity",
            "--mode-shapes", str(shapes), "--modes", "2", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    table = pd.read_csv(out)
    locked = table[table["mode"] == 1]
    np.testing.assert_allclose(locked["frequency_hz"], 105.0, rtol=5e-4)
    np.testing.assert_allclose(locked["damping_ratio"], 0.01, rtol=0.02)
    side = json.loads(sidecar_path(out).read_text())["curves"][0]
    assert side["shapes_source"] == str(shapes)
    assert list(side["reconstruction_error"]) == names
    # Without a mode-shape file the shapes are estimated from the record (the ramps between
    # the holds ring the second mode), and the source says so.
    estimated = tmp_path / "estimated.csv"
    assert main([*argv[:7], "--modes", "2", "--out", str(estimated)]) == 0
    side = json.loads(sidecar_path(estimated).read_text())["curves"][0]
    assert side["shapes_source"].startswith("estimated from the records")
    np.testing.assert_allclose(side["linear_frequencies_hz"], [105.0, 198.0], atol=1.0)
    locked = pd.read_csv(estimated).query("mode == 1")
    np.testing.assert_allclose(locked["frequency_hz"], 105.0, rtol=5e-4)
    np.testing.assert_allclose(locked["damping_ratio"], 0.01, rtol=0.02)
    # One mode of the same file: the first response's backbone, as with that column alone.
    one, alone = tmp_path / "one.csv", tmp_path / "alone.csv"
    base = ["backbones", str(path), "--relative-response", "--quantity", "velocity"]
    assert main([*base, "--response", ",".join(names), "--out", str(one)]) == 0
    assert main([*base, "--response", names[0], "--out", str(alone)]) == 0
    assert one.read_bytes() == alone.read_bytes()


def test_one_mode_reading_warns_once_of_a_second_mode_it_leaves_out(tmp_path):
    folder = tmp_path / "close"
    # A second mode close above the first with a large participation: its off-resonant
    # answer carries several per cent of the energy.
    write_record(_two_mode_record(115.0, 0.005, 3.0), folder)
    x1 = abs(_receptance(LEVELS[0], 105.0, 105.0, 0.01, 1.0))
    x2 = abs(_receptance(LEVELS[0], 105.0, 115.0, 0.005, 3.0)) * np.abs(TORSION).max()
    w = 2 * np.pi * 105.0
    e1, e2 = 0.25 * 2 * w**2 * x1**2, 0.25 * (w**2 + (2 * np.pi * 115.0) ** 2) * x2**2
    share = e2 / (e1 + e2)
    assert share > 0.05
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert main(["backbones", str(folder), "--out", str(tmp_path / "bb.csv")]) == 0
    said = [str(w.message) for w in caught if "second mode" in str(w.message)]
    assert len(said) == 1 and "115 Hz" in said[0]
    stated = float(said[0].split("carries ")[1].split(" %")[0]) / 100
    assert stated == pytest.approx(share, rel=0.03)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        argv = ["backbones", str(folder), "--out", str(tmp_path / "bb2.csv"),
                "--second-mode-share", f"{share * 1.1}"]  # fmt: skip
        assert main(argv) == 0
    assert not [w for w in caught if "second mode" in str(w.message)]


# --------------------------------------------------------------------------------------
# --modes 1 is main's path, bit for bit


def test_one_mode_backbones_are_mains_to_rounding(two_mode_folder, tmp_path):
    """``backbones --modes 1`` writes what main wrote before several modes were read:
    tests/data/one_mode_backbones/ holds main's tables of a one-assembly trc-like rig
    campaign (2 levels) and of the two-mode plate record (see its README for the commit);
    only ``source``, the record's folder, is kept as the record's name. The same columns,
    rows and words; numbers equal to 1e-12 relative, as another processor's floating point
    rounds the last digit otherwise (seen: 1e-15 on an AMD EPYC, equal on CI's)."""
    from pm_joint.pipeline import write_rig_campaign

    rig = tmp_path / "rig"
    write_rig_campaign("trc-like", rig, assemblies=1, n_levels=2, progress=False)
    for name, folder in {"rig": rig, "two_mode": two_mode_folder}.items():
        mine = tmp_path / f"{name}.csv"
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            assert main(["backbones", str(folder), "--modes", "1", "--out", str(mine)]) == 0
        written = mine.read_text().replace(f",{folder}{os.sep}", ",")
        expected = (DATA / "one_mode_backbones" / f"{name}.csv").read_text()
        mine_frame, main_frame = (pd.read_csv(io.StringIO(t)) for t in (written, expected))
        pd.testing.assert_frame_equal(mine_frame, main_frame, check_exact=False, rtol=1e-12,
                                      atol=0, obj=name)  # fmt: skip


def test_csv_with_several_response_columns(tmp_path):
    from identification.measurements.columns import ColumnLayout, read_columns

    t = np.arange(2000) / FS
    frame = pd.DataFrame(
        {"time": t, "acc_a": np.sin(600 * t), "acc_b": np.cos(600 * t), "acc_c": t,
         "base_acc": 0.1 * np.sin(600 * t)}
    )  # fmt: skip
    path = tmp_path / "plate.csv"
    frame.to_csv(path, index=False)
    layout = ColumnLayout(test="phase-resonance", response="acc_a, acc_c,acc_b")
    record = read_columns(path, layout)
    assert record.sensor_names == ("acc_a", "acc_c", "acc_b")
    assert record.response_name == "acc_a" and record.quantity == "acceleration"
    np.testing.assert_array_equal(
        record.sensor_responses, frame[["acc_a", "acc_c", "acc_b"]].to_numpy()
    )
    assert record.excitation_name == "base_acc"
    with pytest.raises(ValueError, match="named twice"):
        read_columns(path, ColumnLayout(response="acc_a,acc_b,acc_a"))
    with pytest.raises(ValueError, match="no response column 'acc_d'"):
        read_columns(path, ColumnLayout(response="acc_a,acc_d"))
