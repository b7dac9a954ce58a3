"""The two-mode virtual TRC: bending and torsion of the panel, coupled through the joint.

A :class:`ModalRig` writes campaigns in the TRC layout from a ground truth of
several modes (:class:`~identification.multimode.model.ModalModel`), through the
lab engine of :mod:`identification.rig.modal_engine` (the N-mode PLL simulator's
integrator inside the lab rig's loop), with every lab artefact of
:mod:`identification.rig.conditions`: shaker distortion, controller ripple and
phase offset, drift, per-channel noise, offsets and dropouts.

Panel
    The 15 points of the 5 × 3 grid see each mode through its shape
    (:func:`plate_shapes`): the first bending mode ``sin(πξ)(1 − 0.1(2η − 1)²)``
    (one sign over the plate, 1 at the centre point) and the first torsion mode
    ``sin(πξ)(1 − 2η)/0.5`` (antisymmetric across the centre line, 0 on it, ±1 at
    the side points of the middle row). The modal coordinate of each mode is its
    displacement at its reference point (where its shape is largest), and the base
    drives it through its participation there; the one-mode rig's convention
    (``ẍ + … = −a_base`` at the centre) is mode 1's.
Tests
    ``pll``: levels stepped up through phase resonance of the locked ``mode``
    (the controller's response channel is the centre point for bending, the
    difference of the middle row's side points for torsion); ``free-decay``: the
    panel released from a deflected shape (``release``) or hit at a point
    (``impulse``), the step file's level 1 while it is held and 0 from the release.
Ground truth
    ``ground_truth.json`` (format ``pm-joint/modal-rig-ground-truth``): the rig's
    settings and, per record, the drawn ModalModel's JSON, shaker gain, noise,
    seed, the lab's draws, and each mode's backbone per amplitude
    (:class:`ModeBackboneTruth`): its phase-resonance backbone (the harmonic
    balance of :func:`identification.multimode.phase_resonance`) for PLL records,
    its nonlinear mode (:func:`identification.multimode.nonlinear_modes`) for
    decays: frequency, damping ratio, every mode's participation per harmonic at
    its reference point and the energy shares. The pipeline never reads it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from identification.measurements.records import (
    N_BASE_POINTS,
    N_PANEL_POINTS,
    Modes,
    Record,
    StepSchedule,
    record_name,
)
from identification.multimode import ModalModel, nonlinear_modes, phase_resonance
from identification.multimode.balance import modal_arrays
from identification.multimode.pll.closed_loop import kernel_arrays, linearisation
from identification.multimode.solve import HarmonicSettings, ModalSolution
from identification.rig.conditions import Controller, Drift, Sensors, Shaker
from identification.rig.lab import measured_channels, sensor_draws
from identification.rig.modal_engine import free_decay, run_modal_lab
from identification.rig.rig import (
    Rig,
    campaign_jobs,
    first_bending_shape,
    level_steps,
    read_sidecar,
    sidecar,
)

__all__ = [
    "MODAL_GROUND_TRUTH_FORMAT",
    "TESTS",
    "ModalRecordTruth",
    "ModalRig",
    "ModeBackboneTruth",
    "lock_weights",
    "plate_shapes",
    "read_modal_ground_truth",
    "reference_points",
    "small_amplitude_frequencies_hz",
]

MODAL_GROUND_TRUTH_FORMAT = "pm-joint/modal-rig-ground-truth"
TESTS = ("pll", "free-decay")
DECAY_STARTS = ("impulse", "release")
_GRID = (5, 3)
#: Points of the truth's backbone grid, spanning the campaign's amplitudes.
_TRUTH_POINTS = 81
#: The truth's grid reaches this far beyond the campaign's target amplitudes (a factor).
_TRUTH_MARGIN = 1.4
#: A decay's truth spans its initial amplitude down to this many times less.
_DECAY_SPAN = 300.0
#: Harmonics of the truth's harmonic balance.
_TRUTH_HARMONICS = 7


def plate_shapes(width_variation: float = 0.1) -> np.ndarray:
    """``(15, 2)`` shapes at the panel points: first bending, first torsion (see the module notes).

    Points numbered row by row, three across the width per position along the length;
    each shape is 1 at its reference point (bending: the centre point 8; torsion:
    point 7, with −1 at point 9 across the centre line).
    """
    xi = np.arange(1, _GRID[0] + 1) / (_GRID[0] + 1)
    eta = np.arange(1, _GRID[1] + 1) / (_GRID[1] + 1)
    torsion = np.outer(np.sin(np.pi * xi), (1 - 2 * eta) / 0.5).ravel()
    return np.column_stack([first_bending_shape(width_variation), torsion])


def small_amplitude_frequencies_hz(model: ModalModel) -> np.ndarray:
    """Natural frequencies of ``model`` linearised at rest (joint elements' linear parts in)."""
    arrays = modal_arrays(model)
    stiffness = linearisation(arrays, kernel_arrays(arrays, None))[0][0]
    return np.sqrt(np.linalg.eigvalsh(stiffness)) / (2 * np.pi)


def reference_points(shapes: np.ndarray) -> np.ndarray:
    """Index (from 0) of the sensor where each mode's shape is largest (the first such)."""
    return np.argmax(np.abs(np.asarray(shapes)), axis=0)


def _mirror(point: int) -> int:
    """The panel point across the centre line (same position along the length)."""
    row, column = divmod(point, _GRID[1])
    return row * _GRID[1] + (_GRID[1] - 1 - column)


def lock_weights(shapes: np.ndarray, mode: int) -> np.ndarray:
    """Weights of the panel channels in the controller's response channel when ``mode`` is locked.

    The reference point of the mode alone, or, for a shape antisymmetric across the
    centre line, half the difference of the reference point and its mirror (the
    symmetric modes and the base cancel there).
    """
    shapes = np.asarray(shapes, dtype=float)
    point = int(reference_points(shapes)[mode - 1])
    weights = np.zeros(shapes.shape[0])
    mirror = _mirror(point)
    column = shapes[:, mode - 1]
    if mirror != point and np.isclose(column[mirror], -column[point]):
        weights[point], weights[mirror] = 0.5, -0.5
    else:
        weights[point] = 1.0
    return weights


class ModeBackboneTruth(NamedTuple):
    """One mode's backbone in the ground truth, per amplitude (one entry per point).

    ``problem`` is ``"phase_resonance"`` (PLL records) or ``"nonlinear_modes"``
    (decays). ``amplitude_mm`` is the mode's fundamental at its reference point,
    ``participation_mm`` ``(points, modes, 3)`` every mode's harmonics 1–3 at its own
    reference point, ``participation_phase_deg`` their phase against k × this mode's
    fundamental (the convention of :attr:`identification.multimode.ModalPLLResult.
    participation_phase_deg`), ``energy_share`` ``(points, modes)``.
    """

    mode: int
    problem: str
    reference_point: int
    amplitude_mm: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    participation_mm: np.ndarray
    participation_phase_deg: np.ndarray
    energy_share: np.ndarray
    base_acceleration_m_s2: np.ndarray

    def to_dict(self) -> dict[str, Any]:
        return {
            k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in self._asdict().items()
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ModeBackboneTruth:
        values = {k: data[k] for k in cls._fields}
        arrays = {k: np.asarray(v, dtype=float) for k, v in values.items() if isinstance(v, list)}
        return cls(**{**values, **arrays})


@dataclass(frozen=True)
class ModalRecordTruth:
    """Ground truth of one record of a :class:`ModalRig` campaign (``ground_truth.json``)."""

    model: ModalModel
    shaker_gain: float
    noise_m_s: float
    seed: tuple[int, ...]
    lab: Mapping[str, Any]
    backbones: tuple[ModeBackboneTruth, ...]


def _truth_backbone(
    model: ModalModel, mode: int, amplitudes_m: np.ndarray, shapes: np.ndarray, problem: str
) -> ModeBackboneTruth:
    """``mode``'s backbone of ``model`` at its reference point's amplitudes ``amplitudes_m``."""
    points = reference_points(shapes)
    scale = shapes[points, np.arange(shapes.shape[1])]  # each mode's shape at its reference
    solve = phase_resonance if problem == "phase_resonance" else nonlinear_modes
    solution: ModalSolution = solve(
        model,
        amplitudes_m / scale[mode - 1],
        mode=mode,
        settings=HarmonicSettings(harmonics=_TRUTH_HARMONICS),
    )
    coefficients = solution.coefficients[..., 1:7]  # harmonics 1–3
    cos, sin = coefficients[..., 0::2], coefficients[..., 1::2]
    amplitude = np.hypot(cos, sin) * np.abs(scale)[:, None]
    phase = np.arctan2(-sin, cos)
    relative = phase - np.arange(1, 4) * phase[:, mode - 1, None, :1]
    return ModeBackboneTruth(
        mode=mode,
        problem=problem,
        reference_point=int(points[mode - 1]) + 1,
        amplitude_mm=1e3 * solution.amplitude_m * abs(scale[mode - 1]),
        frequency_hz=solution.frequency_hz,
        damping_ratio=solution.damping_ratio,
        participation_mm=1e3 * amplitude,
        participation_phase_deg=np.degrees(np.angle(np.exp(1j * relative))),
        energy_share=solution.energy_share,
        base_acceleration_m_s2=(
            solution.base_acceleration[..., 1]
            if problem == "phase_resonance"
            else np.full(solution.frequency_hz.shape, np.nan)
        ),
    )


def _with_parameters(model: ModalModel, values: Mapping[str, float]) -> ModalModel:
    """A copy of ``model`` with modal parameters ``mode{m}.{field}`` and ``coupling{i}`` set."""
    modes, couplings = list(model.modes), list(model.couplings)
    for name, value in values.items():
        head, _, tail = name.partition(".")
        if head.startswith("mode") and tail:
            m = int(head[4:]) - 1
            modes[m] = dataclasses.replace(modes[m], **{tail: value})
        elif head.startswith("coupling"):
            i = int(head[8:]) - 1
            couplings[i] = dataclasses.replace(couplings[i], coefficient=value)
        else:
            raise ValueError(f"ModalRig.variability: cannot spread {name!r}")
    return dataclasses.replace(model, modes=tuple(modes), couplings=tuple(couplings))


@dataclass(frozen=True)
class ModalRig:
    """A lab rig for a structure of several modes (see the module notes).

    Attributes
    ----------
    model
        Nominal ground truth; its modal coordinates are the modes' displacements at
        their reference points.
    levels_v
        Shaker voltages of the holds (``pll``), in test order (V).
    shaker_gain
        Coil acceleration per volt (m/s² per V).
    mode
        The mode the PLL locks (from 1).
    test
        ``"pll"`` or ``"free-decay"``.
    decay_start
        ``"impulse"`` or ``"release"`` (free decays).
    decay_amplitude_m
        Mode 1's initial amplitude at its reference point in a free decay (m).
    decay_point
        Panel point (from 1) hit or pulled in a free decay.
    decay_s
        Duration of a free decay after the release (s).
    shapes
        ``(15, N)`` mode shapes at the panel points (default :func:`plate_shapes`).
    noise_m_s, hold_s, ramp_s, fs, variability, config, name, description
        As :class:`~identification.rig.rig.Rig` (``variability`` names
        ``mode{m}.frequency_hz``, ``mode{m}.damping_ratio``, ``mode{m}.participation``
        or ``coupling{i}``).
    shaker, controller, drift, sensors
        The lab's artefacts (:mod:`identification.rig.conditions`); the shaker's
        interaction must be 0 (see :mod:`identification.rig.modal_engine`).
    """

    model: ModalModel
    levels_v: tuple[float, ...] = (1.0,)
    shaker_gain: float = 10.0
    mode: int = 1
    test: str = "pll"
    decay_start: str = "impulse"
    decay_amplitude_m: float = 2e-3
    decay_point: int = 9
    decay_s: float = 3.0
    shapes: tuple[tuple[float, ...], ...] | None = None
    noise_m_s: float = 1e-4
    hold_s: float = 2.5
    ramp_s: float = 0.1
    fs: float = 10_000.0
    variability: Mapping[str, float] = field(default_factory=dict)
    config: str = "1"
    name: str = ""
    description: str = ""
    shaker: Shaker = field(default_factory=Shaker)
    controller: Controller = field(default_factory=Controller)
    drift: Drift = field(default_factory=Drift)
    sensors: Sensors = field(default_factory=Sensors)
    amplitudes_m: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        n = self.model.n_modes
        shapes = plate_shapes()[:, :n] if self.shapes is None else np.asarray(self.shapes, float)
        if shapes.shape != (N_PANEL_POINTS, n) or not np.isfinite(shapes).all():
            raise ValueError(f"ModalRig.shapes must be ({N_PANEL_POINTS}, {n}) finite values")
        object.__setattr__(self, "shapes", tuple(map(tuple, shapes)))
        if self.test not in TESTS:
            raise ValueError(f"ModalRig.test must be one of {TESTS}, got {self.test!r}")
        if self.decay_start not in DECAY_STARTS:
            raise ValueError(f"ModalRig.decay_start must be one of {DECAY_STARTS}")
        if not 1 <= self.mode <= n:
            raise ValueError(f"ModalRig.mode must be 1..{n}, got {self.mode}")
        if not 1 <= self.decay_point <= N_PANEL_POINTS:
            raise ValueError(f"ModalRig.decay_point must be 1..{N_PANEL_POINTS}")
        if self.shaker.interaction != 0.0:
            raise ValueError("ModalRig: the shaker-structure interaction is not modelled (set 0)")
        for name in ("shaker_gain", "fs", "hold_s", "decay_s", "decay_amplitude_m"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"ModalRig.{name} must be finite and > 0, got {value}")
        known = set(self.model.parameter_names) | {"shaker_gain"}
        for key, spread in self.variability.items():
            if key not in known or key.startswith("joint"):
                raise ValueError(f"ModalRig.variability: cannot spread {key!r}")
            if not (math.isfinite(spread) and spread >= 0):
                raise ValueError(f"ModalRig.variability[{key!r}] must be finite and ≥ 0")
        object.__setattr__(self, "variability", dict(self.variability))
        record_name(self.config, 1)  # validates the label

    # ------------------------------------------------------------ building
    @property
    def shape_matrix(self) -> np.ndarray:
        """``(15, N)`` mode shapes at the panel points."""
        return np.asarray(self.shapes, dtype=float)

    @classmethod
    def for_amplitudes(
        cls,
        model: ModalModel,
        amplitudes_m: Sequence[float],
        mode: int = 1,
        shaker_gain: float = 10.0,
        schedule: str = "up",
        **options: Any,
    ) -> ModalRig:
        """A rig whose levels hold ``mode`` of the nominal ``model`` at the given amplitudes.

        Amplitudes (m) are the mode's fundamental at its reference point; the levels
        come from the harmonic balance's phase-resonant base acceleration;
        ``schedule="up-down"`` steps back down through them after the highest.
        """
        draft = cls(model, mode=mode, shaker_gain=shaker_gain, **options)
        amplitudes = np.asarray(amplitudes_m, dtype=float)
        solution = phase_resonance(
            model,
            amplitudes / _ref_scale(draft, mode),
            mode=mode,
            settings=HarmonicSettings(harmonics=_TRUTH_HARMONICS),
        )
        base = np.abs(solution.base_acceleration[..., 1])
        if not (solution.converged.all() and np.all(base > 0)):
            raise ValueError(
                f"{model.name or 'ModalModel'}: no phase-resonant level at some of "
                f"the amplitudes {amplitudes.tolist()} m of mode {mode}"
            )
        if schedule not in ("up", "up-down"):
            raise ValueError(f"schedule must be 'up' or 'up-down', got {schedule!r}")
        if schedule == "up-down":
            base = np.concatenate([base, base[-2::-1]])
        return dataclasses.replace(
            draft,
            levels_v=tuple(map(float, base / shaker_gain)),
            amplitudes_m=tuple(map(float, amplitudes)),
        )

    @classmethod
    def preset(
        cls,
        name: str,
        /,
        levels: int = 10,
        amplitude_range_mm: tuple[float, float] | None = None,
        ratio: float | None = None,
        test: str = "pll",
        mode: int = 1,
        model: ModalModel | None = None,
        **options: Any,
    ) -> ModalRig:
        """A rig from :data:`identification.rig.presets.MODAL_RIG_PRESETS`.

        ``ratio`` sets the second mode's frequency over the first's (default the
        preset's); the amplitudes (default the preset's range for the locked mode)
        are spaced geometrically; ``test`` and ``mode`` pick the test; ``model``
        replaces the preset's model (a variant of it: the preset's lab, variability
        and amplitudes kept); ``options`` override the preset's settings (the rig's own
        ``name`` among them: the preset's name is positional).
        """
        from identification.rig.presets import MODAL_RIG_PRESETS

        if name not in MODAL_RIG_PRESETS:
            raise ValueError(
                f"unknown modal rig preset {name!r}; available: {', '.join(MODAL_RIG_PRESETS)}"
            )
        preset = MODAL_RIG_PRESETS[name]
        model = preset.model(ratio) if model is None else model
        low, high = amplitude_range_mm or preset.amplitude_range_mm[mode - 1]
        if not (0 < low < high and math.isfinite(high)) or levels < 1:
            raise ValueError(f"need levels ≥ 1 and 0 < low < high, got {levels}, {(low, high)}")
        settings = {
            "variability": dict(preset.variability),
            "name": name,
            "description": preset.description,
            **preset.lab,
            "test": test,
            **options,
        }
        amplitudes = 1e-3 * np.geomspace(low, high, levels)
        if test == "free-decay":
            settings.pop("schedule", None)
            return cls(model, mode=mode, amplitudes_m=tuple(amplitudes), **settings)
        return cls.for_amplitudes(model, amplitudes, mode=mode, **settings)

    # ------------------------------------------------------------ drawing
    def draw(self, rng: np.random.Generator) -> tuple[ModalModel, float]:
        """One assembly: the model and shaker gain with their lognormal spreads applied."""
        factors = {
            k: math.exp(s * rng.standard_normal()) for k, s in sorted(self.variability.items())
        }
        gain = self.shaker_gain * factors.pop("shaker_gain", 1.0)
        nominal = self._parameter_values()
        return _with_parameters(self.model, {k: nominal[k] * f for k, f in factors.items()}), gain

    def _parameter_values(self) -> dict[str, float]:
        values = {}
        for m, spec in enumerate(self.model.modes, start=1):
            for name in ("frequency_hz", "damping_ratio", "participation"):
                values[f"mode{m}.{name}"] = getattr(spec, name)
        for i, coupling in enumerate(self.model.couplings, start=1):
            values[f"coupling{i}"] = coupling.coefficient
        return values

    # ------------------------------------------------------------ records
    def _samples(self) -> tuple[int, int]:
        return round(self.ramp_s * self.fs), round(self.hold_s * self.fs)

    def steps(self) -> StepSchedule:
        """The level schedule (V): the PLL's ramps and holds, or a decay's hold and release."""
        source = f"Config{self.config}_PRT_amplitude_steps"
        if self.test == "free-decay":
            held = self._decay_head() - 1
            end = held + 1 + round(self.decay_s * self.fs)
            return StepSchedule(
                [0.0, held / self.fs, (held + 1) / self.fs, end / self.fs],
                [1.0, 1.0, 0.0, 0.0],
                source=source,
            )
        return level_steps(self.levels_v, *self._samples(), self.fs, self.config)

    def _decay_head(self) -> int:
        """Samples before the release (the panel held, or at rest before the hit)."""
        return round(0.05 * self.fs)

    def modes(self) -> Modes:
        """The linear modes of the nominal model at the panel points (the modes file).

        Shapes are those of the truth's modal coordinates; frequencies those of the
        model linearised at rest (joint elements stuck), which the joint's linear parts
        couple slightly, so its modes are the coordinates' to within that coupling.
        """
        return Modes(self.shape_matrix, small_amplitude_frequencies_hz(self.model))

    def _n_samples(self) -> int:
        if self.test == "free-decay":
            return self._decay_head() + round(self.decay_s * self.fs)
        ramp, hold = self._samples()
        return len(self.levels_v) * (ramp + hold)

    def _initial_state(self, model: ModalModel) -> tuple[np.ndarray, np.ndarray]:
        """Modal displacements and velocities at the release or just after the hit."""
        phi = self.shape_matrix[self.decay_point - 1]
        omega = 2 * np.pi * np.array([m.frequency_hz for m in model.modes])
        if self.decay_start == "impulse":  # every mode's velocity ∝ its shape at the hit point
            velocity = phi * self.decay_amplitude_m * omega[0] / phi[0]
            return np.zeros_like(phi), velocity
        # a static point load: each mode deflected by its shape there over its stiffness
        return phi * (omega[0] / omega) ** 2 * self.decay_amplitude_m / phi[0], np.zeros_like(phi)

    def simulate(
        self,
        model: ModalModel,
        shaker_gain: float,
        rng: np.random.Generator,
        name: str,
        position: float = 0.0,
    ) -> tuple[Record, dict[str, Any]]:
        """One record of ``model`` and what its ground-truth entry says of the lab."""
        n = self._n_samples()
        channel_noise_m_s, noise, dropouts = sensor_draws(
            self.sensors, self.noise_m_s, rng, n, self.fs
        )
        shapes = self.shape_matrix
        lab: dict[str, Any] = {
            "position": position,
            "channel_noise_m_s": channel_noise_m_s.tolist(),
            "dropouts": [[c, s, v.size] for c, s, v in dropouts],
        }
        if self.test == "free-decay":
            eta, eta_dot = self._decay(model)
            base_velocity = np.zeros(n)
            frequency = phase = np.zeros(n)
            lab["initial_state"] = {
                "eta_m": eta[:, 0].tolist(),
                "eta_dot_m_s": eta_dot[:, 0].tolist(),
            }
        else:
            series = self._pll(model, shaker_gain, noise, position)
            eta_dot, base_velocity = series.eta_dot, series.base_velocity
            frequency, phase = series.frequency_hz, series.theta
            lab["natural_frequency_drift"] = list(self.drift.frequency(position))
            lab["sensor_gain"] = list(self.drift.gain(position))
        data = np.empty((n, 1 + N_PANEL_POINTS + N_BASE_POINTS + 2))
        data[:, 0] = np.arange(n) / self.fs
        data[:, 1 : 1 + N_PANEL_POINTS] = (shapes @ eta_dot).T + base_velocity[:, None]
        data[:, 1 + N_PANEL_POINTS : -2] = base_velocity[:, None]
        data[:, -2] = frequency
        data[:, -1] = np.degrees(np.angle(np.exp(1j * np.asarray(phase))))
        measured_channels(data, self.drift, position, noise, dropouts)
        return Record(data, self.steps(), name, modes=self.modes()), lab

    def _pll(self, model: ModalModel, shaker_gain: float, noise: np.ndarray, position: float):
        weights = lock_weights(self.shape_matrix, self.mode)
        # The noise the controller's channel carries: its panel channels' and the base's.
        sensed = np.vstack([noise[:, :N_PANEL_POINTS] @ weights, noise[:, N_PANEL_POINTS]])
        locked = model.modes[self.mode - 1]
        ramp, hold = self._samples()
        series = run_modal_lab(
            model,
            np.asarray(self.levels_v) * shaker_gain,
            fs=self.fs,
            ramp_samples=ramp,
            hold_samples=hold,
            response_weights=weights @ self.shape_matrix,
            weight_sum=float(weights.sum()),
            target_frequency_hz=locked.frequency_hz,
            target_damping_ratio=locked.damping_ratio,
            shaker=self.shaker,
            controller=self.controller,
            drift=self.drift,
            position=position,
            sensed=sensed,
        )
        if not series.completed:
            raise RuntimeError("the two-mode lab simulation diverged (|η| > 0.05 m or non-finite)")
        return series

    def _decay(self, model: ModalModel) -> tuple[np.ndarray, np.ndarray]:
        eta0, eta_dot0 = self._initial_state(model)
        head = self._decay_head()
        eta, eta_dot = free_decay(model, eta0, eta_dot0, self.fs, self._n_samples() - head)
        if self.decay_start == "impulse":  # at rest before the hit
            eta0 = np.zeros_like(eta0)
        return (
            np.hstack([np.repeat(eta0[:, None], head, axis=1), eta]),
            np.hstack([np.zeros((model.n_modes, head)), eta_dot]),
        )

    def truth_backbones(self, model: ModalModel) -> tuple[ModeBackboneTruth, ...]:
        """Every mode's backbone of ``model`` over the campaign's amplitudes (see the notes).

        PLL records: the phase-resonant backbone of each mode over the locked mode's
        amplitude range (the other modes from their own small-amplitude start to the
        same range at their reference points); decays: each mode's nonlinear mode from
        the decay's initial amplitude down.
        """
        if self.test == "pll":
            low, high = min(self.amplitudes_m), max(self.amplitudes_m)
        else:  # a decay passes through every amplitude below its start
            low, high = self.decay_amplitude_m / _DECAY_SPAN, self.decay_amplitude_m
        grid = np.geomspace(low / _TRUTH_MARGIN, high * _TRUTH_MARGIN, _TRUTH_POINTS)
        problem = "phase_resonance" if self.test == "pll" else "nonlinear_modes"
        modes = [self.mode] if self.test == "pll" else range(1, model.n_modes + 1)
        return tuple(_truth_backbone(model, m, grid, self.shape_matrix, problem) for m in modes)

    # ------------------------------------------------------------ campaigns
    def _jobs(self, assemblies: int, runs: int, seed: int) -> list[tuple]:
        return campaign_jobs(self.draw, self.config, assemblies, runs, seed)

    def _simulate_job(self, name, drawn, seeds, position) -> tuple[Record, dict[str, Any]]:
        model, gain = drawn
        record, lab = self.simulate(model, gain, np.random.default_rng(list(seeds)), name, position)
        truth = {
            "model": model.to_dict(),
            "shaker_gain": gain,
            "noise_m_s": self.noise_m_s,
            "seed": list(seeds),
            "lab": lab,
            "backbones": [b.to_dict() for b in self.truth_backbones(model)],
        }
        return record, truth

    # The campaign loop, its executors and its sidecar bookkeeping are the one-mode rig's.
    campaign = Rig.campaign
    write_campaign = Rig.write_campaign
    _write = Rig._write
    _open = Rig._open

    def _sidecar(self, records: dict[str, Any]) -> dict[str, Any]:
        return sidecar(
            self, MODAL_GROUND_TRUTH_FORMAT, records,
            after_model={"test": self.test, "mode": self.mode},
            after_levels={"amplitudes_m": list(self.amplitudes_m)},
            rest={
                "shapes": [list(row) for row in self.shapes],
                "reference_points": (reference_points(self.shape_matrix) + 1).tolist(),
                "lock_weights": lock_weights(self.shape_matrix, self.mode).tolist(),
                "decay": {
                    "start": self.decay_start,
                    "amplitude_m": self.decay_amplitude_m,
                    "point": self.decay_point,
                    "duration_s": self.decay_s,
                },
                "lab": {
                    "shaker": self.shaker.to_dict(),
                    "controller": self.controller.to_dict(),
                    "drift": self.drift.to_dict(),
                    "sensors": self.sensors.to_dict(),
                },
            },
        )  # fmt: skip


def _ref_scale(rig: ModalRig, mode: int) -> float:
    """The mode's shape at its reference point."""
    shapes = rig.shape_matrix
    return float(abs(shapes[reference_points(shapes)[mode - 1], mode - 1]))


def read_modal_ground_truth(folder: str | Path) -> dict[str, ModalRecordTruth]:
    """The per-record ground truth of a :class:`ModalRig` campaign folder, by record name."""
    path, data = read_sidecar(folder, MODAL_GROUND_TRUTH_FORMAT)
    return {
        name: ModalRecordTruth(
            model=ModalModel.from_dict(entry["model"], source=f"{path}: {name}"),
            shaker_gain=float(entry["shaker_gain"]),
            noise_m_s=float(entry["noise_m_s"]),
            seed=tuple(entry["seed"]),
            lab=entry["lab"],
            backbones=tuple(ModeBackboneTruth.from_dict(b) for b in entry["backbones"]),
        )
        for name, entry in data["records"].items()
    }
