"""`pm-joint predict`: a model simulated from a record's start, against records written by the
independent simulator (:mod:`independent.decays`, scipy's DOP853 on forces written here).

Expectations are independent of the code under test: an exact model reproduces the simulator's
decay; a 1 % frequency error gives the NMTE of two sinusoids drifting apart in phase, computed
here in closed form; a two-mode decay is predicted by the two-mode model and not by one mode.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from identification.measurements.columns import ColumnLayout
from identification.measurements.modes import Modes
from identification.model import JointModel
from identification.multimode.model import Coupling, ModalModel, Mode
from independent.decays import (
    ModalSystem,
    PotentialTerm,
    forced_steady_state,
    free_decay,
    modal_free_decay,
)
from pm_joint.cli import main
from pm_joint.predict import SimulationDiverged, nmte, predict_record

HELD_OUT_SEED = 1_000_000
FS_HZ = 5_000.0
F_HZ, ZETA = 100.0, 0.01
OMEGA = 2 * math.pi * F_HZ
DECAY = ColumnLayout(test="free-decay", quantity="displacement")
SENSORS = ("s1", "s2", "s3", "s4")
DECAY4 = ColumnLayout(test="free-decay", quantity="displacement", response=",".join(SENSORS))


def _write(path, time_s, values, names):
    np.savetxt(path, np.column_stack([time_s, values]), delimiter=",",
               header=",".join(["time", *names]), comments="", fmt="%.12e")  # fmt: skip
    return path


@pytest.fixture(scope="module")
def linear_decay(tmp_path_factory):
    """A linear oscillator's ring-down, 0.5 s at 5 kHz, from 1 mm at rest."""
    d = free_decay(lambda x, v: OMEGA**2 * x + 2 * ZETA * OMEGA * v, 1e-3, 0.0,
                   fs_hz=FS_HZ, duration_s=0.5)  # fmt: skip
    folder = tmp_path_factory.mktemp("decay")
    _write(folder / "acceleration.csv", d["time_s"], d["acceleration_m_s2"], ["acceleration"])
    return _write(folder / "decay.csv", d["time_s"], d["displacement_m"], ["displacement"])


def _oscillator(frequency_hz: float, zeta_omega: float) -> JointModel:
    return JointModel({"linear_stiffness": (2 * math.pi * frequency_hz) ** 2,
                       "viscous_damping": 2 * zeta_omega})  # fmt: skip


def test_nmte_of_scaled_and_missing_predictions():
    t = np.linspace(0, 1, 1001)
    y = np.column_stack([np.cos(2 * np.pi * 5 * t), np.sin(2 * np.pi * 5 * t)])
    assert nmte(1.03 * y, y) == pytest.approx(0.03, rel=1e-9)
    assert nmte(np.zeros_like(y), y) == pytest.approx(1.0, rel=1e-9)
    # One sensor: on its delay embedding over a period ‖(y(t), …)‖ is constant.
    assert nmte(1.02 * y[:, :1], y[:, :1], embedding_samples=200) == pytest.approx(0.02, rel=1e-9)


def test_the_true_linear_model_predicts_the_decay(linear_decay):
    prediction = predict_record(_oscillator(F_HZ, ZETA * OMEGA), linear_decay, layout=DECAY)
    assert prediction.nmte < 1e-3
    assert prediction.embedding_samples == round(2 * FS_HZ / F_HZ)
    assert prediction.initial_displacement[0] == pytest.approx(1e-3, rel=1e-4)


def test_an_acceleration_record_is_predicted_in_acceleration(linear_decay):
    path = linear_decay.with_name("acceleration.csv")
    layout = ColumnLayout(test="free-decay", quantity="acceleration")
    prediction = predict_record(_oscillator(F_HZ, ZETA * OMEGA), path, layout=layout)
    assert prediction.quantity == "acceleration" and prediction.nmte < 1e-3
    assert prediction.initial_displacement[0] == pytest.approx(1e-3, rel=1e-3)


