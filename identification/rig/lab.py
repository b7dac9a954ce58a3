"""The lab rig: phase-resonance records as a laboratory measures them.

:class:`LabRig` is a :class:`~identification.rig.rig.Rig` whose records come from
its own test engine instead of the ideal PLL simulator
(:mod:`identification.analytical.pll`, whose adaptive Fourier detector gives a
ripple-free frequency channel and whose excitation is a pure sine). It writes
the same TRC layout through the same :func:`~identification.measurements.records.write_record`
path, with a ``ground_truth.json`` that says everything that was put in.

The engine
----------
Structure (mass-normalised, ``x`` the first modal coordinate, 1 at the centre)::

    ẍ + k x + c ẋ + F_nl(u, u̇) + Δk(t)·x = −a_base
    q̈ + 2ζ₂ω₂ q̇ + ω₂² q + b·F_nl(u, u̇) = −Γ₂ a_base        (with a SecondMode)
    u = x + b·q

``k`` and ``c`` are the ground truth's linear stiffness and viscous damping
(modal), ``F_nl`` every other term of its catalogue model (their numba kernels,
the Jenkins element included) plus the rig's out-of-catalogue joints
(:mod:`identification.rig.joints`): the nonlinear forces act where the joint is,
on ``u``, and so couple the two modes; without a second mode ``u = x`` and the
first line is the model's own equation. ``Δk(t)`` is the natural-frequency drift.
Excitation and artefacts are those of :mod:`identification.rig.conditions`: the
base motion ``a_base = a_coil + μ f₁ − ω_c v_base`` with ``v̇_base = a_base``
(so the base velocity the sensors see is the exact integral of what drives
the structure), ``a_coil = A(t)(sin θ + Σ dₖ sin(kθ + ψₖ))``, ``θ̇ = ω``.

The controller runs once per sample on what the sensors deliver (noise, gain
drift and dropouts included): the centre-point channel minus the first base
channel is multiplied by ``sin θ``, ``cos θ`` and low-passed (exact discrete
first-order stages), and so is the base channel when it is the reference; the
phase error drives a PI controller that sets ``ω`` for the next sample. The
recorded frequency channel is that ``ω/2π`` — ripple and all — and the phase
channel ``θ`` in degrees. Levels are shaker voltages; each is approached by a
raised-cosine ramp of ``ramp_s`` and held ``hold_s`` (a fixed-time schedule;
the controller switches on at the first hold).

Time integration is RK4 with the sample split into sub-steps that keep the
stiffest linearised eigenvalue (joint contact springs included) inside RK4's
stability region; hysteretic elements (Jenkins, Iwan sliders) are evaluated
from their anchor at the sub-step start and moved to the accepted state after
it, as in the PLL simulator.

What a lab would see
--------------------
A frequency channel that ripples at 2ω (and at 1ω with response harmonics), base
channels with the shaker's 2nd and 3rd harmonics and the structure's reaction,
phase errors of a few degrees where the lock is poor, backbones that move
between records (frequency drift) or along the amplitude axis (gain drift), and
spikes where the vibrometer lost the speckle. The truth in ``ground_truth.json``
(per record: the drawn model and joints, the drift at start and end, the
controller gains and predicted ripple, the noise of every channel and every
dropout) is for studies and tests; the identification pipeline never reads it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.harmonic import coefficient_table, describing_sums
from identification.analytical.pll import stable_substeps
from identification.analytical.pll.integrator import RK4_STABLE_STEP
from identification.effects import (
    CATALOGUE,
    LINEAR_STIFFNESS,
    VISCOUS_DAMPING,
    jenkins_force,
    memoryless_force,
)
from identification.measurements.records import CENTRE_POINT, N_PANEL_POINTS, Modes, Record
from identification.model import JointModel
from identification.rig.conditions import Controller, Drift, Sensors, Shaker
from identification.rig.joints import (
    IwanJoint,
    Joint,
    SecondMode,
    iwan_force,
    iwan_update,
    memoryless_joint_force,
)
from identification.rig.lab_loop import (
    DELTA0,
    DELTA1,
    DT,
    LOOP_CHANNELS,
    N_LOOP_SETTINGS,
    N_SUB,
    OMEGA_INITIAL,
    ORDER,
    RAMP,
    X_MAX,
    LabChannels,
    coil,
    loop_settings,
    ramp_level,
    record_loop,
    schedule,
    track,
)
from identification.rig.rig import Rig, trc_channels

__all__ = [
    "LabAssembly",
    "LabRig",
    "LabTimeSeries",
    "measured_channels",
    "panel_positions",
    "sensor_draws",
]

#: Catalogue terms of the first mode alone; every other term acts on the joint displacement.
_MODAL_EFFECTS = (LINEAR_STIFFNESS, VISCOUS_DAMPING)
_GRID = (5, 3)

# Settings vector of the kernel: the loop's, then the drift's stiffness.
_K_DRIFT, _N_SETTINGS = range(N_LOOP_SETTINGS, N_LOOP_SETTINGS + 2)
# Second-mode vector: ω₂ (0: none), ζ₂, Γ₂, centre shape, joint shape.
_OMEGA2, _ZETA2, _GAMMA2, _CENTRE2, _JOINT2 = range(5)
# Hysteretic anchors: the Jenkins element's joint displacement and force, the Iwan sliders'
# joint displacement.
_JENKINS_U, _JENKINS_F, _IWAN_U = range(3)
#: Channels the kernel records, one row each.
CHANNELS = ("x", "v", "q", "w", *LOOP_CHANNELS)
# What the controller's sensors add: centre-point noise, centre-point dropout value
# (NaN where none), base-point-1 noise, its dropout value.
_CENTRE_NOISE, _CENTRE_DROPOUT, _BASE_NOISE, _BASE_DROPOUT = range(4)


def sensor_draws(
    sensors: Sensors, noise_m_s: float, rng: np.random.Generator, n_samples: int, fs: float
) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, np.ndarray]]]:
    """What the 17 velocity channels of one record add: their RMS noise (m/s), the
    ``(n_samples, 17)`` noise with the panel offset, and every dropout as
    ``(channel, first sample, spike values)``; ``rng`` draws the noise, then the dropouts."""
    channel_noise_m_s = sensors.channel_noise(noise_m_s)
    noise = rng.standard_normal((n_samples, channel_noise_m_s.size)) * channel_noise_m_s
    noise[:, :N_PANEL_POINTS] += sensors.panel_offset_m_s
    dropouts = [
        (channel, start, rng.uniform(-1.0, 1.0, length) * sensors.dropout_spike_m_s)
        for channel, start, length in sensors.dropouts(rng, n_samples, fs)
    ]
    return channel_noise_m_s, noise, dropouts


def measured_channels(
    data: np.ndarray,
    drift: Drift,
    position: float,
    noise: np.ndarray,
    dropouts: Sequence[tuple[int, int, np.ndarray]],
) -> None:
    """Turn true TRC data columns into measured ones, in place: the drifting sensor gain,
    the noise and the dropouts of :func:`sensor_draws` (``position`` places the record in
    its campaign)."""
    panel = slice(1, 1 + N_PANEL_POINTS)
    gain = np.linspace(*drift.gain(position), data.shape[0])
    drifting = panel if drift.gain_channels == "panel" else slice(panel.stop, -2)
    data[:, drifting] *= gain[:, None]
    data[:, 1:-2] += noise
    for channel, start, spikes in dropouts:
        data[start : start + spikes.size, 1 + channel] = spikes


def panel_positions() -> np.ndarray:
    """Position ξ (0…1) along the length of each of the 15 panel points, row by row."""
    return np.repeat(np.arange(1, _GRID[0] + 1) / (_GRID[0] + 1), _GRID[1])


@dataclass(frozen=True)
class LabAssembly:
    """One assembly's structure: catalogue model, joints, second mode, shaker gain."""

    model: JointModel
    shaker_gain: float
    joints: tuple[Joint, ...] = ()
    second_mode: SecondMode | None = None

    @property
    def small_amplitude_stiffness(self) -> float:
        """First mode's stiffness at rest, joints included (1/s²)."""
        return self.model.linear_stiffness + sum(j.small_amplitude_stiffness for j in self.joints)

    @property
    def linear_frequency_hz(self) -> float:
        """First mode's small-amplitude natural frequency (Hz)."""
        k = self.small_amplitude_stiffness
        if k <= 0:
            raise ValueError(f"the assembly has no positive stiffness at rest (k = {k})")
        return math.sqrt(k) / (2 * math.pi)

    @property
    def damping_ratio(self) -> float:
        """First mode's viscous damping ratio at rest (1)."""
        return self.model.coefficient(VISCOUS_DAMPING) / (
            2 * math.sqrt(self.small_amplitude_stiffness)
        )

    def describing(self, a: ArrayLike, omega: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Equivalent stiffness and damping of catalogue terms and joints at amplitude ``a``."""
        k_eq, c_eq = describing_sums(
            np.asarray(a, float), np.asarray(omega, float), coefficient_table(self.model)
        )
        k_eq, c_eq = k_eq[0], c_eq[0]
        for joint in self.joints:
            k_j, c_j = joint.describing(a, omega)
            k_eq, c_eq = k_eq + k_j, c_eq + c_j
        return k_eq, c_eq

    def to_dict(self) -> dict[str, Any]:
        return {
            "model": self.model.to_dict(),
            "shaker_gain": self.shaker_gain,
            "joints": [j.to_dict() for j in self.joints],
            "second_mode": None if self.second_mode is None else self.second_mode.to_dict(),
        }


@dataclass(frozen=True, eq=False)
class LabTimeSeries(LabChannels):
    """The engine's true signals of one record: the loop's
    (:class:`~identification.rig.lab_loop.LabChannels`) and the structure's, ``x``, ``v``
    the first modal coordinate and its velocity, ``q``, ``w`` the second mode's.
    """

    x: np.ndarray
    v: np.ndarray
    q: np.ndarray
    w: np.ndarray


# --------------------------------------------------------------------------
# numba engine


@numba.njit(cache=True, inline="always")
def _forces(structure, anchors, slider_forces, x, v, u, du):
    """(modal force on x, nonlinear force on u), hysteretic elements from their anchors.

    ``structure`` is the tuple the kernel receives (catalogue arrays, modal flags,
    Jenkins element, joints, Iwan sliders, second mode, shaker). Catalogue terms
    flagged modal (the linear stiffness and viscous damping) act on the first modal
    coordinate; every other term, the Jenkins element and the joints act on the joint
    displacement ``u``. ``anchors`` holds the Jenkins element's anchor displacement
    and force and the Iwan sliders' common anchor.
    """
    indices, coefficients, shapes, modal, microslip = structure[:5]
    joint_kinds, joint_parameters, slider_stiffness, slip_forces = structure[5:9]
    f_modal = 0.0
    f_joint = 0.0
    for i in range(indices.size):
        p0, p1 = shapes[i, 0], shapes[i, 1]
        if modal[i]:
            f_modal += coefficients[i] * memoryless_force(indices[i], x, v, p0, p1)
        else:
            f_joint += coefficients[i] * memoryless_force(indices[i], u, du, p0, p1)
    if microslip[0] != 0.0:
        f_joint += microslip[0] * jenkins_force(
            u, anchors[_JENKINS_U], anchors[_JENKINS_F], microslip[1], microslip[2]
        )
    for j in range(joint_kinds.size):
        p = joint_parameters[j]
        f_joint += memoryless_joint_force(joint_kinds[j], u, du, p[0], p[1], p[2])
    if slider_forces.size > 0:
        f_joint += iwan_force(u, anchors[_IWAN_U], slider_forces, slider_stiffness, slip_forces)
    return f_modal, f_joint


@numba.njit(cache=True, inline="always")
def _derivatives(structure, anchors, slider_forces, dk, x, v, q, w, vb, coil):
    """Time derivatives of ``(x, ẋ, q, q̇, v_base)``; the last is the base acceleration.

    ``coil`` is the coil acceleration, ``dk`` the drift's stiffness.
    """
    mode2, shaker = structure[9], structure[10]
    b = mode2[_JOINT2]
    f_modal, f_joint = _forces(structure, anchors, slider_forces, x, v, x + b * q, v + b * w)
    f1 = f_modal + f_joint + dk * x
    a_base = coil + shaker[0] * f1 - shaker[1] * vb
    omega2 = mode2[_OMEGA2]
    q_acceleration = -2.0 * mode2[_ZETA2] * omega2 * w - omega2 * omega2 * q - b * f_joint
    return v, -f1 - a_base, w, q_acceleration - mode2[_GAMMA2] * a_base, a_base


@numba.njit(cache=True)
def _lab_kernel(structure, distortion, coil_m_s2, settings, sensors, out):
    """Run the whole schedule; fills ``out`` (len(CHANNELS), n) and returns the samples done.

    ``coil_m_s2`` holds the coil-acceleration amplitude (m/s²) of each hold.
    """
    dt = settings[DT]
    n_sub = int(settings[N_SUB])
    ramp = int(settings[RAMP])
    k_drift, delta0, delta1 = settings[_K_DRIFT], settings[DELTA0], settings[DELTA1]
    x_max = settings[X_MAX]
    slider_stiffness, slip_forces, mode2 = structure[7], structure[8], structure[9]
    centre2, b = mode2[_CENTRE2], mode2[_JOINT2]

    n_total = out.shape[1]
    x = v = q = w = vb = 0.0
    anchors = np.zeros(3)
    slider_forces = np.zeros(slider_stiffness.size)
    theta = 0.0
    omega = settings[OMEGA_INITIAL]
    integral = omega
    control_on = False
    # I and Q of the response, then of the reference, each a cascade of low passes
    filters = np.zeros((4, int(settings[ORDER])))
    coils = np.empty(2 * n_sub + 1)
    a_from = 0.0
    h = dt / n_sub
    for n in range(n_total):
        hold, in_hold, a_from, a_to, amplitude, fraction, panel_gain, base_gain = schedule(
            settings, coil_m_s2, n, n_total, a_from
        )
        delta = delta0 + (delta1 - delta0) * fraction
        dk = k_drift * ((1.0 + delta) ** 2 - 1.0)
        coils[0] = coil(amplitude, theta, distortion)
        d1 = _derivatives(structure, anchors, slider_forces, dk, x, v, q, w, vb, coils[0])
        a_base = d1[4]
        if not (abs(x) <= x_max and np.isfinite(v) and np.isfinite(a_base)):
            return n

        # What the sensors deliver to the controller.
        centre = panel_gain * (v + centre2 * w + vb) + sensors[_CENTRE_NOISE, n]
        if not np.isnan(sensors[_CENTRE_DROPOUT, n]):
            centre = sensors[_CENTRE_DROPOUT, n]
        base = base_gain * vb + sensors[_BASE_NOISE, n]
        if not np.isnan(sensors[_BASE_DROPOUT, n]):
            base = sensors[_BASE_DROPOUT, n]
        error, control_on, integral, omega = track(
            settings, filters, centre - base, base, theta, hold, in_hold, control_on, integral,
            omega,
        )  # fmt: skip

        out[0, n] = x
        out[1, n] = v
        out[2, n] = q
        out[3, n] = w
        record_loop(out, 4, n, vb, a_base, omega, theta, amplitude, error)

        # The oscillator runs at the updated frequency until the next sample.
        for j in range(1, 2 * n_sub + 1):
            part = j / (2.0 * n_sub)
            coils[j] = coil(
                ramp_level(a_from, a_to, in_hold + part, ramp), theta + omega * dt * part,
                distortion,
            )  # fmt: skip
        for j in range(n_sub):
            if j > 0:
                d1 = _derivatives(
                    structure, anchors, slider_forces, dk, x, v, q, w, vb, coils[2 * j]
                )
            half = 0.5 * h
            d2 = _derivatives(
                structure, anchors, slider_forces, dk, x + half * d1[0], v + half * d1[1],
                q + half * d1[2], w + half * d1[3], vb + half * d1[4], coils[2 * j + 1],
            )  # fmt: skip
            d3 = _derivatives(
                structure, anchors, slider_forces, dk, x + half * d2[0], v + half * d2[1],
                q + half * d2[2], w + half * d2[3], vb + half * d2[4], coils[2 * j + 1],
            )  # fmt: skip
            d4 = _derivatives(
                structure, anchors, slider_forces, dk, x + h * d3[0], v + h * d3[1],
                q + h * d3[2], w + h * d3[3], vb + h * d3[4], coils[2 * j + 2],
            )  # fmt: skip
            x += h / 6.0 * (d1[0] + 2.0 * d2[0] + 2.0 * d3[0] + d4[0])
            v += h / 6.0 * (d1[1] + 2.0 * d2[1] + 2.0 * d3[1] + d4[1])
            q += h / 6.0 * (d1[2] + 2.0 * d2[2] + 2.0 * d3[2] + d4[2])
            w += h / 6.0 * (d1[3] + 2.0 * d2[3] + 2.0 * d3[3] + d4[3])
            vb += h / 6.0 * (d1[4] + 2.0 * d2[4] + 2.0 * d3[4] + d4[4])
            u = x + b * q
            microslip = structure[4]
            if microslip[0] != 0.0:
                anchors[_JENKINS_F] = jenkins_force(
                    u, anchors[_JENKINS_U], anchors[_JENKINS_F], microslip[1], microslip[2]
                )
                anchors[_JENKINS_U] = u
            if slider_forces.size > 0:
                iwan_update(u, anchors[_IWAN_U], slider_forces, slider_stiffness, slip_forces)
                anchors[_IWAN_U] = u
        theta += omega * dt
    return n_total


# --------------------------------------------------------------------------
# The rig


@dataclass(frozen=True)
class LabRig(Rig):
    """A virtual test rig that measures like a lab (see the module notes).

    Every :class:`~identification.rig.rig.Rig` field keeps its meaning
    (``noise_m_s`` is the default noise of every velocity channel; ``model`` the
    catalogue part of the ground truth; ``variability`` may also name joint
    parameters ``"<joint>.<parameter>"`` and ``"second_mode.<parameter>"``). The
    levels are coil-acceleration amplitudes per volt × ``shaker_gain``.

    Attributes
    ----------
    joints
        Out-of-catalogue joint forces (:mod:`identification.rig.joints`), at most one
        of each kind.
    second_mode
        A second mode nearby, or None.
    shaker, controller, drift, sensors
        The lab's artefacts (:mod:`identification.rig.conditions`).
    """

    joints: tuple[Joint, ...] = ()
    second_mode: SecondMode | None = None
    shaker: Shaker = field(default_factory=Shaker)
    controller: Controller = field(default_factory=Controller)
    drift: Drift = field(default_factory=Drift)
    sensors: Sensors = field(default_factory=Sensors)

    takes_lab_settings: ClassVar[bool] = True

    def __post_init__(self) -> None:
        joints = tuple(self.joints)
        for joint in joints:
            if not isinstance(joint, Joint):
                raise ValueError(f"LabRig.joints must be Joint objects, got {joint!r}")
        names = [j.name for j in joints]
        if len(set(names)) != len(names):
            raise ValueError(f"LabRig.joints: at most one joint of each kind, got {names}")
        object.__setattr__(self, "joints", joints)
        if self.pll_options:
            raise ValueError(
                "LabRig has its own controller (LabRig.controller); pll_options belong to Rig"
            )
        super().__post_init__()
        self.nominal.linear_frequency_hz  # noqa: B018 (validates a positive stiffness)

    # ------------------------------------------------------------ structure
    @property
    def nominal(self) -> LabAssembly:
        """The nominal assembly (no reassembly spread)."""
        return LabAssembly(self.model, self.shaker_gain, self.joints, self.second_mode)

    def _variable_parameters(self) -> list[str]:
        names = super()._variable_parameters()
        for joint in self.joints:
            names += [f"{joint.name}.{p}" for p in joint.variable_parameters]
        if self.second_mode is not None:
            names += [f"second_mode.{p}" for p in self.second_mode.parameters]
        return names

    def draw_assembly(self, rng: np.random.Generator) -> LabAssembly:
        """One assembly: every parameter of ``variability`` drawn with its lognormal spread."""
        factors = self._factors(rng)
        gain = self.shaker_gain * factors.pop("shaker_gain", 1.0)
        scaled = {k: f * self._nominal_value(k) for k, f in factors.items()}
        model = self.model.with_parameters(
            {k: v for k, v in scaled.items() if k in self.model.parameter_names}
        )
        joints = tuple(
            j.with_parameters(
                {k.split(".", 1)[1]: v for k, v in scaled.items() if k.split(".", 1)[0] == j.name}
            )
            for j in self.joints
        )
        mode = self.second_mode
        if mode is not None:
            mode = mode.with_parameters(
                {k.split(".", 1)[1]: v for k, v in scaled.items() if k.startswith("second_mode.")}
            )
        return LabAssembly(model, gain, joints, mode)

    def _nominal_value(self, name: str) -> float:
        if name in self.model.parameter_names:
            return self.model.parameters[name]
        owner, parameter = name.split(".", 1)
        if owner == "second_mode":
            return self.second_mode.parameters[parameter]
        return next(j for j in self.joints if j.name == owner).parameters[parameter]

    def draw(self, rng: np.random.Generator) -> tuple[JointModel, float]:
        """The catalogue model and shaker gain of one assembly (see :meth:`draw_assembly`)."""
        assembly = self.draw_assembly(rng)
        return assembly.model, assembly.shaker_gain

    def _draw_job(self, rng: np.random.Generator) -> LabAssembly:
        return self.draw_assembly(rng)

    # ------------------------------------------------------------ levels
    def levels_for_amplitudes(self, amplitudes_m: ArrayLike, max_iter: int = 100) -> np.ndarray:
        """Coil-acceleration amplitudes (m/s²) that hold the nominal assembly at ``amplitudes_m``.

        Single-harmonic balance of the catalogue terms and the joints'
        describing functions (the second mode left out), with the shaker's
        interaction (:meth:`~identification.rig.conditions.Shaker.coil_per_base`).
        Accurate enough to place a test's levels.
        """
        a = np.asarray(amplitudes_m, dtype=float)
        assembly = self.nominal
        omega = np.full(a.shape, 2 * np.pi * assembly.linear_frequency_hz)
        for _ in range(max_iter):
            k_eq, c_eq = assembly.describing(a, omega)
            updated = np.sqrt(np.where(k_eq > 0, k_eq, np.nan))
            if np.allclose(updated, omega, rtol=1e-12, equal_nan=True):
                break
            omega = updated
        zeta = c_eq / (2 * omega)
        if not np.all(np.isfinite(zeta) & (zeta > 0)):
            raise ValueError(
                f"{self.name or 'LabRig'}: no phase-resonant excitation at some of the amplitudes "
                f"{a} m (negative net damping or no stiffness)"
            )
        base = 2 * zeta * omega**2 * a
        return base * np.array([self.shaker.coil_per_base(z) for z in zeta])

    @classmethod
    def for_amplitudes(
        cls,
        model: JointModel,
        amplitudes_m: ArrayLike,
        shaker_gain: float = 10.0,
        schedule: str = "up",
        **options: Any,
    ) -> LabRig:
        """A lab rig whose levels hold the nominal assembly at ``amplitudes_m`` (m).

        ``schedule="up-down"`` steps back down through the same levels after the
        highest (the TRC procedure), so drift shows between equal levels.
        """
        if schedule not in ("up", "up-down"):
            raise ValueError(f"schedule must be 'up' or 'up-down', got {schedule!r}")
        draft = cls(model, (1.0,), shaker_gain=shaker_gain, **options)
        drive_v = draft.levels_for_amplitudes(amplitudes_m) / shaker_gain
        if schedule == "up-down":
            drive_v = np.concatenate([drive_v, drive_v[-2::-1]])
        return dataclasses.replace(draft, levels_v=tuple(drive_v))

    # ------------------------------------------------------------ running
    def modes(self) -> Modes:
        """Linear modes of the nominal assembly: first bending, and the second mode if any."""
        first = np.asarray(self.mode_shape)[:, None]
        f1 = self.nominal.linear_frequency_hz
        if self.second_mode is None:
            return Modes(first, [f1])
        second = self.second_mode.panel_shape(panel_positions())[:, None]
        return Modes(np.hstack([first, second]), [f1, f1 * self.second_mode.frequency_ratio])

    def _substeps(self, assembly: LabAssembly) -> int:
        joints = assembly.joints
        stiffness = assembly.model.linear_stiffness + sum(j.stiffness_bound for j in joints)
        slope = sum(j.damping_slope_bound for j in joints)
        if assembly.second_mode is not None:
            mode = assembly.second_mode
            omega2 = mode.frequency_ratio * 2 * math.pi * assembly.linear_frequency_hz
            stiffness = max(stiffness, omega2**2 + abs(mode.joint_shape) ** 2 * stiffness)
        eigenvalue = 0.5 * slope + math.sqrt(0.25 * slope**2 + abs(stiffness))
        needed = math.ceil(eigenvalue / self.fs / RK4_STABLE_STEP)
        return max(1, needed, stable_substeps(assembly.model, self.fs))

    def run(
        self, assembly: LabAssembly, sensors: np.ndarray | None = None, position: float = 0.0
    ) -> LabTimeSeries:
        """Simulate the schedule on ``assembly``.

        ``sensors`` is the ``(4, n)`` array of what the controller's sensors add
        (centre-point noise and dropout values, base-point noise and dropout
        values; NaN where no dropout); None: ideal sensors. ``position`` (0…1)
        places the record in its campaign for the drift.
        """
        ramp, hold = self._samples()
        n = len(self.levels_v) * (ramp + hold)
        if sensors is None:
            sensors = np.zeros((4, n))
            sensors[[_CENTRE_DROPOUT, _BASE_DROPOUT]] = np.nan
        f1 = assembly.linear_frequency_hz
        settings = loop_settings(
            _N_SETTINGS, fs=self.fs, n_sub=self._substeps(assembly), ramp_samples=ramp,
            hold_samples=hold, controller=self.controller, frequency_hz=f1,
            damping_ratio=assembly.damping_ratio, drift=self.drift, position=position,
        )  # fmt: skip
        settings[_K_DRIFT] = assembly.small_amplitude_stiffness
        memoryless = [j for j in assembly.joints if not isinstance(j, IwanJoint)]
        iwan = [j for j in assembly.joints if isinstance(j, IwanJoint)]
        sliders = iwan[0].sliders() if iwan else (np.zeros(0), np.zeros(0))
        mode2 = np.zeros(5)
        if assembly.second_mode is not None:
            m = assembly.second_mode
            mode2[:] = (
                m.frequency_ratio * 2 * math.pi * f1,
                m.damping_ratio,
                m.participation,
                m.centre_shape,
                m.joint_shape,
            )
        indices, coefficients, shapes = assembly.model.kernel_arrays()
        modal = np.isin(indices, [CATALOGUE[e].index for e in _MODAL_EFFECTS])
        out = np.full((len(CHANNELS), n), np.nan)
        shaker = np.array([self.shaker.interaction, 2 * math.pi * self.shaker.centring_hz])
        structure = (
            indices, coefficients, shapes, modal, np.array(assembly.model.microslip_arrays()),
            np.array([j.kind for j in memoryless], dtype=np.int64),
            np.array([j.kernel_parameters() for j in memoryless], dtype=float).reshape(-1, 3),
            *sliders, mode2, shaker,
        )  # fmt: skip
        done = _lab_kernel(
            structure, self.shaker.harmonics_table(),
            np.asarray(self.levels_v) * assembly.shaker_gain, settings,
            np.ascontiguousarray(sensors, dtype=float), out,
        )  # fmt: skip
        return LabTimeSeries(self.fs, done == n, **dict(zip(CHANNELS, out, strict=True)))

    def simulate_assembly(
        self, assembly: LabAssembly, rng: np.random.Generator, name: str, position: float = 0.0
    ) -> tuple[Record, dict[str, Any]]:
        """One record of ``assembly`` and its ground-truth entry.

        ``rng`` draws the noise of the 17 velocity channels, then the dropouts;
        ``position`` (0…1) places the record in its campaign for the drift.
        """
        ramp, hold = self._samples()
        n = len(self.levels_v) * (ramp + hold)
        channel_noise_m_s, noise, dropouts = sensor_draws(
            self.sensors, self.noise_m_s, rng, n, self.fs
        )
        centre, base = CENTRE_POINT - 1, N_PANEL_POINTS
        sensed = np.full((4, n), np.nan)
        sensed[_CENTRE_NOISE], sensed[_BASE_NOISE] = noise[:, centre], noise[:, base]
        for channel, start, spikes in dropouts:
            row = {centre: _CENTRE_DROPOUT, base: _BASE_DROPOUT}.get(channel)
            if row is not None:
                sensed[row, start : start + spikes.size] = spikes
        series = self.run(assembly, sensed, position)
        if not series.completed:
            raise RuntimeError(
                f"{name}: the lab simulation diverged (|x| > 0.05 m or non-finite) at "
                f"t = {np.flatnonzero(np.isnan(series.x))[0] / self.fs:.3f} s"
            )
        data = trc_channels(
            series.t,
            series.v,
            series.base_velocity,
            series.frequency_hz,
            series.theta,
            self.mode_shape,
        )
        panel = slice(1, 1 + N_PANEL_POINTS)
        if assembly.second_mode is not None:
            shape = assembly.second_mode.panel_shape(panel_positions())
            data[:, panel] += np.outer(series.w, shape)
        measured_channels(data, self.drift, position, noise, dropouts)
        record = Record(data, self.steps(), name, modes=self.modes())
        delta = self.drift.frequency(position)
        gains = self.controller.gains(assembly.linear_frequency_hz, assembly.damping_ratio)
        truth = {
            **assembly.to_dict(),
            "noise_m_s": self.noise_m_s,
            "lab": {
                "position": position,
                "small_amplitude_frequency_hz": assembly.linear_frequency_hz,
                "natural_frequency_drift": list(delta),
                "sensor_gain": list(self.drift.gain(position)),
                "channel_noise_m_s": channel_noise_m_s.tolist(),
                "dropouts": [[channel, start, spikes.size] for channel, start, spikes in dropouts],
                "controller_gains": dataclasses.asdict(gains),
                "predicted_ripple_hz": self.controller.predicted_ripple_hz(
                    assembly.linear_frequency_hz,
                    assembly.linear_frequency_hz,
                    assembly.damping_ratio,
                ),
                "substeps": self._substeps(assembly),
            },
        }
        return record, truth

    def simulate(
        self, model: JointModel, shaker_gain: float, rng: np.random.Generator, name: str
    ) -> Record:
        """One record of ``model`` with the nominal joints and second mode, at no drift offset."""
        assembly = LabAssembly(model, shaker_gain, self.joints, self.second_mode)
        return self.simulate_assembly(assembly, rng, name)[0]

    def _simulate_job(
        self, name: str, drawn: LabAssembly, seeds: Sequence[int], position: float
    ) -> tuple[Record, dict[str, Any]]:
        record, truth = self.simulate_assembly(
            drawn, np.random.default_rng(list(seeds)), name, position
        )
        return record, {**truth, "seed": list(seeds)}

    def _sidecar(self, records: dict[str, Any]) -> dict[str, Any]:
        sidecar = super()._sidecar(records)
        sidecar["rig"]["lab"] = {
            "engine": "pm-joint lab rig (multiply-and-low-pass PLL)",
            "joints": [j.to_dict() for j in self.joints],
            "second_mode": None if self.second_mode is None else self.second_mode.to_dict(),
            "shaker": self.shaker.to_dict(),
            "controller": self.controller.to_dict(),
            "drift": self.drift.to_dict(),
            "sensors": self.sensors.to_dict(),
        }
        return sidecar
