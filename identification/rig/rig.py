"""Virtual test rig: phase-resonance records of a known ground truth.

A :class:`Rig` runs the PLL simulator (:func:`identification.analytical.pll.simulate_pll`)
on a ground-truth :class:`~identification.model.JointModel` and writes what the
TRC rig would have recorded, in the TRC layout (:mod:`identification.measurements.records`),
so that the identification pipeline meets virtual and measured data through the
same door. Around the simulation it adds what makes a test a test:

* **Channels.** The 15 panel points move with a first-bending shape
  (:func:`first_bending_shape`): point ``j`` measures ``φ_j · v_rel + v_base``;
  the two base points measure ``v_base``. The frequency channel is the PLL
  oscillator's frequency (Hz) and the phase channel its phase θ (deg, wrapped to
  (−180°, 180°]), with the base acceleration ``A sin θ``.
* **Sensor noise.** Independent white Gaussian noise of ``noise_m_s`` m/s RMS on
  each of the 17 velocity channels (default 1e-4 m/s, a laser vibrometer on
  reflective tape at 10 kHz); the controller channels are noise-free.
* **Shaker.** Levels are shaker voltages (V); ``shaker_gain`` (m/s² per V)
  turns them into base-acceleration amplitudes.
* **Reassembly.** Each assembly draws its own model and gain: every entry of
  ``variability`` (a model parameter name or ``"shaker_gain"``) is multiplied
  by a lognormal factor ``exp(s·N(0,1))`` with ``s`` the given relative spread.
  Runs of one assembly share the draw and differ in their noise.
* **Schedule.** A fixed-time schedule, as in the TRC tests where one step file
  serves every assembly of a configuration: each level is approached by a ramp
  of ``ramp_s`` and held for ``hold_s`` while the PLL tracks phase resonance.

Every campaign folder gets a ``ground_truth.json`` sidecar (per record: the
drawn model, shaker gain, noise level, seed) for tests and studies; the
identification pipeline never reads it.

Presets (:data:`RIG_PRESETS`, :meth:`Rig.preset`) include one scenario per
hidden effect for model criticism: a *base model* a user would start from and a
ground truth that adds the hidden effect(s) at a level that shows clearly in
the backbone over 0.05–2 mm.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import ArrayLike

from identification.artifacts import atomic_write_text, versions
from identification.measurements.records import (
    CENTRE_POINT,
    N_BASE_POINTS,
    N_PANEL_POINTS,
    Campaign,
    Modes,
    Record,
    StepSchedule,
    record_name,
    write_record,
)
from identification.model import JointModel

__all__ = [
    "GROUND_TRUTH_FILE",
    "RecordTruth",
    "Rig",
    "campaign_jobs",
    "first_bending_shape",
    "level_steps",
    "levels_for_amplitudes",
    "read_ground_truth",
    "read_sidecar",
    "sidecar",
    "trc_channels",
]

GROUND_TRUTH_FILE = "ground_truth.json"
#: PLLConfig fields the rig sets itself to hold its fixed-time schedule.
_SCHEDULE_OPTIONS = {
    "fs",
    "n_periods",
    "lock_tolerance_deg",
    "lock_periods",
    "max_hold_s",
    "ramp_s",
}
_FORMAT = "pm-joint/rig-ground-truth"
_GRID = (5, 3)  # points along the length × across the width, numbered row by row


def first_bending_shape(width_variation: float = 0.1) -> np.ndarray:
    """First bending mode at the 15 panel points, 1 at the centre (point 8).

    ``sin(π ξ)`` along the length (points at ξ = 1/6 … 5/6 between the clamped
    ends) times ``1 − width_variation·(2η − 1)²`` across the width (η = 1/4,
    1/2, 3/4), numbered row by row, three points per position along the length.
    """
    xi = np.arange(1, _GRID[0] + 1) / (_GRID[0] + 1)
    eta = np.arange(1, _GRID[1] + 1) / (_GRID[1] + 1)
    shape = np.outer(np.sin(np.pi * xi), 1 - width_variation * (2 * eta - 1) ** 2).ravel()
    return shape / shape[CENTRE_POINT - 1]


def trc_channels(
    time_s: ArrayLike,
    relative_velocity: ArrayLike,
    base_velocity: ArrayLike,
    frequency_hz: ArrayLike,
    phase_rad: ArrayLike,
    mode_shape: ArrayLike | None = None,
    noise_m_s: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """The (n, 20) TRC data columns of a base-excited panel moving in one mode.

    Panel point ``j`` measures ``mode_shape[j] · relative_velocity + base_velocity``,
    both base points ``base_velocity``; every velocity channel gets independent
    white noise of ``noise_m_s`` RMS. The phase is written in degrees, wrapped.
    """
    t = np.asarray(time_s, dtype=float)
    v_rel = np.asarray(relative_velocity, dtype=float)
    v_base = np.asarray(base_velocity, dtype=float)
    shape = first_bending_shape() if mode_shape is None else np.asarray(mode_shape, float)
    if shape.shape != (N_PANEL_POINTS,):
        raise ValueError(f"mode_shape must have {N_PANEL_POINTS} values, got shape {shape.shape}")
    if not (math.isfinite(noise_m_s) and noise_m_s >= 0):
        raise ValueError(f"noise_m_s must be finite and ≥ 0, got {noise_m_s}")
    data = np.empty((t.size, 1 + N_PANEL_POINTS + N_BASE_POINTS + 2))
    data[:, 0] = t
    data[:, 1 : 1 + N_PANEL_POINTS] = np.outer(v_rel, shape) + v_base[:, None]
    data[:, 1 + N_PANEL_POINTS : -2] = v_base[:, None]
    if noise_m_s > 0:
        rng = np.random.default_rng() if rng is None else rng
        data[:, 1:-2] += rng.normal(0.0, noise_m_s, (t.size, N_PANEL_POINTS + N_BASE_POINTS))
    data[:, -2] = frequency_hz
    data[:, -1] = np.degrees(np.angle(np.exp(1j * np.asarray(phase_rad, dtype=float))))
    return data


def levels_for_amplitudes(model: JointModel, amplitudes_m: ArrayLike) -> np.ndarray:
    """Base-acceleration amplitudes (m/s²) that hold ``model`` at the given amplitudes.

    From the single-harmonic backbone (:func:`identification.analytical.harmonic.backbone`),
    accurate enough to place a test's levels.
    """
    from identification.analytical.harmonic import backbone

    result = backbone(model, amplitudes_m, method="single")
    excitation_m_s2 = result.base_acceleration
    if not (result.converged.all() and np.all(excitation_m_s2 > 0)):
        raise ValueError(
            f"model {model.name or model.equation()!r} has no positive phase-resonant excitation "
            f"at some of the amplitudes {np.asarray(amplitudes_m)} m (negative net damping?)"
        )
    return excitation_m_s2


def level_steps(
    levels_v: Sequence[float], ramp: int, hold: int, fs: float, config: str
) -> StepSchedule:
    """A fixed-time level schedule (V): rest, then per level a ramp of ``ramp`` samples and a
    hold of ``hold`` samples at ``fs``; the step file of configuration ``config``."""
    time, level = [0.0], [0.0]
    for j, volts in enumerate(levels_v):
        start = j * (ramp + hold) + ramp
        time += [start / fs, (start + hold - 1) / fs]
        level += [volts, volts]
    return StepSchedule(time, level, source=f"Config{config}_PRT_amplitude_steps")


def campaign_jobs(
    draw: Callable[[np.random.Generator], Any], config: str, assemblies: int, runs: int, seed: int
) -> list[tuple]:
    """``(name, assembly draw, seeds, campaign position)`` of every record, in test order.

    Assembly ``a`` draws from ``default_rng([seed, a])``; run ``r`` of it gets the seeds
    ``(seed, a, r)``; the position runs from 0 (first record) to 1 (last).
    """
    if assemblies < 1 or runs < 1:
        raise ValueError(f"assemblies and runs must be ≥ 1, got {assemblies}, {runs}")
    jobs = []
    for a in range(1, assemblies + 1):
        drawn = draw(np.random.default_rng([seed, a]))
        for r in range(1, runs + 1):
            name = record_name(config, a, r if runs > 1 else None)
            jobs.append((name, drawn, (seed, a, r)))
    last = max(len(jobs) - 1, 1)
    return [(*job, i / last) for i, job in enumerate(jobs)]


@dataclass(frozen=True)
class RecordTruth:
    """Ground truth of one virtual record (from ``ground_truth.json``)."""

    model: JointModel
    shaker_gain: float
    noise_m_s: float
    seed: tuple[int, ...]
    lab: Mapping[str, Any] | None = None


@dataclass(frozen=True)
class Rig:
    """A virtual phase-resonance test rig.

    Attributes
    ----------
    model
        Nominal ground truth.
    levels_v
        Shaker voltages of the hold phases, in test order (V).
    shaker_gain
        Base-acceleration amplitude per volt (m/s² per V).
    noise_m_s
        RMS of the white noise on every velocity channel (m/s).
    hold_s, ramp_s
        Duration of each hold phase and of the ramp before it (s).
    fs
        Sampling rate (Hz).
    variability
        Relative lognormal spread per model parameter name (or ``"shaker_gain"``)
        drawn for each assembly.
    mode_shape
        First bending shape at the 15 panel points (default :func:`first_bending_shape`).
    config
        Configuration label of the written files (``ConfigN_…``).
    name, description
        Preset name and what the scenario is.
    base_model
        The model a user would start from (presets with a hidden effect).
    hidden_effects
        Effects in the ground truth that ``base_model`` lacks.
    pll_options
        Other :class:`~identification.analytical.pll.PLLConfig` settings (the rig senses the
        relative velocity against the base velocity, with the fastest loop).
    """

    model: JointModel
    levels_v: tuple[float, ...]
    shaker_gain: float = 10.0
    noise_m_s: float = 1e-4
    hold_s: float = 2.5
    ramp_s: float = 0.1
    fs: float = 10_000.0
    variability: Mapping[str, float] = field(default_factory=dict)
    mode_shape: tuple[float, ...] = field(default_factory=lambda: tuple(first_bending_shape()))
    config: str = "1"
    name: str = ""
    description: str = ""
    base_model: JointModel | None = None
    hidden_effects: tuple[str, ...] = ()
    pll_options: Mapping[str, Any] = field(default_factory=dict)

    #: Whether the class takes a preset's lab settings (the lab engine does).
    takes_lab_settings: ClassVar[bool] = False

    def __post_init__(self) -> None:
        drive_v = tuple(float(v) for v in np.atleast_1d(self.levels_v))
        if not drive_v or not all(math.isfinite(v) and v > 0 for v in drive_v):
            raise ValueError(f"Rig.levels_v must be finite voltages > 0, got {self.levels_v}")
        object.__setattr__(self, "levels_v", drive_v)
        for name in ("shaker_gain", "hold_s", "fs"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"Rig.{name} must be finite and > 0, got {value}")
        for name in ("noise_m_s", "ramp_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"Rig.{name} must be finite and ≥ 0, got {value}")
        known = set(self._variable_parameters())
        for key, spread in self.variability.items():
            if key not in known:
                raise ValueError(f"Rig.variability: unknown parameter {key!r}; use {sorted(known)}")
            if not (math.isfinite(spread) and spread >= 0):
                raise ValueError(f"Rig.variability[{key!r}] must be finite and ≥ 0, got {spread}")
        object.__setattr__(self, "variability", dict(self.variability))
        shape = np.asarray(self.mode_shape, dtype=float)
        if shape.shape != (N_PANEL_POINTS,) or not np.isfinite(shape).all():
            raise ValueError(f"Rig.mode_shape must be {N_PANEL_POINTS} finite values")
        object.__setattr__(self, "mode_shape", tuple(shape))
        record_name(self.config, 1)  # validates the label
        fixed = _SCHEDULE_OPTIONS & set(self.pll_options)
        if fixed:
            raise ValueError(
                f"Rig.pll_options cannot set {sorted(fixed)}: the rig's own fields set the schedule"
            )
        object.__setattr__(self, "pll_options", dict(self.pll_options))

    # ------------------------------------------------------------ building
    @classmethod
    def for_amplitudes(
        cls, model: JointModel, amplitudes_m: ArrayLike, shaker_gain: float = 10.0, **options: Any
    ) -> Rig:
        """A rig whose levels hold the nominal ``model`` at the given amplitudes (m)."""
        drive_v = levels_for_amplitudes(model, amplitudes_m) / shaker_gain
        return cls(model, tuple(drive_v), shaker_gain=shaker_gain, **options)

    @classmethod
    def preset(
        cls,
        name: str,
        levels: int = 10,
        amplitude_range_mm: tuple[float, float] = (0.05, 2.0),
        **options: Any,
    ) -> Rig:
        """A rig from :data:`RIG_PRESETS`; lab scenarios: :func:`identification.rig.rig_for_preset`.

        Parameters
        ----------
        name
            Preset name.
        levels
            Number of hold phases, stepping up through amplitudes spaced
            geometrically over ``amplitude_range_mm`` (for the nominal model).
        amplitude_range_mm
            Smallest and largest target amplitude (mm).
        **options
            Any other :class:`Rig` field (``hold_s``, ``noise_m_s``, ``variability``, …).
        """
        from identification.rig.presets import RIG_PRESETS  # presets build on this module

        try:
            preset = RIG_PRESETS[name]
        except KeyError:
            raise ValueError(
                f"unknown rig preset {name!r}; available: {', '.join(RIG_PRESETS)}"
            ) from None
        low, high = amplitude_range_mm
        if not (0 < low < high and math.isfinite(high)) or levels < 1:
            raise ValueError(
                f"need levels ≥ 1 and 0 < low < high, got {levels}, {amplitude_range_mm}"
            )
        amplitudes = 1e-3 * np.geomspace(low, high, levels)
        if preset.lab is not None and not cls.takes_lab_settings:
            raise ValueError(
                f"rig preset {name!r} is a lab scenario: build it with "
                "identification.rig.rig_for_preset (or LabRig.preset)"
            )
        settings = {
            "variability": dict(preset.variability),
            "name": name,
            "description": preset.description,
            "base_model": preset.base_model,
            "hidden_effects": preset.hidden_effects,
            **(preset.lab or {}),
            **options,
        }
        return cls.for_amplitudes(preset.model, amplitudes, **settings)

    # ------------------------------------------------------------ drawing
    def _variable_parameters(self) -> list[str]:
        """Names ``variability`` may spread."""
        return [*self.model.parameter_names, "shaker_gain"]

    def _factors(self, rng: np.random.Generator) -> dict[str, float]:
        """One lognormal factor per entry of ``variability``, drawn in name order."""
        return {k: math.exp(s * rng.standard_normal()) for k, s in sorted(self.variability.items())}

    def draw(self, rng: np.random.Generator) -> tuple[JointModel, float]:
        """One assembly: the model and shaker gain with their lognormal spreads applied."""
        factors = self._factors(rng)
        gain = self.shaker_gain * factors.pop("shaker_gain", 1.0)
        values = {k: self.model.parameters[k] * f for k, f in factors.items()}
        return self.model.with_parameters(values), gain

    def _draw_job(self, rng: np.random.Generator) -> Any:
        """What :meth:`_simulate_job` needs of one assembly."""
        return self.draw(rng)

    # ------------------------------------------------------------ running
    def steps(self) -> StepSchedule:
        """The fixed-time level schedule (V): rest, then per level a ramp and a hold."""
        return level_steps(self.levels_v, *self._samples(), self.fs, self.config)

    def modes(self) -> Modes:
        """The configuration's linear first bending mode (nominal model)."""
        return Modes(np.asarray(self.mode_shape)[:, None], [self.model.linear_frequency_hz])

    def _samples(self) -> tuple[int, int]:
        return round(self.ramp_s * self.fs), round(self.hold_s * self.fs)

    def simulate(
        self, model: JointModel, shaker_gain: float, rng: np.random.Generator, name: str
    ) -> Record:
        """One record of ``model`` driven through this rig's schedule."""
        from identification.analytical.pll import simulate_pll

        ramp, hold = self._samples()
        result = simulate_pll(
            model, shaker_gain * np.asarray(self.levels_v), config=self._pll_config(model),
            record=True,
        )  # fmt: skip
        series = result.time_series
        expected = ramp + hold
        lengths = np.diff(series.holds, axis=1).ravel() + ramp
        if series.t.size != expected * len(self.levels_v) or np.any(lengths != expected):
            raise RuntimeError(
                f"{name}: the PLL simulation did not follow the fixed schedule "
                f"(diverged or stopped early; hold ranges {series.holds.tolist()})"
            )
        data = trc_channels(
            series.t, series.v, series.base_velocity, series.frequency_hz, series.phase,
            self.mode_shape, self.noise_m_s, rng,
        )  # fmt: skip
        return Record(data, self.steps(), name, modes=self.modes())

    def _pll_config(self, model: JointModel):
        from identification.analytical.pll import PLLConfig

        # The simulator ends a hold once it has locked and measured; a fixed-time
        # schedule needs every hold to run its full length, so the lock detector
        # gets a criterion it cannot meet (a phase error below 1e-300° for half
        # the hold) while the PI controller tracks resonance as usual. `simulate`
        # checks that every hold ran its full length.
        f0 = model.linear_frequency_hz
        options = {
            "sensing": "velocity",
            "reference": "base_velocity",
            # The fastest loop the simulator allows (pole at ω₀/30): the backbone moves
            # by several hertz between levels and the holds are short.
            "bandwidth_ratio": 1e3,
            **self.pll_options,
        }
        return PLLConfig(
            fs=self.fs,
            n_periods=1,
            lock_tolerance_deg=1e-300,
            lock_periods=max(1, int(0.5 * self.hold_s * f0) - 1),
            max_hold_s=self.hold_s,
            ramp_s=self.ramp_s,
            **options,
        )

    def _jobs(self, assemblies: int, runs: int, seed: int) -> list[tuple]:
        """``(name, assembly draw, seeds, campaign position)`` of every record, in test order."""
        return campaign_jobs(self._draw_job, self.config, assemblies, runs, seed)

    def _simulate_job(
        self, name: str, drawn: Any, seeds: Sequence[int], position: float
    ) -> tuple[Record, dict[str, Any]]:
        """One record of a campaign and its ground-truth entry."""
        model, gain = drawn
        record = self.simulate(model, gain, np.random.default_rng(list(seeds)), name)
        truth = {
            "model": model.to_dict(),
            "shaker_gain": gain,
            "noise_m_s": self.noise_m_s,
            "seed": list(seeds),
        }
        return record, truth

    def campaign(
        self, assemblies: int = 3, runs: int = 1, seed: int = 0
    ) -> list[tuple[Record, dict[str, Any]]]:
        """The records of :meth:`write_campaign`, in memory, each with its ground-truth entry.

        The same draws and noise as :meth:`write_campaign` with the same arguments.
        """
        return [self._simulate_job(*job) for job in self._jobs(assemblies, runs, seed)]

    def write_campaign(
        self,
        folder: str | Path,
        assemblies: int = 3,
        runs: int = 1,
        seed: int = 0,
        comma: bool = False,
        extension: str = "",
        precision: int = 6,
        executor: Any = None,
        progress: bool = False,
    ) -> Campaign:
        """Simulate and write a campaign: every assembly × run, plus ``ground_truth.json``.

        Records are named ``Config{config}_PRT_Assemb{a}[_{r}]`` (the run only
        when ``runs > 1``). Assembly ``a`` draws its model from
        ``default_rng([seed, a])``, run ``r`` its noise from
        ``default_rng([seed, a, r])``. With an ``executor``
        (``concurrent.futures``-style, e.g. a process pool or a dask Client) each
        record is simulated and written there; formatting the text takes as long
        as the simulation. Velocities are written with ``precision`` digits after
        the point, far below the sensor noise; at 6 a sample takes about 280 bytes
        (10 levels of 2.6 s at 10 kHz: about 75 MB per record).

        ``ground_truth.json`` is rewritten (atomically) after every record, so
        whatever is on disk when a run stops has its truth beside it; the first
        failure is raised after the records that did finish are accounted for.
        """
        folder = Path(folder)
        jobs = self._jobs(assemblies, runs, seed)
        formatting = {"comma": comma, "extension": extension, "precision": precision}
        if executor is None:  # one record in memory at a time, stop at the first failure
            outcomes = (_write_job(self, folder, formatting, *job) for job in jobs)
        else:
            futures = [executor.submit(_write_job, self, folder, formatting, *job) for job in jobs]
            outcomes = (_outcome(future) for future in futures)
        if progress:
            from tqdm.auto import tqdm

            outcomes = tqdm(outcomes, total=len(jobs), desc="rig records", unit="record")
        truth, failure = {}, None
        sidecar = self._sidecar(truth)  # holds ``truth`` itself, which fills below
        for job, outcome in zip(jobs, outcomes, strict=True):
            if isinstance(outcome, Exception):
                failure = failure or outcome
                continue
            truth[job[0]] = outcome[1]
            atomic_write_text(folder / GROUND_TRUTH_FILE, json.dumps(sidecar, indent=2))
        if failure is not None:
            raise failure
        return self._open(folder)

    def _write(self, record: Record, folder: Path, formatting: dict) -> Path:
        """Write one record (the TRC layout)."""
        return write_record(record, folder, **formatting)

    def _open(self, folder: Path) -> Campaign:
        """The campaign of a folder this rig wrote."""
        return Campaign(folder)

    def _sidecar(self, records: dict[str, Any]) -> dict[str, Any]:
        return sidecar(
            self, _FORMAT, records,
            after_model={
                "base_model": None if self.base_model is None else self.base_model.to_dict(),
                "hidden_effects": list(self.hidden_effects),
            },
            after_levels={},
            rest={"mode_shape": list(self.mode_shape)},
        )  # fmt: skip


