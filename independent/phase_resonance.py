"""The phase-resonance backbone of a base-excited joint, by a harmonic balance of its own.

The joint (:class:`~independent.forces.JointSpec`) is ``ẍ + f(x, ẋ) = −a_base(t)`` with ``x``
relative to the base. A backbone point at amplitude ``a`` is the steady periodic state whose
fundamental is ``a cos θ`` (``θ = ωt``) while the base acceleration is ``A sin θ``: the
displacement lags the effective force ``−a_base`` by 90°, the condition a phase-locked loop
holds. What a test's hold fit reads from that state, as the library defines its channels:

* the frequency ``ω/2π`` (Hz);
* the damping ratio of the fundamental's power balance, ``D = |Q_b| / (2|Q|)`` with the base
  displacement ``|Q_b| = A/ω²`` and ``|Q| = a``: ``D = A / (2 ω² a)`` — for a linear viscous
  joint exactly ``ζ``, for any joint the energy it dissipates per cycle over ``2π ω² a²``;
* the harmonics ``h = 2..H`` of the relative displacement, ``x = a cos θ + Σ_h (C_h cos hθ +
  S_h sin hθ)``, as ``(C_h − i S_h) / a``, and the mean offset.

Method: the periodic state is written as a Fourier series of ``H`` harmonics (default 12),
sampled at ``N`` points per period; the force is evaluated on the samples (a hysteretic
force marched period after period until its loop closes) and projected by the FFT;
Broyden's method from a forward-difference Jacobian, with backtracking Newton steps where it
stalls, solves the balance of the mean, the fundamental's cosine (which fixes ``ω``) and every
higher harmonic, while the fundamental's sine gives ``A``. All cases (joints × amplitudes)
are solved at once as arrays, started from the fundamental-only balance at each amplitude.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from independent.forces import JointSpec, stacked

__all__ = [
    "DEFAULT_BALANCE",
    "BalanceSettings",
    "PhaseResonanceBackbone",
    "phase_resonance_backbone",
]

#: Forward-difference step of the Jacobian, in the unknowns' units (fractions of ``a``, of ω0).
_STEP = 1e-7


@dataclass(frozen=True)
class BalanceSettings:
    """Settings of the harmonic balance.

    Attributes
    ----------
    harmonics
        Highest harmonic ``H`` of the periodic state.
    samples_per_period
        ``N`` samples of the force per period; None: 128 for smooth joints, 512 where a
        term has a kink, jump or hysteresis (their projections converge like ``1/N²``).
    tol
        Converged when every balance residual is below ``tol · ω0² a``.
    max_iter
        Newton iterations before a case is declared not converged.
    """

    harmonics: int = 12
    samples_per_period: int | None = None
    tol: float = 1e-10
    max_iter: int = 60

    def samples(self, smooth: bool) -> int:
        """Samples per period for a joint that is smooth (or not)."""
        if self.samples_per_period is not None:
            n = self.samples_per_period
        else:
            n = 128 if smooth else 512
        if n < 2 * self.harmonics + 2:
            raise ValueError(f"samples_per_period must exceed 2·harmonics + 1, got {n}")
        return n


#: The settings every caller gets unless it says otherwise.
DEFAULT_BALANCE = BalanceSettings()


@dataclass(frozen=True)
class PhaseResonanceBackbone:
    """Phase-resonance backbones, one row per joint, one column per amplitude.

    Attributes
    ----------
    amplitude_m
        Fundamental amplitude ``a`` of the relative displacement (m).
    frequency_hz
        Phase-resonance frequency (Hz).
    damping_ratio
        ``A / (2 ω² a)``, the fundamental's power balance (signed).
    base_acceleration_m_s2
        Fundamental amplitude ``A`` of the base acceleration that holds the point (m/s²).
    harmonics
        ``(..., H − 1)`` complex ``(C_h − i S_h)/a`` of orders ``h = 2..H``.
    mean_offset_m
        Mean of the relative displacement (m).
    converged
        False where Newton's method did not meet the tolerance; the numbers there are NaN.
    """

    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    base_acceleration_m_s2: np.ndarray
    harmonics: np.ndarray
    mean_offset_m: np.ndarray
    converged: np.ndarray


class _Balance:
    """The balance residual of many cases: rows are cases, unknowns
    ``z = [X0/a, ω/ω0, C_2/a, S_2/a, …, C_H/a, S_H/a]``."""

    def __init__(self, joint: JointSpec, a: np.ndarray, harmonics: int, n: int) -> None:
        self.joint, self.a, self.n = joint, a[:, None, None], n
        self.w0 = np.asarray(joint.omega0_rad_s, dtype=float).reshape(-1, 1, 1)
        theta = 2 * np.pi * np.arange(n) / n
        orders = np.arange(2, harmonics + 1)
        self.orders = orders
        self.cos1, self.sin1 = np.cos(theta), np.sin(theta)
        self.cos_h = np.cos(orders[:, None] * theta)
        self.sin_h = np.sin(orders[:, None] * theta)

    def __call__(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Residuals ``(rows, k, 2H)`` (over ``ω0² a``) and ``A`` ``(rows, k)`` at unknowns
        ``z`` ``(rows, k, 2H)``."""
        a, w0, h = self.a, self.w0, self.orders
        c, s = z[..., 2::2], z[..., 3::2]
        omega = z[..., 1:2] * w0
        x = a * (z[..., :1] + self.cos1 + c @ self.cos_h + s @ self.sin_h)
        v = a * omega * (-self.sin1 + (h * s) @ self.cos_h - (h * c) @ self.sin_h)
        force = self.joint.periodic_force(x, v)
        spectrum = np.fft.rfft(force, axis=-1) * (2.0 / self.n)
        scale = w0[..., 0] ** 2 * a[..., 0]
        w2 = (omega[..., 0] / w0[..., 0]) ** 2
        residual = np.empty(z.shape)
        residual[..., 0] = 0.5 * spectrum[..., 0].real / scale
        residual[..., 1] = spectrum[..., 1].real / scale - w2
        residual[..., 2::2] = spectrum[..., h].real / scale[..., None] - h**2 * w2[..., None] * c
        residual[..., 3::2] = -spectrum[..., h].imag / scale[..., None] - h**2 * w2[..., None] * s
        return residual, spectrum[..., 1].imag  # A = −F_s1 = +Im of the projection

    def start(self, iterations: int = 12) -> np.ndarray:
        """The fundamental-only balance ``ω² a = F_c1(a cos θ, −aω sin θ)``, by fixed point."""
        z = np.zeros((self.a.shape[0], 1, 2 * self.orders.size + 2))
        z[..., 1] = 1.0
        for _ in range(iterations):
            residual, _ = self(z)
            with np.errstate(invalid="ignore"):
                z[..., 1] = np.sqrt(z[..., 1] ** 2 + residual[..., 1])
        return z[:, 0]


