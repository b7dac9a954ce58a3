"""The one-mode request's second-mode warning on a free decay of several sensors looks at all
of them (the modal filter), not at the one-mode response alone.

The decay is the independent simulator's (:func:`independent.decays.modal_free_decay`: bending
at 100 Hz, torsion at 196 Hz, a cubic joint on ``q1 + 0.8 q2``, ``κ q1² q2``) seen by the 15
panel points of a plate; the first response column is the panel's centre point, which sits on
the torsion's node line (its torsion shape is 0), as the TRC layout's response does. Both modes
ring (torsion started at 40 % of bending's displacement, a third of the energy); the warning
must name torsion's frequency whether the shapes are given (``--mode-shapes``) or estimated.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from identification.rig import plate_shapes
from independent.decays import ModalSystem, PotentialTerm, modal_free_decay
from independent.forces import CubicStiffness
from pm_joint.cli import main as cli

F_HZ = (100.0, 196.0)
SHAPES = plate_shapes()[:, :2]
CENTRE = 7  # the panel's centre point (from 0): on the torsion's node line
#: The centre point first (the one-mode response), then the other points.
ORDER = [CENTRE, *[i for i in range(SHAPES.shape[0]) if i != CENTRE]]
NAMES = [f"p{i + 1}" for i in ORDER]


def _write(folder, q0_m, name: str):
    system = ModalSystem(F_HZ, (0.003, 0.003), joint_shape=(1.0, 0.8),
                         joint_terms=(CubicStiffness(5e9),),
                         couplings=(PotentialTerm(3e6, (2, 1)),))  # fmt: skip
    decay = modal_free_decay(system, q0_m, sensor_shapes=SHAPES[ORDER], duration_s=0.8,
                             time_digits=7)  # fmt: skip
    noisy = decay.velocity_m_s + np.random.default_rng(5).normal(0, 2e-5, decay.velocity_m_s.shape)
    path = folder / f"{name}.csv"
    frame = pd.DataFrame(noisy.T, columns=NAMES)
    frame.insert(0, "time", decay.time_s)
    frame.to_csv(path, index=False, float_format="%.10g")
    shapes = folder / "shapes.txt"
    np.savetxt(shapes, np.vstack([SHAPES[ORDER], F_HZ]), fmt="%.10g")
    return path, shapes


@pytest.fixture(scope="module")
def decay_files(tmp_path_factory):
    assert SHAPES[CENTRE, 1] == 0.0
    return _write(tmp_path_factory.mktemp("second_mode"), (1e-3, 0.4e-3), "plate")


def _warnings(capsys, path, *extra) -> list[str]:
    capsys.readouterr()
    options = ["--test", "free-decay", "--quantity", "velocity", *extra]
    assert cli(["backbones", str(path), *options, "--out", str(path.with_suffix(".out.csv"))]) == 0
    return [line for line in capsys.readouterr().err.splitlines() if "second mode" in line]


@pytest.mark.parametrize("given_shapes", [True, False])
def test_the_warning_sees_torsion_through_every_sensor(decay_files, capsys, given_shapes):
    path, shapes = decay_files
    extra = ["--response", ",".join(NAMES)]
    if given_shapes:
        extra += ["--mode-shapes", str(shapes)]
    lines = _warnings(capsys, path, *extra)
    assert len(lines) == 1
    frequency = float(lines[0].split("second mode near ")[1].split(" Hz")[0])
    assert frequency == pytest.approx(196.0, rel=5e-3)


def test_the_centre_point_alone_cannot_see_torsion(decay_files, capsys):
    """The same record read on its centre point only: torsion is not there to warn about."""
    path, _ = decay_files
    assert _warnings(capsys, path, "--response", NAMES[0]) == []


@pytest.mark.parametrize("given_shapes", [True, False])
def test_bending_alone_gives_no_warning(tmp_path, capsys, given_shapes):
    """Bending started alone: torsion only follows it through the joint and the coupling
    (slaved, well under 5 % of the energy), so no sensor shows a second mode to warn of."""
    path, shapes = _write(tmp_path, (1e-3, 0.0), "bending")
    extra = ["--response", ",".join(NAMES)]
    if given_shapes:
        extra += ["--mode-shapes", str(shapes)]
    assert _warnings(capsys, path, *extra) == []
