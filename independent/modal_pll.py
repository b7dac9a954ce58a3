"""Phase-locked tests of a :class:`~independent.decays.ModalSystem`, written as TRC campaigns.

A test steps the shaker through levels; at each a phase-locked loop holds one mode at phase
resonance (its fundamental 90° behind the effective force ``−a_base``), and the sensors record
the hold. What is simulated, all in plain Python floats (no library code):

* **the structure**: the modal equations of :class:`~independent.decays.ModalSystem`, every
  mode driven by ``−Γ_i a_base(t)``, ``a_base = A(t) [sin φ + Σ_h d_h sin(hφ + ψ_h)]`` (the
  shaker's distortion, :class:`~independent.modal_resonance.ShakerDistortion`) with ``φ`` the
  loop's oscillator phase and ``A(t)`` the level schedule (linear ramps, then holds);
* **the loop**: the locked mode's coordinate (a modal filter with exact shapes in the loop)
  demodulated against the oscillator, ``I, Q`` low-passed (first order), the phase error
  ``e = atan2(−Q, I)`` (zero when the coordinate is ``a cos φ``) driving the oscillator's
  frequency through a PI law ``ω = ω_L + k_p e + k_i ∫e dt`` from the mode's linear frequency;
  the low-pass leaves a ripple at ``2ω`` in the frequency channel, as a lab loop does;
* **the lab**: white noise on every velocity channel (15 panel points, 2 base points), time
  stamps rounded to a number of significant digits, the shaker's distortion;
* **drift** (:class:`FrequencyDrift`, off by default): every mode's linear frequency moves by
  ``δ(t)``, linear in time over the campaign (temperature), by scaling its linear stiffness by
  ``(1 + δ)²`` with its viscous coefficient ``2ζω`` unchanged, as the library's rig drifts its
  modes; a record covers a stated part of its campaign.

The state (modal displacements and velocities, the base velocity, ``φ``, ``I``, ``Q``, ``∫e``)
is integrated by the classical fourth-order Runge–Kutta method on a fixed step, a fraction of
the sampling interval, as a digital controller runs at its sampling rate: scipy's DOP853 with a
Python right-hand side spends many times as long per simulated second, too long for campaigns
of holds of seconds in a test (``tests/test_modal_pll_acceptance.py`` checks the two agree on
the open loop).

:func:`write_trc_campaign` writes what the library reads: ``ConfigN_PRT_AssembA`` (time, 15
panel velocities, 2 base velocities, frequency channel, oscillator phase), the step file of the
levels and ``ConfigN_linear_complex_modes`` (the sensors' shapes, the linear frequencies).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from independent.decays import ModalSystem, rounded_time_stamps
from independent.modal_resonance import PURE_SINE, ShakerDistortion

__all__ = [
    "NO_DRIFT",
    "FrequencyDrift",
    "LabNoise",
    "LoopSettings",
    "PLLRecord",
    "pll_record",
    "write_trc_campaign",
]


@dataclass(frozen=True)
class LoopSettings:
    """The test's schedule and its phase-locked loop.

    Attributes
    ----------
    fs_hz
        Sampling rate of the record (Hz).
    substeps
        Runge–Kutta steps per sample.
    ramp_s, hold_s
        Each level's ramp from the previous one (the first from 0) and its hold (s).
    lowpass_hz
        Corner of the demodulator's first-order low-pass (Hz).
    kp_rad_s, ki_rad_s2
        The PI law's gains: rad/s and rad/s² of frequency per rad of phase error.
    """

    fs_hz: float = 5_000.0
    substeps: int = 2
    ramp_s: float = 0.3
    hold_s: float = 3.5
    lowpass_hz: float = 5.0
    kp_rad_s: float = 10.0
    ki_rad_s2: float = 25.0


@dataclass(frozen=True)
class LabNoise:
    """What the lab adds to a record.

    Attributes
    ----------
    velocity_m_s
        Standard deviation of white noise on every velocity channel (m/s).
    time_digits
        Significant digits of the written time stamps (None: exact).
    """

    velocity_m_s: float = 2e-5
    time_digits: int | None = 7


@dataclass(frozen=True)
class FrequencyDrift:
    """A slow change of every mode's linear frequency over a campaign (e.g. temperature).

    The modes' linear stiffnesses are scaled by ``(1 + δ(t))²``, their viscous coefficients
    ``2ζω`` kept: the drifted system at ``δ`` is the system with frequencies ``(1 + δ) f`` and
    damping ratios ``ζ / (1 + δ)``. ``δ`` grows linearly in time from 0 at the campaign's start
    to ``frequency_over_campaign`` at its end; a record covers ``record_span`` of it (fractions
    of the campaign at its first and last sample), linearly in its own time.

    Attributes
    ----------
    frequency_over_campaign
        The relative change of the linear frequencies over the campaign (0.005 is +0.5 %).
    record_span
        The part of the campaign (0…1) the record covers, from its start to its end.
    """

    frequency_over_campaign: float = 0.0
    record_span: tuple[float, float] = (0.0, 1.0)

    def __post_init__(self) -> None:
        size, (start, end) = self.frequency_over_campaign, self.record_span
        if not (math.isfinite(size) and size > -0.5):
            raise ValueError(f"frequency_over_campaign must be finite and > −0.5, got {size}")
        if not 0.0 <= start <= end <= 1.0:
            raise ValueError(f"record_span must be 0 ≤ start ≤ end ≤ 1, got {self.record_span}")

    def delta(self, record_fraction: float) -> float:
        """``δ`` at ``record_fraction`` (0…1) of the record's duration."""
        start, end = self.record_span
        return self.frequency_over_campaign * (start + (end - start) * record_fraction)