def test_a_base_driven_record_replays_its_excitation(tmp_path):
    """A steady response to a measured base acceleration, recorded absolute: the model driven
    by the replayed column, the base's acceleration added back, matches it."""
    omega_drive, amplitude = 0.97 * OMEGA, 2.0

    def force(x, v):
        return OMEGA**2 * x + 2 * ZETA * OMEGA * v

    d = forced_steady_state(force, lambda t: amplitude * np.sin(omega_drive * t),
                            2 * np.pi / omega_drive, fs_hz=FS_HZ, record_periods=30)  # fmt: skip
    base = -d["excitation"]  # ẍ + force = −a_base
    relative = d["excitation"] - force(d["displacement_m"], d["velocity_m_s"])
    path = tmp_path / "driven.csv"
    np.savetxt(path, np.column_stack([d["time_s"], relative + base, base]), delimiter=",",
               header="time,acceleration,base_acceleration", comments="", fmt="%.12e")  # fmt: skip
    layout = ColumnLayout(
        test="stepped-sine", response="acceleration", quantity="acceleration",
        excitation="base_acceleration", excitation_kind="base-acceleration",
    )  # fmt: skip
    prediction = predict_record(_oscillator(F_HZ, ZETA * OMEGA), path, layout=layout)
    assert prediction.excitation == "base-acceleration" and not prediction.relative
    assert prediction.nmte < 1e-3
    at_rest = predict_record(_oscillator(F_HZ, ZETA * OMEGA), path,
                             layout=dataclasses.replace(layout, test="free-decay"))  # fmt: skip
    assert at_rest.nmte > 0.1  # the same model without the excitation: the record is not a decay


def test_a_one_percent_frequency_error_gives_the_phase_drift_error(linear_decay):
    """Model frequency ω(1+δ), same decay rate σ: fitted at the centre t_c = T of the first two
    periods, its phase drifts by δω(t − t_c) and ‖ŷ − y‖ of a window centred at t is
    2|sin(δω(t − t_c)/2)| times A e^{−σt}, ‖y‖ being A e^{−σt} (an embedding of whole periods)."""
    delta = 0.01
    exact = predict_record(_oscillator(F_HZ, ZETA * OMEGA), linear_decay, layout=DECAY)
    off = predict_record(_oscillator(F_HZ * (1 + delta), ZETA * OMEGA), linear_decay,
                         layout=DECAY)  # fmt: skip
    period = 1 / F_HZ
    m = off.embedding_samples
    centres = off.time_s[: off.time_s.size - m + 1] + period
    sigma = ZETA * OMEGA
    drift = 2 * np.abs(np.sin(delta * OMEGA * (centres - period) / 2))
    expected = np.mean(np.exp(-sigma * centres) * drift) / np.exp(-sigma * period)
    assert off.nmte == pytest.approx(expected, rel=0.03)
    assert off.nmte > 100 * exact.nmte


# ---------------------------------------------------------------------------
# Two modes near 1:2, coupled by a κq₁²q₂ potential, seen by four sensors

F2_HZ, ZETA2, KAPPA = 201.0, 0.008, 3e7
#: Shapes at the sensors, each mode's largest entry 1 (its coordinate is its contribution there).
SHAPES = np.array([[1.0, 0.0], [0.8, 1.0], [0.8, -1.0], [0.5, 0.6]])
NAMES = SENSORS


def _two_mode_record(tmp_path, seed: int):
    rng = np.random.default_rng(seed)
    system = ModalSystem((F_HZ, F2_HZ), (ZETA, ZETA2), couplings=(PotentialTerm(KAPPA, (2, 1)),))
    q0 = 1e-3 * rng.uniform([0.6, 0.1], [1.0, 0.4])
    qdot0 = 1e-3 * rng.uniform(-1, 1, 2) * system.omega_rad_s
    decay = modal_free_decay(system, q0, qdot0, sensor_shapes=SHAPES, fs_hz=FS_HZ,
                             duration_s=0.4, time_digits=7)  # fmt: skip
    path = decay.write_csv(tmp_path / f"two_modes_{seed}.csv", "displacement", NAMES)
    return path, Modes(SHAPES, np.array([F_HZ, F2_HZ]), source="test shapes")


def _two_mode_model() -> ModalModel:
    # ∂(κq₁²q₂)/∂q₁ = 2κq₁q₂ on mode 1, ∂/∂q₂ = κq₁² on mode 2
    return ModalModel(
        modes=(Mode(F_HZ, ZETA, 1.0), Mode(F2_HZ, ZETA2, 1.0)), joint_shapes=(),
        couplings=(Coupling(1, (1, 1), 2 * KAPPA), Coupling(2, (2, 0), KAPPA)),
    )  # fmt: skip


