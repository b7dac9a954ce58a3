"""Ring-downs and forced steady states: scipy's DOP853 on forces written as plain Python.

Tests that check pm-joint's extraction, identification or criticism need data that the code under
test did not make. This module shares nothing with pm-joint (no catalogue kernels, no numba, no
harmonic balance): forces are Python callables of ``(x, v)`` written in each test, or the forces
of :mod:`independent.forces`, and the equations are integrated by
:func:`scipy.integrate.solve_ivp`, then sampled as a data acquisition would (fixed rate).

One mode: :func:`free_decay`, :func:`forced_steady_state`, and the field's Hilbert backbone of
a decay (:func:`hilbert_backbone`). Several modes (:class:`ModalSystem`,
:func:`modal_free_decay`): mass-normalised modal oscillators coupled through joint forces on a
physical joint coordinate and through a polynomial modal potential, seen by sensors through
their mode shapes; :func:`modal_backbones` gives each mode's decay backbone from its true modal
coordinate, the reference a modal filter's estimate is compared with.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.integrate import solve_ivp

from independent.forces import Force as JointForce

__all__ = [
    "DecayBackbone",
    "ModalDecay",
    "ModalSystem",
    "PotentialTerm",
    "forced_steady_state",
    "free_decay",
    "hilbert_backbone",
    "modal_backbones",
    "modal_free_decay",
    "rounded_time_stamps",
]

Force = Callable[[float, float], float]


def free_decay(
    force: Force,
    x0_m: float,
    v0_m_s: float,
    *,
    fs_hz: float = 10_000.0,
    duration_s: float = 1.0,
    rtol: float = 1e-10,
) -> dict[str, np.ndarray]:
    """Ring-down of ``ẍ + force(x, ẋ) = 0`` from ``(x0, v0)``, sampled at ``fs_hz``.

    Returns the time (s), displacement (m), velocity (m/s) and acceleration (m/s²), the last
    from the equation of motion (not from differencing).
    """

    def rhs(_, state):
        x, v = state
        return [v, -force(x, v)]

    t = np.arange(round(duration_s * fs_hz)) / fs_hz
    solution = solve_ivp(
        rhs, (0.0, t[-1]), [x0_m, v0_m_s], method="DOP853", t_eval=t, rtol=rtol, atol=1e-14
    )
    if not solution.success:
        raise RuntimeError(f"free decay did not integrate: {solution.message}")
    x, v = solution.y
    a = -np.array([force(xi, vi) for xi, vi in zip(x, v, strict=True)])
    return {"time_s": t, "displacement_m": x, "velocity_m_s": v, "acceleration_m_s2": a}


def forced_steady_state(
    force: Force,
    excitation: Callable[[float], float],
    period_s: float,
    *,
    fs_hz: float = 10_000.0,
    settle_periods: int = 400,
    record_periods: int = 50,
    rtol: float = 1e-10,
) -> dict[str, np.ndarray]:
    """Steady response of ``ẍ + force(x, ẋ) = excitation(t)`` after ``settle_periods`` periods.

    The last ``record_periods`` periods are sampled at ``fs_hz`` (time restarts at 0 there).
    The caller makes sure the transient has died out (light damping needs many periods).
    """

    def rhs(t, state):
        x, v = state
        return [v, excitation(t) - force(x, v)]

    t_settle = settle_periods * period_s
    first = solve_ivp(rhs, (0.0, t_settle), [0.0, 0.0], method="DOP853", rtol=rtol, atol=1e-14)
    if not first.success:
        raise RuntimeError(f"settling did not integrate: {first.message}")
    n = round(record_periods * period_s * fs_hz)
    t = t_settle + np.arange(n) / fs_hz
    second = solve_ivp(
        rhs, (t_settle, t[-1]), first.y[:, -1], method="DOP853", t_eval=t, rtol=rtol, atol=1e-14
    )
    if not second.success:
        raise RuntimeError(f"recording did not integrate: {second.message}")
    x, v = second.y
    return {
        "time_s": t - t_settle,
        "displacement_m": x,
        "velocity_m_s": v,
        "excitation": np.array([excitation(ti) for ti in t]),
    }


def hilbert_backbone(
    time_s: np.ndarray, displacement_m: np.ndarray, band_hz: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """The field's model-free backbone of a free decay: the Hilbert transform of its fundamental.

    The fundamental is band-passed (4th-order Butterworth, zero phase), its analytic signal
    (:func:`scipy.signal.hilbert`) gives the instantaneous amplitude and frequency, both averaged
    over a period; ten periods at each end (the filter's and the transform's end effects) are
    dropped. Returns the amplitude (m) and frequency (Hz), in time order.
    """
    _, amplitude, frequency = _hilbert(time_s, displacement_m, band_hz)
    return amplitude, frequency


def _hilbert(
    time_s: np.ndarray, displacement_m: np.ndarray, band_hz: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`hilbert_backbone` with the times of its samples first."""
    from scipy import signal

    fs_hz = (time_s.size - 1) / (time_s[-1] - time_s[0])
    sos = signal.butter(4, band_hz, btype="bandpass", fs=fs_hz, output="sos")
    analytic = signal.hilbert(signal.sosfiltfilt(sos, displacement_m))
    frequency = np.gradient(np.unwrap(np.angle(analytic)), time_s) / (2 * np.pi)
    period = round(fs_hz / np.median(frequency))
    kernel = np.ones(period) / period
    amplitude = np.convolve(np.abs(analytic), kernel, mode="same")
    frequency = np.convolve(frequency, kernel, mode="same")
    inside = slice(10 * period, -10 * period)
    return time_s[inside], amplitude[inside], frequency[inside]