#: No drift: the modes keep their linear frequencies.
NO_DRIFT = FrequencyDrift()


@dataclass(frozen=True)
class PLLRecord:
    """One phase-locked test, sampled.

    Attributes
    ----------
    time_s
        Sample times (s), rounded as written where asked.
    panel_velocity_m_s
        ``(n, S)`` absolute velocities of the sensors (base plus the modes' motion, noise).
    base_velocity_m_s
        ``(n, 2)`` the two base points' velocities (noise on each).
    frequency_hz
        The oscillator's frequency (the loop's frequency channel).
    phase_deg
        The oscillator's phase in [0, 360).
    modal_displacement
        ``(n, N)`` the modal coordinates, noise-free.
    step_time_s, step_level
        The level schedule's breakpoints (level: base acceleration amplitude, m/s²).
    """

    time_s: np.ndarray
    panel_velocity_m_s: np.ndarray
    base_velocity_m_s: np.ndarray
    frequency_hz: np.ndarray
    phase_deg: np.ndarray
    modal_displacement: np.ndarray
    step_time_s: np.ndarray
    step_level: np.ndarray


def _schedule(levels: Sequence[float], settings: LoopSettings) -> tuple[np.ndarray, np.ndarray]:
    """Breakpoints of the level schedule: from 0, per level a ramp then a hold."""
    times, values, t = [0.0], [0.0], 0.0
    for level in levels:
        t += settings.ramp_s
        times.append(t)
        values.append(level)
        t += settings.hold_s
        times.append(t)
        values.append(level)
    return np.array(times), np.array(values)


