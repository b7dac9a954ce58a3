"""#26's acceptance on free decays written by the independent simulator.

The decays come from :func:`independent.decays.modal_free_decay` (scipy's DOP853 on modal
equations written without pm-joint's kernels): two modes near 1:2 (100 and 196 Hz) coupled
through a joint with a cubic spring and a cubic damper on ``u = q1 + 0.8 q2`` and through
the potential ``κ q1² q2``, seen by the 15 panel points of a plate (its shapes given with
``--mode-shapes``), read as velocities with sensor noise, time stamps rounded to 7
significant digits, written as one CSV of 15 response columns and read by the command line
``pm-joint backbones FILE --test free-decay --response p1,…,p15 --quantity velocity
--modes 2 --mode-shapes FILE --out FILE``.

Each decay starts on one mode (its coordinate displaced, the other at rest), so that it
follows that mode's nonlinear mode; the truth is the nonlinear mode by the extended
periodic motion concept (:func:`identification.multimode.nonlinear_modes`, checked against
independent integrations in ``test_multimode``). Acceptance: every point of the mode's
backbone within 0.05 % in frequency and 2 % in damping of the truth at its amplitude, over
the measured range. The second mode's participation is checked on PLL holds (where it is
defined: the other mode's harmonics at the locked mode's frequency; ``test_two_mode_rig``,
against the rig's truth), not here.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from scipy.interpolate import PchipInterpolator
from two_modes import JointedTwoModes

from identification.multimode import (
    Coupling,
    HarmonicSettings,
    ModalModel,
    Mode,
    nonlinear_modes,
)
from identification.rig import plate_shapes
from independent.decays import ModalSystem, PotentialTerm, modal_free_decay
from pm_joint.cli import main as cli

#: Among the longest files of ``make test``: handed out first (tests/conftest.py).
pytestmark = pytest.mark.heavy

FREQUENCY_RTOL, DAMPING_RTOL = 5e-4, 0.02
F_HZ, ZETA = (100.0, 196.0), (0.003, 0.003)
JOINT = (1.0, 0.8)
K3, C3, KAPPA = 5e9, 12.0, 3e6
#: Sensor noise (m/s): 3e-5 of the largest velocity of a 1 mm decay.
NOISE_M_S = 2e-5
SHAPES = plate_shapes()[:, :2]
NAMES = [f"p{i + 1}" for i in range(SHAPES.shape[0])]


TRUTH = JointedTwoModes(F_HZ, ZETA, JOINT, K3, C3, KAPPA)


def _write_decay(folder, mode: int, amplitude_m: float, seed: int):
    q0 = np.zeros(2)
    q0[mode - 1] = amplitude_m
    decay = modal_free_decay(TRUTH.system(), q0, sensor_shapes=SHAPES, duration_s=1.5,
                             time_digits=7)  # fmt: skip
    rng = np.random.default_rng(seed)
    velocity = decay.velocity_m_s + rng.normal(0.0, NOISE_M_S, decay.velocity_m_s.shape)
    path = folder / f"decay_mode{mode}.csv"
    frame = pd.DataFrame(velocity.T, columns=NAMES)
    frame.insert(0, "time", decay.time_s)
    frame.to_csv(path, index=False, float_format="%.10g")
    shapes = folder / "shapes.txt"
    np.savetxt(shapes, np.vstack([SHAPES, F_HZ]), fmt="%.10g")
    return path, shapes


def _read(path, shapes, out):
    code = cli(["backbones", str(path), "--test", "free-decay", "--response", ",".join(NAMES),
                "--quantity", "velocity", "--modes", "2", "--mode-shapes", str(shapes),
                "--out", str(out)])  # fmt: skip
    assert code == 0
    return pd.read_csv(out)


@pytest.mark.parametrize(("mode", "amplitude_m"), [(1, 1.2e-3), (2, 1.0e-3)])
def test_decay_backbones_follow_the_nonlinear_modes(tmp_path, mode, amplitude_m):
    path, shapes = _write_decay(tmp_path, mode, amplitude_m, seed=mode)
    rows = _read(path, shapes, tmp_path / "modes.csv")
    mine = rows[rows["mode"] == mode]
    assert len(mine) >= 20
    reference = np.abs(SHAPES[:, mode - 1]).max()  # the table's amplitudes: at that sensor
    a_m = mine["amplitude_mm"].to_numpy() / 1e3 / reference
    grid = np.geomspace(0.5 * a_m.min(), 1.2 * a_m.max(), 40)
    truth = nonlinear_modes(TRUTH.model(), grid, mode=mode, settings=HarmonicSettings(harmonics=5))
    assert truth.converged.all()
    frequency = PchipInterpolator(np.log(grid), truth.frequency_hz)(np.log(a_m))
    damping = PchipInterpolator(np.log(grid), truth.damping_ratio)(np.log(a_m))
    np.testing.assert_allclose(mine["frequency_hz"], frequency, rtol=FREQUENCY_RTOL)
    np.testing.assert_allclose(mine["damping_ratio"], damping, rtol=DAMPING_RTOL)


# ------------------------------------------------------------------ one sensor near 1:2

#: ``κ q1² q2`` of the one-sensor decay: mode 2's slaved response is 5 % of mode 1's at 1 mm.
ONE_SENSOR_KAPPA = 2e6
ONE_SENSOR_F_HZ, ONE_SENSOR_ZETA = (122.0, 243.0), (0.004, 0.003)


def test_one_sensor_decay_near_one_to_two(tmp_path, capsys):
    """One sensor seeing both modes of a ``κ q1² q2`` pair near 1:2, time stamps rounded to 7
    digits: ``--modes 2`` gives both modes' backbones, and the one-mode request prints the
    warning line naming mode 2's frequency.

    Both modes ring here, and mode 2's free part at ω2 ≈ 2ω1 drives mode 1 through
    ``2κ q1 q2`` at ω2 − ω1 ≈ ω1: energy goes back and forth, which no single nonlinear
    mode carries. Frequencies hold the nonlinear modes' to 0.05 %, mode 2's damping to 2 %;
    mode 1's damping is held to 5 % (the exchange modulates its decay rate by a few %).
    """
    system = ModalSystem(ONE_SENSOR_F_HZ, ONE_SENSOR_ZETA,
                         couplings=(PotentialTerm(ONE_SENSOR_KAPPA, (2, 1)),))  # fmt: skip
    decay = modal_free_decay(system, (1e-3, 0.3e-3), sensor_shapes=[[1.0, 0.8]],
                             duration_s=1.0, time_digits=7)  # fmt: skip
    assert np.ptp(np.diff(decay.time_s)) > 0  # the rounded stamps jitter
    noisy = decay.displacement_m + np.random.default_rng(7).normal(0, 1e-8, decay.time_s.size)
    path = tmp_path / "ring.csv"
    pd.DataFrame({"time": decay.time_s, "displacement": noisy[0]}).to_csv(path, index=False)
    options = ["--test", "free-decay", "--response", "displacement", "--quantity",
               "displacement"]  # fmt: skip
    assert cli(["backbones", str(path), *options, "--modes", "2", "--out",
                str(tmp_path / "two.csv")]) == 0  # fmt: skip
    rows = pd.read_csv(tmp_path / "two.csv")
    model = ModalModel(
        modes=tuple(Mode(f, z, 1.0) for f, z in zip(ONE_SENSOR_F_HZ, ONE_SENSOR_ZETA,
                                                    strict=True)),
        joint_shapes=(),
        couplings=(Coupling(1, (1, 1), 2 * ONE_SENSOR_KAPPA),
                   Coupling(2, (2, 0), ONE_SENSOR_KAPPA)),
    )  # fmt: skip
    for mode, shape, damping_rtol in ((1, 1.0, 0.05), (2, 0.8, DAMPING_RTOL)):
        mine = rows[rows["mode"] == mode]
        assert len(mine) >= 20
        a_m = mine["amplitude_mm"].to_numpy() / 1e3 / shape
        grid = np.geomspace(0.5 * a_m.min(), 1.2 * a_m.max(), 40)
        truth = nonlinear_modes(model, grid, mode=mode, settings=HarmonicSettings(harmonics=5))
        frequency = PchipInterpolator(np.log(grid), truth.frequency_hz)(np.log(a_m))
        damping = PchipInterpolator(np.log(grid), truth.damping_ratio)(np.log(a_m))
        np.testing.assert_allclose(mine["frequency_hz"], frequency, rtol=FREQUENCY_RTOL)
        np.testing.assert_allclose(mine["damping_ratio"], damping, rtol=damping_rtol)
    capsys.readouterr()
    assert cli(["backbones", str(path), *options, "--out", str(tmp_path / "one.csv")]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "second mode" in line]
    assert len(warnings) == 1
    assert "second mode near 243.0 Hz" in warnings[0]