# ---------------------------------------------------------------------------
# Several modes


@dataclass(frozen=True)
class PotentialTerm:
    """One monomial of the modal potential, ``V = c Π_i q_i^{p_i}`` (per unit modal mass).

    Mode ``i`` feels ``∂V/∂q_i``. ``PotentialTerm(c, (2, 1))`` is the ``c q1² q2`` coupling of
    a 1:2 internal resonance (forces ``2c q1 q2`` on mode 1, ``c q1²`` on mode 2);
    ``(4, 0)`` a cubic spring of mode 1 (``4c q1³``); ``(2, 2)`` a cubic coupling.
    """

    coefficient: float
    powers: tuple[int, ...]

    def forces(self, q: np.ndarray) -> np.ndarray:
        """``∂V/∂q_i`` of every mode at modal coordinates ``q`` (first axis: modes)."""
        out = np.zeros(q.shape)
        for i, p in enumerate(self.powers):
            if p:
                term = self.coefficient * p
                for j, e in enumerate(self.powers):
                    if e - (j == i):
                        term = term * q[j] ** (e - (j == i))
                out[i] = term
        return out

    def energy(self, q: np.ndarray) -> np.ndarray:
        """``V`` at modal coordinates ``q`` (first axis: modes)."""
        return self.coefficient * np.prod([q[j] ** e for j, e in enumerate(self.powers)], axis=0)