class _Loop:
    """The closed loop's right-hand side in Python floats (its state documented in the module)."""

    def __init__(self, system: ModalSystem, participation: Sequence[float], mode: int,
                 distortion: ShakerDistortion, settings: LoopSettings,
                 schedule: tuple[np.ndarray, np.ndarray],
                 drift: FrequencyDrift = NO_DRIFT) -> None:  # fmt: skip
        self.n = len(system.frequencies_hz)
        w = [float(x) for x in system.omega_rad_s]
        self.k = [x * x for x in w]
        self.c = [2 * float(z) * x for z, x in zip(system.damping_ratios, w, strict=True)]
        self.phi = [float(x) for x in system.joint_shape]
        if any(t.hysteretic for t in system.joint_terms):
            raise ValueError("the PLL simulator takes memoryless joint terms only")
        self.joint = list(system.joint_terms)
        # Each coupling's force on mode i: c·p_i·Π_j q_j^(p_j − [j = i]).
        self.couplings = [
            (i, c.coefficient * p, [e - (j == i) for j, e in enumerate(c.powers)])
            for c in system.couplings
            for i, p in enumerate(c.powers)
            if p
        ]
        self.gamma = [float(g) for g in participation]
        self.locked = mode - 1
        self.w_start = w[self.locked]
        self.distortion = list(
            zip(distortion.orders, distortion.fractions, distortion.phases_rad, strict=True)
        )
        self.wf = 2 * math.pi * settings.lowpass_hz
        self.kp, self.ki = settings.kp_rad_s, settings.ki_rad_s2
        self.t_break = [float(x) for x in schedule[0]]
        self.levels = [float(x) for x in schedule[1]]
        self.segment = 0
        # δ(t) = δ0 + (δ1 − δ0) t / t_end over the schedule; off, the stiffness scale is 1.0
        # exactly and the record is the undrifted one bit for bit.
        self.delta0 = drift.delta(0.0)
        duration = self.t_break[-1]
        self.delta_rate = (drift.delta(1.0) - self.delta0) / duration if duration > 0 else 0.0

    def level(self, t: float) -> float:
        """The schedule's level at ``t`` (linear between breakpoints); times only go forward."""
        tb = self.t_break
        while self.segment < len(tb) - 2 and t > tb[self.segment + 1]:
            self.segment += 1
        i = self.segment
        if t >= tb[-1]:
            return self.levels[-1]
        f = (t - tb[i]) / (tb[i + 1] - tb[i])
        return self.levels[i] + f * (self.levels[i + 1] - self.levels[i])

    def frequency(self, y: list[float]) -> tuple[float, float]:
        """The oscillator's angular frequency and the phase error in state ``y``."""
        n = self.n
        error = math.atan2(-y[2 * n + 3], y[2 * n + 2])
        return self.w_start + self.kp * error + self.ki * y[2 * n + 4], error

    def rhs(self, t: float, y: list[float]) -> list[float]:
        n = self.n
        q, v = y[:n], y[n : 2 * n]
        phase = y[2 * n + 1]
        omega, error = self.frequency(y)
        shape = math.sin(phase)
        for h, d, psi in self.distortion:
            shape += d * math.sin(h * phase + psi)
        base = self.level(t) * shape
        scale = (1.0 + self.delta0 + self.delta_rate * t) ** 2
        acc = [-self.k[i] * scale * q[i] - self.c[i] * v[i] - self.gamma[i] * base
               for i in range(n)]  # fmt: skip
        if self.joint:
            u = sum(p * x for p, x in zip(self.phi, q, strict=True))
            udot = sum(p * x for p, x in zip(self.phi, v, strict=True))
            force = sum(term.force(u, udot) for term in self.joint)
            for i in range(n):
                acc[i] -= self.phi[i] * force
        for i, coefficient, powers in self.couplings:
            term = coefficient
            for x, e in zip(q, powers, strict=True):
                if e:
                    term *= x**e
            acc[i] -= term
        x = q[self.locked]
        wf = self.wf
        return [
            *v,
            *acc,
            base,
            omega,
            wf * (2 * x * math.cos(phase) - y[2 * n + 2]),
            wf * (2 * x * math.sin(phase) - y[2 * n + 3]),
            error,
        ]


def _rk4(loop: _Loop, y: list[float], t: float, h: float) -> list[float]:
    k1 = loop.rhs(t, y)
    k2 = loop.rhs(t + 0.5 * h, [a + 0.5 * h * b for a, b in zip(y, k1, strict=True)])
    k3 = loop.rhs(t + 0.5 * h, [a + 0.5 * h * b for a, b in zip(y, k2, strict=True)])
    k4 = loop.rhs(t + h, [a + h * b for a, b in zip(y, k3, strict=True)])
    return [a + h / 6 * (b + 2 * c + 2 * d + e)
            for a, b, c, d, e in zip(y, k1, k2, k3, k4, strict=True)]  # fmt: skip


