"""The phase-resonance backbone of one mode of a :class:`~independent.decays.ModalSystem`,
by a harmonic balance of its own: what a phase-locked test of several modes holds.

The system is base-driven, mode ``i`` feeling ``−Γ_i a_base(θ)``; the locked mode ``L`` is held
at phase resonance: its fundamental is ``a cos θ`` (``θ = ωt``) while the base acceleration is

    ``a_base = A [sin θ + Σ_h d_h sin(hθ + ψ_h)]``

(a shaker's distortion: fractions ``d_h`` of orders ``h ≥ 2`` at phases ``ψ_h`` in the frame of
its fundamental; none by default). The unknowns are ``ω``, ``A``, the locked mode's mean and
harmonics ``2..H`` and every harmonic of the other modes. What a test reads from that state:

* the frequency ``ω/2π`` (Hz);
* the damping ratio of the locked mode's fundamental power balance, ``D = Γ_L A / (2 ω² a)``
  (a modal filter's reading of a coordinate whose base participation is ``Γ_L``);
* every mode's participation: the complex amplitude ``P_k = C_k − i S_k`` of each harmonic
  ``k`` of its coordinate, ``q = Re Σ_k P_k e^{ikθ}``, so that the locked mode's ``P_1 = a``
  and another mode's phase is against ``k×`` the locked fundamental's.

Method: the Fourier coefficients are sampled at ``M`` points per period, the joint and
potential forces evaluated there (memoryless joint terms only) and projected by the FFT;
:func:`scipy.optimize.root` (MINPACK's hybrid method) solves the balance, amplitude after
amplitude from the previous solution (the first from the linear resonance). Nothing here is the
library's: it shares only the system's definition with :mod:`independent.decays`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import root

from independent.decays import ModalSystem

__all__ = ["PURE_SINE", "ModalResonance", "ShakerDistortion", "modal_phase_resonance"]


@dataclass(frozen=True)
class ShakerDistortion:
    """Orders ``h ≥ 2`` of a base acceleration ``A [sin θ + Σ_h d_h sin(hθ + ψ_h)]``.

    Attributes
    ----------
    orders
        The orders ``h``.
    fractions
        ``d_h``: each order's amplitude over the fundamental's.
    phases_rad
        ``ψ_h`` (rad).
    """

    orders: tuple[int, ...] = ()
    fractions: tuple[float, ...] = ()
    phases_rad: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if not len(self.orders) == len(self.fractions) == len(self.phases_rad):
            raise ValueError("orders, fractions and phases_rad need one value per order")
        if any(h < 2 for h in self.orders):
            raise ValueError(f"distortion orders must be ≥ 2, got {self.orders}")

    def shape(self, theta: np.ndarray | float) -> np.ndarray | float:
        """``sin θ + Σ_h d_h sin(hθ + ψ_h)``: the base acceleration per unit ``A``."""
        out = np.sin(theta)
        for h, d, psi in zip(self.orders, self.fractions, self.phases_rad, strict=True):
            out = out + d * np.sin(h * theta + psi)
        return out


#: A shaker without distortion.
PURE_SINE = ShakerDistortion()


@dataclass(frozen=True)
class ModalResonance:
    """Phase-resonance points of one locked mode, one per amplitude.

    Attributes
    ----------
    mode
        The locked mode (from 1).
    amplitude_m
        Its fundamental amplitude ``a`` (m of its coordinate).
    frequency_hz
        ``ω/2π``.
    damping_ratio
        ``Γ_L A / (2 ω² a)``.
    base_acceleration_m_s2
        ``A``.
    participation
        ``(n_amp, n_modes, H)`` complex ``P_k`` of harmonics ``k = 1..H`` of every mode (m).
    mean_m
        ``(n_amp, n_modes)`` every mode's mean ``C_0`` (m).
    converged
        Whether the balance met its tolerance; NaN elsewhere.
    """

    mode: int
    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    base_acceleration_m_s2: np.ndarray
    participation: np.ndarray
    mean_m: np.ndarray
    converged: np.ndarray


class _Balance:
    """Residual of the balance; unknowns ``z`` (scaled by ``a``, ``ω_L``, ``ω_L² a``):
    per mode ``[C0, C1, S1, …, CH, SH]/a`` with the locked mode's ``C1, S1`` replaced by
    ``ω/ω_L`` and ``A/(ω_L² a)``."""

    def __init__(self, system: ModalSystem, participation: np.ndarray, mode: int,
                 distortion: ShakerDistortion, harmonics: int, samples: int) -> None:  # fmt: skip
        self.system, self.locked, self.h = system, mode - 1, harmonics
        self.n = len(system.frequencies_hz)
        self.w = system.omega_rad_s
        self.zeta = np.asarray(system.damping_ratios, dtype=float)
        self.phi = np.asarray(system.joint_shape, dtype=float)
        self.gamma = participation
        self.terms = [t for t in system.joint_terms if not t.hysteretic]
        if len(self.terms) != len(system.joint_terms):
            raise ValueError("the modal phase-resonance balance takes memoryless joint terms only")
        self.theta = 2 * np.pi * np.arange(samples) / samples
        self.m = samples
        self.k = np.arange(1, harmonics + 1)
        # The base shape's spectrum per unit A: [mean, (cos, sin) of each order].
        spectrum = np.fft.rfft(distortion.shape(self.theta)) * (2.0 / samples)
        self.base = np.zeros(2 * harmonics + 1)
        self.base[1::2] = spectrum[1 : harmonics + 1].real
        self.base[2::2] = -spectrum[1 : harmonics + 1].imag
        self.wl = self.w[self.locked]

    def coefficients(self, z: np.ndarray, a: float) -> tuple[np.ndarray, float, float]:
        """Fourier coefficients ``(n, 2H+1)`` (m), ``ω`` and ``A`` of unknowns ``z``."""
        c = z.reshape(self.n, 2 * self.h + 1) * a
        omega, big_a = c[self.locked, 1] / a * self.wl, c[self.locked, 2] / a * self.wl**2 * a
        c = c.copy()
        c[self.locked, 1], c[self.locked, 2] = a, 0.0
        return c, omega, big_a

    def time_series(self, c: np.ndarray, omega: float) -> tuple[np.ndarray, np.ndarray]:
        """Every mode's displacement and velocity at the samples ``(n, M)``."""
        cos = np.cos(np.outer(self.k, self.theta))
        sin = np.sin(np.outer(self.k, self.theta))
        q = c[:, :1] + c[:, 1::2] @ cos + c[:, 2::2] @ sin
        v = omega * ((self.k * c[:, 2::2]) @ cos - (self.k * c[:, 1::2]) @ sin)
        return q, v

    def __call__(self, z: np.ndarray, a: float) -> np.ndarray:
        c, omega, big_a = self.coefficients(z, a)
        q, v = self.time_series(c, omega)
        force = np.zeros_like(q)
        if self.terms:
            u, udot = self.phi @ q, self.phi @ v
            joint = sum(t.force(u, udot) for t in self.terms)
            force += self.phi[:, None] * joint
        for coupling in self.system.couplings:
            force += coupling.forces(q)
        spectrum = np.fft.rfft(force, axis=1) * (2.0 / self.m)
        nonlinear = np.zeros_like(c)
        nonlinear[:, 0] = 0.5 * spectrum[:, 0].real
        nonlinear[:, 1::2] = spectrum[:, 1 : self.h + 1].real
        nonlinear[:, 2::2] = -spectrum[:, 1 : self.h + 1].imag
        kw = self.k * omega
        w2, cw = self.w[:, None] ** 2, (2 * self.zeta * self.w)[:, None]
        residual = np.empty_like(c)
        residual[:, 0] = self.w**2 * c[:, 0]
        cc, ss = c[:, 1::2], c[:, 2::2]
        residual[:, 1::2] = (w2 - kw**2) * cc + cw * kw * ss
        residual[:, 2::2] = (w2 - kw**2) * ss - cw * kw * cc
        residual += nonlinear + self.gamma[:, None] * big_a * self.base
        return residual.ravel() / (self.wl**2 * a)

    def start(self, a: float) -> np.ndarray:
        """The linear resonance of the locked mode, the other modes at rest."""
        z = np.zeros((self.n, 2 * self.h + 1))
        z[self.locked, 1] = 1.0
        z[self.locked, 2] = 2 * self.zeta[self.locked] / self.gamma[self.locked]
        return z.ravel()


