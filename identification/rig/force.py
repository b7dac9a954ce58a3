"""The force-driven rig: phase-resonance records of a structure driven by a measured force.

A shaker attached through a force transducer (a stinger) drives the structure
at a point; a PLL holds the response's velocity in phase with the force while
the level is stepped, and at the end the amplifier is switched off and the
structure rings down. :class:`ForceRig` simulates that test on the ground
truth with the PLL simulator (:func:`identification.analytical.pll.simulate_pll`,
``reference="force"``) and writes it in the column layout
(:mod:`identification.measurements.columns`): ``time`` (s), the response
(``displacement``, ``velocity`` or ``acceleration``, SI), ``force`` (N),
``frequency`` (the oscillator's, Hz; held through the decay) and ``level`` (V;
0 once the amplifier is off).

The model is mass-normalised, ``ẍ + f(x, ẋ) = g·F``, with ``g`` the modal forcing
gain (1/kg, :attr:`ForceRig.forcing_gain`): the simulator's effective force
``−a_base`` is ``g·F``, so the rig's levels (V) times ``shaker_gain`` are the
amplitudes of ``g·F`` (m/s²), as for the base-driven rig. The recorded response
is the open-loop replay of the whole record (holds, ramps and decay) under the
recorded force, so response and force are consistent everywhere, the Jenkins
element's state through the switch-off included. The gain is in
``ground_truth.json`` (per record, ``forcing_gain``); the pipeline never reads it.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from identification.measurements.columns import (
    ColumnCampaign,
    ColumnLayout,
    ColumnRecord,
    write_columns,
)
from identification.measurements.quantities import QUANTITIES, check_choice
from identification.measurements.records import StepSchedule
from identification.model import JointModel
from identification.rig.rig import Rig

__all__ = ["ForceRig"]


@dataclass(frozen=True)
class ForceRig(Rig):
    """A virtual force-driven phase-resonance rig (see the module notes).

    Attributes
    ----------
    forcing_gain
        Modal forcing gain ``g`` (1/kg): 10 is a modal mass of 0.1 kg driven at the
        point where the mode is 1.
    response_quantity
        What the response sensor measures.
    force_noise_n
        RMS of the white noise on the force channel (N).
    decay_s
        Length of the ring-down after the amplifier is switched off (s).
    extension
        File type written: ``.h5`` or ``.csv``.

    The other fields are :class:`~identification.rig.rig.Rig`'s; ``noise_m_s`` is the
    response noise for a velocity sensor, scaled by the nominal ``ω₀^(p−1)`` for a
    displacement (``p = 0``) or an acceleration (``p = 2``).
    """

    forcing_gain: float = 10.0
    response_quantity: str = "velocity"
    force_noise_n: float = 1e-5
    decay_s: float = 1.0
    extension: str = ".h5"

    def __post_init__(self) -> None:
        super().__post_init__()
        check_choice("response quantity", self.response_quantity, QUANTITIES)
        for name in ("forcing_gain", "decay_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"ForceRig.{name} must be finite and > 0, got {value}")
        if not (math.isfinite(self.force_noise_n) and self.force_noise_n >= 0):
            raise ValueError(
                f"ForceRig.force_noise_n must be finite and ≥ 0, got {self.force_noise_n}"
            )
        if self.extension not in (".h5", ".csv"):
            raise ValueError(f"ForceRig.extension must be .h5 or .csv, got {self.extension!r}")

    @classmethod
    def preset(cls, name: str, levels: int = 10, amplitude_range_mm=(0.05, 2.0), **options: Any):
        """A force-driven rig of an ideal-rig preset (the lab presets are base-driven)."""
        from identification.rig.presets import RIG_PRESETS

        if name in RIG_PRESETS and RIG_PRESETS[name].lab is not None:
            raise ValueError(
                f"rig preset {name!r} runs the lab rig, which is base-driven; the force-driven "
                "rig takes the ideal-rig presets"
            )
        return super().preset(name, levels, amplitude_range_mm, **options)

    @property
    def layout(self) -> ColumnLayout:
        """How the written files read."""
        return ColumnLayout(
            response=self.response_quantity, quantity=self.response_quantity,
            excitation="force", excitation_kind="force", frequency="frequency", level="level",
        )  # fmt: skip

    def steps(self) -> StepSchedule:
        """The base rig's schedule, then the amplifier off (level 0) for ``decay_s``."""
        held = super().steps()
        end = held.time_s[-1] + 1 / self.fs
        stop = end + (round(self.decay_s * self.fs) - 1) / self.fs
        return StepSchedule([*held.time_s, end, stop], [*held.level, 0.0, 0.0], source="level")

    def _pll_config(self, model: JointModel):
        return dataclasses.replace(super()._pll_config(model), reference="force")

    def simulate(
        self, model: JointModel, shaker_gain: float, rng: np.random.Generator, name: str
    ) -> ColumnRecord:
        """One record of ``model`` driven through this rig's schedule, then its ring-down."""
        from identification.analytical.pll import simulate_base_excitation, simulate_pll

        result = simulate_pll(
            model, shaker_gain * np.asarray(self.levels_v), config=self._pll_config(model),
            record=True,
        )  # fmt: skip
        series = result.time_series
        ramp, hold = self._samples()
        if series.t.size != (ramp + hold) * len(self.levels_v):
            raise RuntimeError(f"{name}: the PLL simulation did not follow the fixed schedule")
        n_decay = round(self.decay_s * self.fs)
        t = np.arange(series.t.size + n_decay) / self.fs
        base_acceleration = np.concatenate([series.base_acceleration, np.zeros(n_decay)])
        x, v, a = simulate_base_excitation(model, t, base_acceleration)
        if not np.all(np.isfinite(x)):
            raise RuntimeError(f"{name}: the replay of the record diverged")
        omega0 = 2 * math.pi * self.model.linear_frequency_hz
        p = QUANTITIES.index(self.response_quantity)
        response = (x, v, a)[p] + rng.normal(0.0, self.noise_m_s * omega0 ** (p - 1), t.size)
        force = -base_acceleration / self.forcing_gain  # g·F = −a_base
        force = force + rng.normal(0.0, self.force_noise_n, t.size)
        frequency = np.concatenate([series.frequency_hz, np.full(n_decay, series.frequency_hz[-1])])
        return ColumnRecord(
            time_s=t, response=response, quantity=self.response_quantity, name=name,
            response_name=self.response_quantity, excitation=force, excitation_kind="force",
            excitation_name="force", frequency_channel=frequency, steps=self.steps(),
        )  # fmt: skip

    def _simulate_job(self, name, drawn, seeds, position):
        record, truth = super()._simulate_job(name, drawn, seeds, position)
        return record, {**truth, "forcing_gain": self.forcing_gain}

    def _write(self, record: ColumnRecord, folder: Path, formatting: dict) -> Path:
        extension = formatting.get("extension") or self.extension
        return write_columns(record, Path(folder) / f"{record.name}{extension}")

    def _open(self, folder: Path) -> ColumnCampaign:
        return ColumnCampaign(folder, self.layout)

    def _sidecar(self, records: dict[str, Any]) -> dict[str, Any]:
        sidecar = super()._sidecar(records)
        sidecar["rig"] |= {
            "excitation": "force", "forcing_gain": self.forcing_gain,
            "response_quantity": self.response_quantity, "force_noise_n": self.force_noise_n,
            "decay_s": self.decay_s,
        }  # fmt: skip
        return sidecar