def pll_record(
    system: ModalSystem,
    mode: int,
    levels_m_s2: Sequence[float],
    sensor_shapes: ArrayLike,
    *,
    participation: Sequence[float] | None = None,
    distortion: ShakerDistortion = PURE_SINE,
    settings: LoopSettings = LoopSettings(),
    noise: LabNoise = LabNoise(),
    seed: int = 0,
    drift: FrequencyDrift = NO_DRIFT,
) -> PLLRecord:
    """A phase-locked test of ``mode`` (from 1) of ``system`` at base levels ``levels_m_s2``.

    Parameters
    ----------
    system
        The modes, their joint (memoryless terms) and modal potential.
    mode
        The mode the loop holds.
    levels_m_s2
        The base acceleration's fundamental amplitude ``A`` of each hold, in test order.
    sensor_shapes
        ``(S, N)`` mode shapes at the panel's sensors.
    participation
        ``Γ_i`` of each mode (default 1).
    distortion
        The shaker's orders ``h ≥ 2``.
    settings, noise
        The schedule and loop; the lab's noise and time stamps.
    seed
        Seed of the noise.
    drift
        The modes' linear-frequency drift over the record's part of its campaign.

    Returns
    -------
    PLLRecord
        Starting at rest, the loop at the mode's linear frequency.
    """
    n = len(system.frequencies_hz)
    shapes = np.atleast_2d(np.asarray(sensor_shapes, dtype=float))
    if shapes.shape[1] != n or not 1 <= mode <= n:
        raise ValueError(f"sensor_shapes must be (S, {n}) and mode 1..{n}")
    gamma = [1.0] * n if participation is None else list(participation)
    schedule = _schedule(levels_m_s2, settings)
    loop = _Loop(system, gamma, mode, distortion, settings, schedule, drift)
    n_samples = round(schedule[0][-1] * settings.fs_hz) + 1
    h = 1.0 / (settings.fs_hz * settings.substeps)
    y = [0.0] * (2 * n + 5)
    states = np.empty((n_samples, 2 * n + 5))
    omega = np.empty(n_samples)
    for i in range(n_samples):
        states[i] = y
        omega[i] = loop.frequency(y)[0]
        t0 = i / settings.fs_hz
        for j in range(settings.substeps):
            y = _rk4(loop, y, t0 + j * h, h)
    time_s = np.arange(n_samples) / settings.fs_hz
    q, v, base = states[:, :n], states[:, n : 2 * n], states[:, 2 * n]
    rng = np.random.default_rng(seed)
    panel = base[:, None] + v @ shapes.T
    panel = panel + rng.normal(0.0, noise.velocity_m_s, panel.shape)
    base_points = base[:, None] + rng.normal(0.0, noise.velocity_m_s, (n_samples, 2))
    if noise.time_digits is not None:
        time_s = rounded_time_stamps(time_s, noise.time_digits)
    return PLLRecord(
        time_s=time_s,
        panel_velocity_m_s=panel,
        base_velocity_m_s=base_points,
        frequency_hz=omega / (2 * np.pi),
        phase_deg=np.degrees(states[:, 2 * n + 1]) % 360.0,
        modal_displacement=q,
        step_time_s=schedule[0],
        step_level=schedule[1],
    )


def write_trc_campaign(
    folder: str | Path,
    records: Sequence[PLLRecord],
    sensor_shapes: ArrayLike,
    frequencies_hz: Sequence[float],
    config: int = 1,
) -> list[Path]:
    """Write ``records`` as assemblies ``1, 2, …`` of one TRC configuration.

    The records share one step schedule (the first's is written; the others must equal it).
    The modes file carries ``sensor_shapes`` (15 rows, real) and ``frequencies_hz``.

    Returns
    -------
    list[Path]
        The data files.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    shapes = np.atleast_2d(np.asarray(sensor_shapes, dtype=float))
    first = records[0]
    for record in records[1:]:
        if not (np.array_equal(record.step_time_s, first.step_time_s)
                and np.array_equal(record.step_level, first.step_level)):  # fmt: skip
            raise ValueError("the records of one configuration share one step schedule")
    np.savetxt(folder / f"Config{config}_PRT_amplitude_steps",
               np.column_stack([first.step_time_s, first.step_level]), fmt="%.10e")  # fmt: skip
    rows = [" ".join(f"{x:.10e}+0.0e+00j" for x in row) for row in shapes]
    rows.append(" ".join(f"{f:.10e}" for f in frequencies_hz))
    (folder / f"Config{config}_linear_complex_modes").write_text("\n".join(rows) + "\n")
    paths = []
    for a, record in enumerate(records, start=1):
        path = folder / f"Config{config}_PRT_Assemb{a}"
        data = np.column_stack([record.time_s, record.panel_velocity_m_s, record.base_velocity_m_s,
                                record.frequency_hz, record.phase_deg])  # fmt: skip
        np.savetxt(path, data, fmt=["%.10g"] + ["%.8e"] * (data.shape[1] - 1))
        paths.append(path)
    return paths