def sidecar(
    rig: Any,
    format_name: str,
    records: dict[str, Any],
    *,
    after_model: dict[str, Any],
    after_levels: dict[str, Any],
    rest: dict[str, Any],
) -> dict[str, Any]:
    """A campaign's ``ground_truth.json`` content: what every rig says of itself, and its own.

    ``rig`` is a :class:`Rig` or a rig of several modes; its own entries come after
    its nominal model, after its levels and at the end (the order the files have).
    """
    return {
        "format": format_name,
        "version": 1,
        "versions": versions(),
        "rig": {
            "name": rig.name,
            "description": rig.description,
            "nominal_model": rig.model.to_dict(),
            **after_model,
            "levels_v": list(rig.levels_v),
            **after_levels,
            "shaker_gain": rig.shaker_gain,
            "noise_m_s": rig.noise_m_s,
            "hold_s": rig.hold_s,
            "ramp_s": rig.ramp_s,
            "fs": rig.fs,
            "variability": rig.variability,
            **rest,
        },
        "records": records,
    }


def _write_job(
    rig: Rig, folder: Path, formatting: dict, name: str, drawn: Any, seeds, position: float
) -> tuple[Path, dict[str, Any]]:
    """Simulate and write one record; its path and truth (module level: executors pickle it)."""
    record, truth = rig._simulate_job(name, drawn, seeds, position)
    return rig._write(record, folder, formatting), truth


def _outcome(future) -> Any:
    """A future's result, or the exception it raised (so later records still count)."""
    try:
        return future.result()
    except Exception as exc:  # re-raised by write_campaign after its bookkeeping
        return exc


def read_sidecar(folder: str | Path, format_name: str) -> tuple[Path, dict[str, Any]]:
    """The path and content of a campaign folder's ``ground_truth.json`` of ``format_name``."""
    path = Path(folder) / GROUND_TRUTH_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: cannot read the rig's ground truth ({exc})") from None
    if data.get("format") != format_name:
        raise ValueError(f"{path}: not a rig ground-truth file (format {data.get('format')!r})")
    return path, data


def read_ground_truth(folder: str | Path) -> dict[str, RecordTruth]:
    """The per-record ground truth of a rig campaign folder, by record name."""
    path, data = read_sidecar(folder, _FORMAT)
    return {
        name: RecordTruth(
            model=JointModel.from_dict(entry["model"], source=f"{path}: {name}"),
            shaker_gain=float(entry["shaker_gain"]),
            noise_m_s=float(entry["noise_m_s"]),
            seed=tuple(entry["seed"]),
            lab=entry.get("lab"),
        )
        for name, entry in data["records"].items()
    }