def _jacobian(balance: _Balance, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residual ``(rows, m)`` and its forward-difference Jacobian ``(rows, m, m)`` at ``z``."""
    m = z.shape[1]
    steps = np.concatenate([np.zeros((1, m)), _STEP * np.eye(m)])
    probe, _ = balance(z[:, None, :] + steps)
    return probe[:, 0], np.swapaxes((probe[:, 1:] - probe[:, :1]) / _STEP, 1, 2)


def _solve(jacobian: np.ndarray, residual: np.ndarray) -> np.ndarray:
    """Newton steps ``−J⁻¹ r`` of every case (least squares where ``J`` is singular)."""
    with np.errstate(all="ignore"):
        try:
            return -np.linalg.solve(jacobian, residual[..., None])[..., 0]
        except np.linalg.LinAlgError:
            return -(np.linalg.pinv(jacobian) @ residual[..., None])[..., 0]


def _newton(balance: _Balance, settings: BalanceSettings) -> tuple[np.ndarray, np.ndarray, ...]:
    """Unknowns, ``A`` and convergence of every case, all cases together.

    Broyden's method from a forward-difference Jacobian: each iteration costs one residual,
    and a case whose residual does not fall gets a fresh Jacobian and a backtracking Newton step
    (halved until it falls).
    """
    z = balance.start()
    residual, jacobian = _jacobian(balance, z)
    norm = np.max(np.abs(residual), axis=-1)
    fresh = True
    for _ in range(settings.max_iter):
        active = (norm >= settings.tol) & np.isfinite(norm)
        if not active.any():
            break
        dz = np.where(active[:, None], _solve(jacobian, residual), 0.0)
        alpha = np.ones(z.shape[0])
        for _ in range(12 if fresh else 1):  # halve the step of cases whose residual grew
            trial = z + alpha[:, None] * dz
            trial_residual, _ = balance(trial[:, None])
            trial_residual = trial_residual[:, 0]
            trial_norm = np.max(np.abs(trial_residual), axis=-1)
            better = (trial_norm < norm) | ~active
            if better.all():
                break
            alpha = np.where(better, alpha, 0.5 * alpha)
        # Broyden's rank-one update on the accepted step: J += (Δr − J Δz) Δzᵀ / |Δz|².
        step = trial - z
        with np.errstate(all="ignore"):
            update = (trial_residual - residual - (jacobian @ step[..., None])[..., 0])[
                ..., None
            ] * (step / np.sum(step * step, axis=-1, keepdims=True))[:, None, :]
        take = better & active
        jacobian = np.where(take[:, None, None], jacobian + update, jacobian)
        z = np.where(better[:, None], trial, z)
        residual = np.where(better[:, None], trial_residual, residual)
        norm = np.where(better, trial_norm, norm)
        if better.all():
            fresh = False
        elif fresh and not take.any():
            break  # no case moves even on a fresh Jacobian
        else:
            residual, jacobian = _jacobian(balance, z)
            fresh = True
    converged = norm < settings.tol
    _, base = balance(z[:, None])
    return z, base[:, 0], converged


def phase_resonance_backbone(
    joints: JointSpec | Sequence[JointSpec],
    amplitudes_m: ArrayLike,
    settings: BalanceSettings = DEFAULT_BALANCE,
) -> PhaseResonanceBackbone:
    """Phase-resonance backbones of ``joints`` at the given fundamental amplitudes.

    Parameters
    ----------
    joints
        One joint, or several with the same kinds of terms (solved together as arrays).
    amplitudes_m
        Fundamental amplitudes of the relative displacement (m), > 0: ``(n_amp,)`` shared by
        every joint, or ``(n_joints, n_amp)``.
    settings
        Harmonics, samples and tolerance of the balance.

    Returns
    -------
    PhaseResonanceBackbone
        Arrays ``(n_joints, n_amp)`` (``(n_amp,)`` for one joint given alone).
    """
    single = isinstance(joints, JointSpec)
    joints = [joints] if single else list(joints)
    a = np.asarray(amplitudes_m, dtype=float)
    a = np.broadcast_to(a, (len(joints), a.shape[-1])) if a.ndim == 1 else a
    if a.shape[0] != len(joints) or not np.all(a > 0):
        raise ValueError(f"amplitudes_m must be > 0, (n_amp,) or ({len(joints)}, n_amp)")
    rows = [j for j in joints for _ in range(a.shape[1])]
    joint = stacked(rows, (-1, 1, 1))
    n = settings.samples(joint.smooth)
    balance = _Balance(joint, a.reshape(-1), settings.harmonics, n)
    z, base, converged = _newton(balance, settings)
    z[~converged] = np.nan
    base[~converged] = np.nan
    omega = z[:, 1] * balance.w0[:, 0, 0]
    flat = a.reshape(-1)
    shape = a.shape
    result = PhaseResonanceBackbone(
        amplitude_m=a.copy(),
        frequency_hz=(omega / (2 * np.pi)).reshape(shape),
        damping_ratio=(base / (2 * omega**2 * flat)).reshape(shape),
        base_acceleration_m_s2=base.reshape(shape),
        harmonics=(z[:, 2::2] - 1j * z[:, 3::2]).reshape(*shape, -1),
        mean_offset_m=(z[:, 0] * flat).reshape(shape),
        converged=converged.reshape(shape),
    )
    if single:
        return PhaseResonanceBackbone(*(getattr(result, f)[0] for f in result.__dataclass_fields__))
    return result
