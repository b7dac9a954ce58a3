"""Two modes near 1:2 for the decay-by-mode tests, through :mod:`independent.decays`.

``TwoModes`` names the cases of the tests (a cubic spring per mode, a quadratic spring of
mode 1, the ``κq₁²q₂`` coupling) as terms of the independent simulator's modal potential;
``two_mode_decay`` returns its ring-down with samples first, as the library reads them.
``JointedTwoModes`` is the acceptance tests' truth (a cubic spring and damper on the joint
coordinate, the ``κq₁²q₂`` coupling) both as the simulator's system and as the library's
model, so the two are written once, side by side.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification.effects import CATALOGUE
from identification.multimode import Coupling, JointElement, ModalModel, Mode
from independent.decays import ModalSystem, PotentialTerm, modal_free_decay
from independent.forces import CubicDamping, CubicStiffness


@dataclass(frozen=True)
class TwoModes:
    """``q̈₁ + 2ζ₁ω₁q̇₁ + ω₁²q₁ + k₃₁q₁³ + k₂₁q₁² + 2κq₁q₂ = 0`` and
    ``q̈₂ + 2ζ₂ω₂q̇₂ + ω₂²q₂ + k₃₂q₂³ + κq₁² = 0`` (unit modal masses, SI units)."""

    frequency_hz: tuple[float, float]
    damping_ratio: tuple[float, float]
    cubic: tuple[float, float] = (0.0, 0.0)
    quadratic_mode1: float = 0.0
    coupling: float = 0.0

    def system(self) -> ModalSystem:
        """The simulator's modal system: each force as the derivative of a potential term."""
        terms = [PotentialTerm(self.quadratic_mode1 / 3, (3, 0)),
                 PotentialTerm(self.cubic[0] / 4, (4, 0)), PotentialTerm(self.cubic[1] / 4, (0, 4)),
                 PotentialTerm(self.coupling, (2, 1))]  # fmt: skip
        return ModalSystem(self.frequency_hz, self.damping_ratio,
                           couplings=tuple(t for t in terms if t.coefficient))  # fmt: skip


@dataclass(frozen=True)
class JointedTwoModes:
    """Two modes with a cubic spring ``k₃`` and a cubic damper ``c₃`` on the joint coordinate
    ``joint · q`` and the potential ``κq₁²q₂`` (unit modal masses, SI units)."""

    frequency_hz: tuple[float, float]
    damping_ratio: tuple[float, float]
    joint: tuple[float, float]
    cubic_stiffness: float
    cubic_damping: float
    coupling: float

    def system(self) -> ModalSystem:
        """The independent simulator's system."""
        return ModalSystem(self.frequency_hz, self.damping_ratio, joint_shape=self.joint,
                           joint_terms=(CubicStiffness(self.cubic_stiffness),
                                        CubicDamping(self.cubic_damping)),
                           couplings=(PotentialTerm(self.coupling, (2, 1)),))  # fmt: skip

    def model(self) -> ModalModel:
        """The same system as the library's model (the potential's forces: ``2κq₁q₂`` on
        mode 1, ``κq₁²`` on mode 2)."""
        modes = zip(self.frequency_hz, self.damping_ratio, strict=True)
        return ModalModel(
            modes=tuple(Mode(f, z, 1.0) for f, z in modes),
            joint_shapes=(self.joint,),
            elements=(JointElement(CATALOGUE["cubic_stiffness"].name, self.cubic_stiffness),
                      JointElement(CATALOGUE["cubic_damping"].name, self.cubic_damping)),
            couplings=(Coupling(1, (1, 1), 2 * self.coupling),
                       Coupling(2, (2, 0), self.coupling)),
        )  # fmt: skip


def two_mode_decay(
    modes: TwoModes,
    q0_m: tuple[float, float],
    shapes: np.ndarray,
    *,
    fs_hz: float = 10_000.0,
    duration_s: float = 1.0,
) -> dict[str, np.ndarray]:
    """Ring-down from rest at ``q0_m``, read by sensors ``shapes`` ``(n_sensors, 2)``, time
    stamps rounded to 7 significant digits: ``time_s``, ``modal_m`` ``(n, 2)`` and the
    sensors' ``displacement_m``, ``velocity_m_s``, ``acceleration_m_s2`` ``(n, n_sensors)``."""
    decay = modal_free_decay(modes.system(), q0_m, sensor_shapes=shapes, fs_hz=fs_hz,
                             duration_s=duration_s, time_digits=7)  # fmt: skip
    return {
        "time_s": decay.time_s,
        "modal_m": decay.modal_displacement.T,
        "displacement_m": decay.displacement_m.T,
        "velocity_m_s": decay.velocity_m_s.T,
        "acceleration_m_s2": decay.acceleration_m_s2.T,
    }
