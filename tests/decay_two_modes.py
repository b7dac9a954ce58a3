"""An independent two-mode ring-down for tests: scipy's DOP853 on modal equations in plain Python.

Shares nothing with pm-joint (no catalogue kernels, no harmonic balance, no modal filter). Two
modal coordinates with modal damping, an optional cubic stiffness per mode and an optional
quadratic coupling through the potential ``κ q₁² q₂`` (the classical 1:2 internal-resonance
model):

    q₁'' + 2ζ₁ω₁ q₁' + ω₁² q₁ + k₃₁ q₁³ + k₂₁ q₁² + 2κ q₁ q₂ = 0
    q₂'' + 2ζ₂ω₂ q₂' + ω₂² q₂ + k₃₂ q₂³ + κ q₁² = 0

Sensors read ``y = Φ q`` (``Φ`` of shape ``(n_sensors, 2)``). Time stamps are written rounded to
``significant_digits`` significant digits, as a text export does.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp


@dataclass(frozen=True)
class TwoModes:
    """The two modal oscillators and their coupling (SI units, unit modal masses)."""

    frequency_hz: tuple[float, float]
    damping_ratio: tuple[float, float]
    cubic: tuple[float, float] = (0.0, 0.0)
    quadratic_mode1: float = 0.0
    coupling: float = 0.0

    def forces(self, q1, q2, v1, v2):
        """Modal restoring and damping forces per unit modal mass (floats or arrays)."""
        w1, w2 = 2 * np.pi * self.frequency_hz[0], 2 * np.pi * self.frequency_hz[1]
        z1, z2 = self.damping_ratio
        k31, k32 = self.cubic
        f1 = (2 * z1 * w1 * v1 + w1 * w1 * q1 + k31 * q1**3 + self.quadratic_mode1 * q1 * q1
              + 2 * self.coupling * q1 * q2)  # fmt: skip
        f2 = 2 * z2 * w2 * v2 + w2 * w2 * q2 + k32 * q2**3 + self.coupling * q1 * q1
        return f1, f2


def round_significant(values: np.ndarray, digits: int) -> np.ndarray:
    """``values`` written with ``digits`` significant digits and read back."""
    return np.array([float(f"{v:.{digits - 1}e}") for v in np.asarray(values, dtype=float)])


def two_mode_decay(
    modes: TwoModes,
    q0_m: tuple[float, float],
    shapes: np.ndarray,
    *,
    fs_hz: float = 10_000.0,
    duration_s: float = 1.0,
    significant_digits: int = 7,
    rtol: float = 1e-10,
) -> dict[str, np.ndarray]:
    """Ring-down from rest at the modal displacements ``q0_m``, read by sensors ``shapes @ q``.

    Returns ``time_s`` (rounded stamps), ``modal_m`` ``(n, 2)``, and the sensors'
    ``displacement_m``, ``velocity_m_s`` and ``acceleration_m_s2`` ``(n, n_sensors)``; the
    acceleration from the equations of motion, not from differencing.
    """

    def rhs(_, state):
        q1, q2, v1, v2 = state.tolist()
        f1, f2 = modes.forces(q1, q2, v1, v2)
        return [v1, v2, -f1, -f2]

    t = np.arange(round(duration_s * fs_hz)) / fs_hz
    solution = solve_ivp(rhs, (0.0, t[-1]), [q0_m[0], q0_m[1], 0.0, 0.0], method="DOP853",
                         t_eval=t, rtol=rtol, atol=1e-15)  # fmt: skip
    if not solution.success:
        raise RuntimeError(f"two-mode decay did not integrate: {solution.message}")
    q, v = solution.y[:2].T, solution.y[2:].T
    a = -np.column_stack(modes.forces(q[:, 0], q[:, 1], v[:, 0], v[:, 1]))
    phi = np.asarray(shapes, dtype=float).reshape(-1, 2)
    return {
        "time_s": round_significant(t, significant_digits),
        "modal_m": q,
        "displacement_m": q @ phi.T,
        "velocity_m_s": v @ phi.T,
        "acceleration_m_s2": a @ phi.T,
    }