@dataclass(frozen=True)
class ModalSystem:
    """Mass-normalised modes coupled through a joint and a modal potential:

    ``q̈_i + 2 ζ_i ω_i q̇_i + ω_i² q_i + φ_i Σ_k f_k(u, u̇) + ∂V/∂q_i = 0``, ``u = Σ_i φ_i q_i``

    Attributes
    ----------
    frequencies_hz
        Linear natural frequency ``ω_i/2π`` of each mode (Hz).
    damping_ratios
        Viscous damping ratio ``ζ_i`` of each mode.
    joint_shape
        ``φ_i``: each mode's shape at the joint coordinate ``u`` (the joint's relative
        displacement, m, per unit modal coordinate).
    joint_terms
        Forces of :mod:`independent.forces` acting on ``u``, memoryless or hysteretic.
    couplings
        Monomials of the modal potential ``V``.
    """

    frequencies_hz: tuple[float, ...]
    damping_ratios: tuple[float, ...]
    joint_shape: tuple[float, ...] | None = None
    joint_terms: tuple[JointForce, ...] = ()
    couplings: tuple[PotentialTerm, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.frequencies_hz)
        shape = (0.0,) * n if self.joint_shape is None else tuple(self.joint_shape)
        object.__setattr__(self, "joint_shape", shape)
        if len(self.damping_ratios) != n or len(shape) != n:
            raise ValueError("frequencies_hz, damping_ratios and joint_shape need a value per mode")
        if any(len(c.powers) != n for c in self.couplings):
            raise ValueError(f"every coupling needs {n} powers, one per mode")

    @property
    def omega_rad_s(self) -> np.ndarray:
        """Linear natural angular frequencies (rad/s)."""
        return 2 * np.pi * np.asarray(self.frequencies_hz, dtype=float)

    def energy(self, q: np.ndarray, qdot: np.ndarray) -> np.ndarray:
        """Kinetic plus potential energy of the modes and couplings (joint terms left out)."""
        w = self.omega_rad_s[:, None]
        total = 0.5 * np.sum(qdot**2 + (w * q) ** 2, axis=0)
        return total + sum((c.energy(q) for c in self.couplings), np.zeros(q.shape[1:]))


@dataclass(frozen=True)
class ModalDecay:
    """A sampled ring-down of a :class:`ModalSystem`.

    Attributes
    ----------
    time_s
        Sample times (s); rounded as an export writes them where asked
        (:func:`rounded_time_stamps`), the samples themselves being at the exact times.
    modal_displacement, modal_velocity, modal_acceleration
        ``(n_modes, n_t)`` modal coordinates and their derivatives (the last from the
        equation of motion).
    displacement_m, velocity_m_s, acceleration_m_s2
        ``(n_sensors, n_t)``: the sensors' mode shapes times the modal coordinates.
    """

    time_s: np.ndarray
    modal_displacement: np.ndarray
    modal_velocity: np.ndarray
    modal_acceleration: np.ndarray
    displacement_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray


def rounded_time_stamps(time_s: ArrayLike, significant_digits: int = 7) -> np.ndarray:
    """Times as a text export with ``significant_digits`` digits writes them."""
    return np.array([float(f"{t:.{significant_digits - 1}e}") for t in np.asarray(time_s)])