@pytest.mark.parametrize("seed", [0, HELD_OUT_SEED, HELD_OUT_SEED + 1])
def test_two_modes_predict_a_two_mode_decay_and_one_mode_does_not(tmp_path, seed):
    """Acceptance of #27: the two-mode model's error ≤ 0.5 × the one-mode model's."""
    path, shapes = _two_mode_record(tmp_path, seed)
    two = predict_record(_two_mode_model(), path, layout=DECAY4, mode_shapes=shapes)
    one = predict_record(_oscillator(F_HZ, ZETA * OMEGA), path, layout=DECAY4, mode_shapes=shapes)
    assert two.nmte < 5e-3
    assert two.nmte <= 0.5 * one.nmte
    assert two.sensor_names == NAMES and two.embedding_samples == 1
    np.testing.assert_allclose(two.sensor_shapes, SHAPES, atol=1e-9)


def test_two_modes_on_one_velocity_sensor(tmp_path):
    """One sensor that sees both modes' coordinates whole: the delay-embedded error."""
    system = ModalSystem((F_HZ, F2_HZ), (ZETA, ZETA2), couplings=(PotentialTerm(KAPPA, (2, 1)),))
    decay = modal_free_decay(system, [8e-4, 2e-4], [0.0, 0.5], sensor_shapes=[[1.0, 1.0]],
                             fs_hz=FS_HZ, duration_s=0.4, time_digits=7)  # fmt: skip
    path = decay.write_csv(tmp_path / "one_sensor.csv", "velocity", ["v"])
    layout = ColumnLayout(test="free-decay", quantity="velocity", response="v")
    two = predict_record(_two_mode_model(), path, layout=layout)
    one = predict_record(_oscillator(F_HZ, ZETA * OMEGA), path, layout=layout)
    assert two.embedding_samples == round(2 * FS_HZ / F_HZ)
    assert two.nmte < 5e-3 and two.nmte <= 0.5 * one.nmte


# ---------------------------------------------------------------------------
# The command


def test_the_command_writes_the_csv_and_json_and_prints_one_line(tmp_path, capsys):
    path, shapes = _two_mode_record(tmp_path, 1)
    shapes_file = tmp_path / "shapes.txt"
    shapes_file.write_text(shapes.to_text())
    model = _two_mode_model().to_json(tmp_path / "two.json")
    out = tmp_path / "prediction.csv"
    code = main(["predict", "--model", str(model), str(path), "--test", "free-decay",
                 "--response", ",".join(NAMES), "--quantity", "displacement",
                 "--mode-shapes", str(shapes_file), "--out", str(out)])  # fmt: skip
    printed = capsys.readouterr().out.strip().splitlines()
    assert code == 0
    assert len(printed) == 1 and printed[0].startswith("NMTE ") and printed[0].endswith(" %")
    header = out.read_text().splitlines()[0]
    assert header == "time," + ",".join(NAMES)
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    stamps = np.loadtxt(path, delimiter=",", skiprows=1)[:, 0]
    np.testing.assert_allclose(table[:, 0], stamps, rtol=1e-6, atol=1e-9)
    summary = json.loads((tmp_path / "prediction.csv.json").read_text())
    assert set(summary["per_sensor_nmte"]) == set(NAMES)
    assert printed[0] == f"NMTE {summary['nmte_percent']:.2f} %"


def test_a_one_mode_model_json_through_the_command(tmp_path, linear_decay, capsys):
    model = _oscillator(F_HZ, ZETA * OMEGA).to_json(tmp_path / "one.json")
    out = tmp_path / "p.csv"
    code = main(["predict", "--model", str(model), str(linear_decay), "--test", "free-decay",
                 "--quantity", "displacement", "--out", str(out)])  # fmt: skip
    assert code == 0 and capsys.readouterr().out.strip() == "NMTE 0.00 %"
    assert out.read_text().splitlines()[0] == "time,displacement"


def test_a_diverging_simulation_exits_2_with_one_line(tmp_path, linear_decay, capsys):
    model = _oscillator(F_HZ, -0.05 * OMEGA)  # negative damping: grows e-fold every 3 periods
    with pytest.raises(SimulationDiverged):
        predict_record(model, linear_decay, layout=DECAY)
    path = model.to_json(tmp_path / "negative.json")
    code = main(["predict", "--model", str(path), str(linear_decay), "--test", "free-decay",
                 "--quantity", "displacement", "--out", str(tmp_path / "p.csv")])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "diverged" in err[0]