def modal_phase_resonance(
    system: ModalSystem,
    mode: int,
    amplitudes_m: ArrayLike,
    participation: Sequence[float] | None = None,
    distortion: ShakerDistortion = PURE_SINE,
    *,
    harmonics: int = 6,
    samples: int = 64,
    tol: float = 1e-12,
) -> ModalResonance:
    """The phase-resonance backbone of ``mode`` (from 1) of a base-driven ``system``.

    Parameters
    ----------
    system
        The modes, their joint (memoryless terms) and modal potential.
    mode
        The locked mode.
    amplitudes_m
        Fundamental amplitudes of the locked coordinate (m), > 0, solved in the given order
        (each from the previous solution: give them increasing).
    participation
        ``Γ_i``: each mode's base participation (default 1 for every mode).
    distortion
        The base acceleration's orders ``h ≥ 2`` (default a pure sine).
    harmonics, samples
        Harmonics ``H`` of the balance and samples per period of its forces.
    tol
        The residual (over ``ω_L² a``) the solution must meet.

    Returns
    -------
    ModalResonance
    """
    n = len(system.frequencies_hz)
    if not 1 <= mode <= n:
        raise ValueError(f"mode must be 1..{n}, got {mode}")
    gamma = np.ones(n) if participation is None else np.asarray(participation, dtype=float)
    a_all = np.atleast_1d(np.asarray(amplitudes_m, dtype=float))
    if not np.all(a_all > 0):
        raise ValueError("amplitudes_m must be > 0")
    balance = _Balance(system, gamma, mode, distortion, harmonics, samples)
    z = balance.start(a_all[0])
    rows = []
    for a in a_all:
        solution = root(balance, z, args=(a,), method="hybr", options={"xtol": 1e-13})
        ok = bool(np.max(np.abs(balance(solution.x, a))) < tol)
        if ok:
            z = solution.x
        c, omega, big_a = balance.coefficients(solution.x, a)
        rows.append((omega, big_a, c[:, 1::2] - 1j * c[:, 2::2], c[:, 0], ok))
    omega = np.array([r[0] for r in rows])
    big_a = np.array([r[1] for r in rows])
    converged = np.array([r[4] for r in rows])
    participation_m = np.array([r[2] for r in rows])
    mean_m = np.array([r[3] for r in rows])
    for values in (omega, big_a, participation_m, mean_m):
        values[~converged] = np.nan
    return ModalResonance(
        mode=mode,
        amplitude_m=a_all,
        frequency_hz=omega / (2 * np.pi),
        damping_ratio=gamma[mode - 1] * big_a / (2 * omega**2 * a_all),
        base_acceleration_m_s2=big_a,
        participation=participation_m,
        mean_m=mean_m,
        converged=converged,
    )
