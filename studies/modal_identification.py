"""Two-mode identification against one mode: held-out decays of a known two-mode truth.

The case of ``pm-joint identify --modes 2`` (issue 27's first acceptance): ring-downs of
the independent simulator (:mod:`independent.decays`, sharing no code with the library)
of two modes near 1:2, coupled through the potential ``κ q₁² q₂`` and through a joint
(``q = q₁ + 0.5 q₂``) with quadratic damping, read by four displacement sensors
(:data:`SHAPES`, each mode's largest entry 1, so the modal coordinates are mass-normalised
and the joint sensor is the first). Identification decays are drawn on tuning seeds
(``0 …``), the prediction error is measured on held-out ones (``HELD_OUT_SEED …``).

Outcome rule (fixed before the held-out run): the two-mode model's mean NMTE over the
held-out decays is at most :data:`RATIO_TARGET` times the one-mode model's.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from identification.measurements.columns import ColumnLayout, open_records
from identification.measurements.modes import Modes
from independent.decays import ModalSystem, PotentialTerm, modal_free_decay
from independent.forces import QuadraticDamping
from pm_joint.predict import predict_record

__all__ = [
    "COUPLING",
    "FREQUENCIES_HZ",
    "JOINT_DAMPING",
    "LAYOUT",
    "MODE_SHAPES",
    "RATIO_TARGET",
    "Comparison",
    "compare",
    "decay_records",
    "truth",
]

FREQUENCIES_HZ = (100.0, 201.0)
DAMPING_RATIOS = (0.005, 0.006)
#: ``κ`` of the potential ``κ q₁² q₂`` (1/(m·s²)).
COUPLING = 3e7
#: Quadratic damping ``c q̇|q̇|`` at the joint (1/m).
JOINT_DAMPING = 5.0
JOINT_SHAPE = (1.0, 0.5)
#: Mode shapes at the four sensors; the first is at the joint.
SHAPES = np.array([JOINT_SHAPE, [0.8, 1.0], [0.8, -1.0], [0.5, 0.6]])
SENSORS = ("s1", "s2", "s3", "s4")
FS_HZ = 10_000.0
DURATION_S = 0.5
LAYOUT = ColumnLayout(test="free-decay", quantity="displacement", response=",".join(SENSORS))
MODE_SHAPES = Modes(SHAPES, np.array(FREQUENCIES_HZ), source="the study's sensor shapes")
#: The acceptance: two-mode NMTE ≤ this × one-mode NMTE on held-out decays.
RATIO_TARGET = 0.5


def truth() -> ModalSystem:
    """The two-mode truth of the independent simulator."""
    return ModalSystem(
        FREQUENCIES_HZ,
        DAMPING_RATIOS,
        joint_shape=JOINT_SHAPE,
        joint_terms=(QuadraticDamping(JOINT_DAMPING),),
        couplings=(PotentialTerm(COUPLING, (2, 1)),),
    )


def decay_records(seeds: Sequence[int], folder: str | Path, duration_s: float = DURATION_S):
    """One ring-down per seed (modal displacements up to 1 mm, random velocities), written as
    CSV in ``folder`` and read back as records."""
    system = truth()
    records = []
    for seed in seeds:
        rng = np.random.default_rng(seed)
        q0 = 1e-3 * rng.uniform([0.6, 0.1], [1.0, 0.4])
        qdot0 = 1e-3 * rng.uniform(-1, 1, 2) * system.omega_rad_s
        decay = modal_free_decay(system, q0, qdot0, sensor_shapes=SHAPES, fs_hz=FS_HZ,
                                 duration_s=duration_s, time_digits=7)  # fmt: skip
        path = decay.write_csv(Path(folder) / f"decay_{seed}.csv", "displacement", SENSORS)
        records += open_records(path, LAYOUT)
    return records


class Comparison(NamedTuple):
    """Held-out NMTE (fractions) of the two models, one per record."""

    two_mode: tuple[float, ...]
    one_mode: tuple[float, ...]

    @property
    def ratio(self) -> float:
        """Mean two-mode NMTE over mean one-mode NMTE."""
        return float(np.mean(self.two_mode) / np.mean(self.one_mode))


def compare(two_mode: Any, one_mode: Any, records: Sequence[Any], **options: Any) -> Comparison:
    """Both models' prediction errors on ``records`` (options: those of ``predict_record``)."""
    two = tuple(predict_record(two_mode, r, **options).nmte for r in records)
    one = tuple(predict_record(one_mode, r, **options).nmte for r in records)
    return Comparison(two, one)