def modal_free_decay(
    system: ModalSystem,
    q0: Sequence[float],
    qdot0: Sequence[float] | None = None,
    *,
    sensor_shapes: ArrayLike | None = None,
    fs_hz: float = 10_000.0,
    duration_s: float = 1.0,
    time_digits: int | None = None,
    rtol: float = 1e-10,
) -> ModalDecay:
    """Ring-down of ``system`` from modal displacements ``q0`` and velocities ``qdot0``.

    Parameters
    ----------
    system
        The modes, their joint and couplings.
    q0, qdot0
        Initial modal coordinates and velocities (default at rest).
    sensor_shapes
        ``(n_sensors, n_modes)`` mode shapes at the sensors; default one sensor per mode
        that sees that mode alone.
    fs_hz, duration_s
        Sampling rate and length of the record.
    time_digits
        Significant digits of the written time stamps (e.g. 7), or None for exact times.
    rtol
        DOP853's relative tolerance (absolute: ``1e-6·rtol`` of the largest initial value).

    Returns
    -------
    ModalDecay
        Hysteretic joint terms start unstressed at the initial joint displacement.
    """
    n = len(system.frequencies_hz)
    q0 = np.asarray(q0, dtype=float)
    qdot0 = np.zeros(n) if qdot0 is None else np.asarray(qdot0, dtype=float)
    shapes = np.eye(n) if sensor_shapes is None else np.atleast_2d(np.asarray(sensor_shapes, float))
    w = system.omega_rad_s
    stiffness, damping = w**2, 2 * np.asarray(system.damping_ratios) * w
    phi = np.asarray(system.joint_shape, dtype=float)
    hysteretic = [t for t in system.joint_terms if t.hysteretic]
    memoryless = [t for t in system.joint_terms if not t.hysteretic]
    sizes = [t.sliders()[0].size for t in hysteretic]
    bounds = np.cumsum([2 * n, *sizes])

    def accelerations(q, qdot, sliders):
        """Modal accelerations (modes first); ``sliders`` with the elements on the last axis."""
        column = (slice(None),) + (None,) * (q.ndim - 1)
        acc = -stiffness[column] * q - damping[column] * qdot
        if system.joint_terms:
            u, udot = phi @ q, phi @ qdot
            joint = 0.0
            for term in memoryless:
                joint = joint + term.force(u, udot)
            for term, state in zip(hysteretic, sliders, strict=True):
                joint = joint + term.from_state(state)
            acc -= phi[column] * joint
        for coupling in system.couplings:
            acc -= coupling.forces(q)
        return acc

    def rhs(_, y):
        q, qdot = y[:n], y[n : 2 * n]
        if not hysteretic:
            return np.concatenate([qdot, accelerations(q, qdot, ())])
        sliders = [y[a:b] for a, b in itertools.pairwise(bounds)]
        udot = np.asarray(phi @ qdot)
        rates = [t.rate(s, udot) for t, s in zip(hysteretic, sliders, strict=True)]
        return np.concatenate([qdot, accelerations(q, qdot, sliders), *rates])

    start_sliders = [np.zeros(size) for size in sizes]
    scale = max(np.max(np.abs(q0)), np.max(np.abs(qdot0)) / w.max())
    t = np.arange(round(duration_s * fs_hz)) / fs_hz
    solution = solve_ivp(
        rhs, (0.0, t[-1]), np.concatenate([q0, qdot0, *start_sliders]), method="DOP853",
        t_eval=t, rtol=rtol, atol=1e-6 * rtol * scale,
    )  # fmt: skip
    if not solution.success:
        raise RuntimeError(f"modal decay did not integrate: {solution.message}")
    q, qdot = solution.y[:n], solution.y[n : 2 * n]
    sliders = [solution.y[a:b] for a, b in itertools.pairwise(bounds)]
    qddot = accelerations(q, qdot, [s.T for s in sliders])
    return ModalDecay(
        time_s=t if time_digits is None else rounded_time_stamps(t, time_digits),
        modal_displacement=q,
        modal_velocity=qdot,
        modal_acceleration=qddot,
        displacement_m=shapes @ q,
        velocity_m_s=shapes @ qdot,
        acceleration_m_s2=shapes @ qddot,
    )


@dataclass(frozen=True)
class DecayBackbone:
    """One mode's backbone from a ring-down: the instantaneous amplitude (m of modal
    coordinate), frequency (Hz) and damping ratio ``−(d ln A/dt)/ω`` in time order."""

    time_s: np.ndarray
    amplitude: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray


def modal_backbones(
    decay: ModalDecay, bands_hz: Sequence[tuple[float, float]]
) -> list[DecayBackbone]:
    """Each mode's decay backbone from its true modal coordinate (:func:`hilbert_backbone` on
    the mode's band, ``bands_hz[i]`` for mode ``i``), the damping ratio from the envelope's
    logarithmic decrement per radian.

    This is the reference this package offers for a mode's backbone of a ring-down: what a
    modal filter with exact mode shapes and a Hilbert transform would read. Near an internal
    resonance a mode's band also holds the other mode's locked harmonic (2ω1 in mode 2's
    band at 1:2): that content is part of mode 2's coordinate here, as it is of its filter.
    """
    out = []
    exact_time = np.arange(decay.time_s.size) * np.median(np.diff(decay.time_s))
    for q, band in zip(decay.modal_displacement, bands_hz, strict=True):
        t, amplitude, frequency = _hilbert(exact_time, q, band)
        rate = np.gradient(np.log(amplitude), t)
        out.append(DecayBackbone(t, amplitude, frequency, -rate / (2 * np.pi * frequency)))
    return out
