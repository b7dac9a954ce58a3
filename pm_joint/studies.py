"""Studies that run the library end to end on the virtual rig (used by bench/,
case_studies/ and slow tests; nothing in the library imports this module)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from identification.criticism.criticism import Criticism, Step, criticize
from identification.fitting.least_squares import fit_backbones
from identification.measurements.backbone import BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Record
from identification.model import JointModel
from identification.rig import RIG_PRESETS, Rig

__all__ = ["KEY_CHANNEL", "StudyResult", "hidden_effect_study"]


# --------------------------------------------------------------------------
# Hidden-effect studies


#: The channel whose error a hidden effect must take down (by ≥ 80 %) in the studies.
#: Damping effects leave the frequency at the noise level already; quadratic
#: stiffness is absorbed by the refitted cubic term in the backbone and shows
#: in the second harmonic of the records.
KEY_CHANNEL = {
    "hidden-cubic": "frequency_hz",
    "hidden-microslip": "frequency_hz",
    "hidden-two": "frequency_hz",
    "hidden-quadratic": "harmonics",
    "hidden-quadratic-damping": "damping_ratio",
    "hidden-coulomb": "damping_ratio",
}
_STEP_RMSE = {
    "frequency_hz": "frequency_rmse_hz",
    "damping_ratio": "damping_rmse",
    "harmonics": "harmonic_rmse",
}


@dataclass
class StudyResult:
    """One hidden-effect scenario run through the criticism loop.

    Keeps the measured backbones, the records and the fitted start model, so the
    same data can be criticised again another way.
    """

    scenario: str
    seed: int
    hidden: tuple[str, ...]
    measured: BackboneSet
    records: list[Record]
    start: JointModel
    criticisms: list[Criticism] = field(default_factory=list)

    @property
    def history(self) -> list[Step]:
        return self.criticisms[-1].history

    @property
    def added(self) -> list[str]:
        return [s.action[2:] for s in self.history if s.action.startswith("+ ")]

    @property
    def first(self) -> str | None:
        """The effect ranked first by the first criticism (None: nothing proposed)."""
        proposed = self.criticisms[0].missing()
        return proposed[0].effect if proposed else None

    def reduction(self, channel: str) -> float | None:
        """Fractional RMSE reduction of a channel from the start to the last step."""
        before, after = (getattr(s, _STEP_RMSE[channel]) for s in (self.history[0],
                                                                   self.history[-1]))  # fmt: skip
        return None if before is None or after is None else float(1 - after / before)

    @property
    def passed(self) -> bool:
        """Control: nothing proposed. Else: the hidden effect(s) found in as many
        rounds, the first of them ranked first, the key channel's error down ≥ 80 %."""
        if not self.hidden:
            return self.first is None
        key = self.reduction(KEY_CHANNEL[self.scenario])
        return (
            self.first in self.hidden
            and sorted(self.added) == sorted(self.hidden)
            and key is not None
            and key >= 0.8
        )

    def row(self) -> dict[str, Any]:
        """Table row: ranked first, what was added, RMSE per step, ΔIC per round."""
        return {
            "scenario": self.scenario,
            "seed": self.seed,
            "hidden": list(self.hidden),
            "ranked_first": self.first,
            "added": self.added,
            "delta_ic": [c.missing()[0].delta_ic for c in self.criticisms if c.missing()],
            "frequency_rmse_hz": [s.frequency_rmse_hz for s in self.history],
            "damping_rmse": [s.damping_rmse for s in self.history],
            "harmonic_rmse": [s.harmonic_rmse for s in self.history],
            "reduction": {c: self.reduction(c) for c in _STEP_RMSE},
            "key_channel": KEY_CHANNEL.get(self.scenario),
            "proposed_at_start": [c.effect for c in self.criticisms[0].missing()],
            "passed": self.passed,
        }


def hidden_effect_study(
    scenario: str,
    seed: int = 0,
    *,
    assemblies: int = 3,
    levels: int = 8,
    hold_s: float = 2.5,
    rounds: int = 3,
) -> StudyResult:
    """Run a rig scenario through the loop: fit the base model, criticise, add, repeat.

    The rig (:meth:`identification.rig.Rig.preset`) draws ``assemblies`` assemblies
    and their noise as :meth:`~identification.rig.Rig.write_campaign` does (seeds
    ``[seed, a]`` and ``[seed, a, 1]``) but keeps the records in memory. The
    user's starting model is the preset's base model with its coefficients
    fitted to the backbones alone (frequency and damping, as a user's first fit
    is); the criticism uses the harmonics the backbones carry too. Each round adds
    the effect ranked first, until nothing significant is missing or ``rounds``
    effects were added.
    """
    rig = Rig.preset(scenario, levels=levels, hold_s=hold_s)
    records = []
    for a in range(1, assemblies + 1):
        model, gain = rig.draw(np.random.default_rng([seed, a]))
        name = f"Config{rig.config}_PRT_Assemb{a}"
        records.append(rig.simulate(model, gain, np.random.default_rng([seed, a, 1]), name))
    measured = extract_backbones(records)
    start = fit_backbones(RIG_PRESETS[scenario].base_model, measured.without_harmonics()).model
    result = StudyResult(
        scenario, seed, RIG_PRESETS[scenario].hidden_effects, measured, records, start
    )
    crit = criticize(start, measured)
    result.criticisms.append(crit)
    for _ in range(rounds):
        proposed = crit.missing()
        if not proposed:
            break
        crit = crit.add(proposed[0].effect)
        result.criticisms.append(crit)
    return result
