"""Criticism of a one-mode model on data that carry a second mode, and on data that do not.

Cases (:data:`CASES`): two-mode data — the lab rig's ``lab-second-mode`` (a mode 5 % above
the first, coupled through the joint: near 1:1), the two-mode rig (``pm-joint rig --preset
two-mode``) at its 1:2 ratio and at a ratio near 1:1, the independent simulator's two-mode
system (:func:`independent_campaign`: no library code) at 1:2 and near 1:1 — and data whose
one-mode model lacks nothing: the two-mode rig with its second mode off the joint and
uncoupled (:data:`UNCOUPLED_CASES`), ``lab-pure`` and every lab hidden-effect preset.
Each campaign: 3 assemblies, 8 levels, the start model fitted to the backbones' frequency
and damping (a user's first fit), criticised with the harmonics
(:func:`identification.criticism.criticism.criticize`, defaults).

**Outcome rule** (fixed before any reported run, ``docs/criticism.md``, "A missing mode"):
a two-mode row *passes* when the verdict is "explained by a second mode", the frequency is
located (from block 12 000 000 by the second mode's participation where the campaign carries
it — the two-mode rig's 15 points, the independent simulator's second coordinate — else by
the two-mode refit; named by the screen or by the participation) and it is within
:data:`FREQUENCY_TOLERANCE` of the truth's second mode (its frequency at rest); a row named
at a located frequency outside it is counted apart (*wrong*: the statement the rule must
not make); a one-mode row *fails* when the verdict is "explained by a second mode" (located
or not). An uncoupled row (a second mode the sensors see that exchanges nothing) *fails*
when it is named as exchanging energy (any mechanism but "sensor") or at a frequency
outside the tolerance; named as seen beside the first (mechanism "sensor", from block
15 000 000, where the coordinate's fundamental places it) within the tolerance, or not
named, it passes. Acceptance (#27): ≥ 27 of 30 per two-mode case, ≤ 1 of 30 on one-mode data;
counts are reported with their two-sided 95 % Clopper–Pearson intervals
(:func:`studies.binomial.clopper_pearson`).
Seeds: tuning below :data:`~studies.seeds.HELD_OUT_SEED`, reported counts from it up.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from identification.criticism.config import Verdict
from identification.criticism.criticism import criticize
from identification.criticism.mode_columns import SENSOR
from identification.criticism.participation import ModeParticipation, ParticipationCurve
from identification.criticism.second_mode import Participation
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.modal_backbones import extract_modal_backbones
from identification.model import JointModel
from identification.rig import (
    LAB_HIDDEN_SCENARIOS,
    LAB_OUT_OF_CATALOGUE_SCENARIOS,
    RIG_PRESETS,
    ModalRig,
)
from identification.rig.modal_rig import small_amplitude_frequencies_hz
from identification.rig.presets import MODAL_RIG_PRESETS, lab_hidden_scenario
from independent.campaigns import HOLD_S, HoldNoise, PopulationScatter
from independent.decays import ModalSystem, PotentialTerm
from independent.forces import CubicStiffness
from independent.modal_resonance import modal_phase_resonance
from studies.binomial import clopper_pearson
from studies.campaigns import first_fit, rig_campaign
from studies.rows import Row
from studies.seeds import is_held_out

__all__ = [
    "CASES",
    "FREQUENCY_TOLERANCE",
    "ONE_MODE_CASES",
    "TWO_MODE_CASES",
    "UNCOUPLED_CASES",
    "Count",
    "SecondModeRow",
    "count",
    "independent_campaign",
    "passes",
    "second_mode_campaign",
]

#: A named second mode counts when its frequency is within this share of the truth's.
FREQUENCY_TOLERANCE = 0.05
#: The independent simulator's two-mode campaigns (:func:`independent_campaign`).
INDEPENDENT = "independent"
#: Two-mode cases: name → (rig, ratio of the two-mode rig or None for a lab preset; the
#: independent simulator's ratio, :data:`INDEPENDENT`).
TWO_MODE_CASES: dict[str, tuple[str, float | None]] = {
    "lab-second-mode": ("lab-second-mode", None),
    "two-mode 1:2": ("two-mode", None),
    "two-mode near 1:1": ("two-mode", 1.06),
    "independent 1:2": (INDEPENDENT, 1.92),
    "independent near 1:1": (INDEPENDENT, 1.07),
}
#: Two modes that do not exchange energy: the two-mode rig with its second mode off the
#: joint and without the coupling (driven by the base, seen at the 15 points): the null of a
#: mode named from its participation (name → ratio).
UNCOUPLED_CASES: dict[str, float | None] = {
    "uncoupled 1:2": None,
    "uncoupled near 1:1": 1.06,
}
#: One-mode cases: the lab's pure null, every hidden catalogue effect, and the one-mode joints
#: out of the catalogue (a second mode must not be named for physics that is not one).
ONE_MODE_CASES: tuple[str, ...] = (
    *UNCOUPLED_CASES,
    "lab-pure",
    *LAB_HIDDEN_SCENARIOS,
    *(s for s in LAB_OUT_OF_CATALOGUE_SCENARIOS if s != "lab-second-mode"),
)
CASES: tuple[str, ...] = (*TWO_MODE_CASES, *ONE_MODE_CASES)
#: Assemblies and levels per branch of a campaign.
ASSEMBLIES, LEVELS = 3, 8
#: The one-mode model a two-mode rig campaign is criticised with: the joint's catalogue
#: effects (microslip on a cubic-hardening base), as a user reading one mode would fit.
_TWO_MODE_START = lab_hidden_scenario("microslip")


@dataclass(frozen=True)
class SecondModeRow(Row):
    """One campaign criticised.

    Attributes
    ----------
    case, seed
        The case (:data:`CASES`) and the campaign's seed.
    two_modes
        Whether the data carry a second mode.
    truth_hz
        The truth's second-mode frequency (NaN on one-mode data).
    verdict, p_value
        The criticism's.
    named_hz, ratio, share, mechanism, gain, catalogue_gain, threshold, why
        The second-mode finding (the frequency NaN where the refit does not locate it).
    passed
        The outcome rule (module notes).
    seconds
        Wall time of the row.
    located, low_hz, high_hz, screen_hz, location
        Whether the frequency was located, its interval, the linear screen's best frequency
        (a diagnostic) and why the frequency is not located.
    located_by, multi_point
        What located it (``"participation"``, ``"refit"``) and whether the criticism had the
        second mode's participation (several response points).
    named_by, exchange
        What named it (``"screen"``, ``"participation"``) and the χ² of the coupling's drive
        of the second mode's coordinate (NaN where not measured).
    """

    case: str
    seed: int
    two_modes: bool
    truth_hz: float
    verdict: str
    p_value: float
    named_hz: float
    ratio: float
    share: float
    mechanism: str
    gain: float
    catalogue_gain: float
    threshold: float
    why: str
    passed: bool
    seconds: float
    located: bool = False
    low_hz: float = float("nan")
    high_hz: float = float("nan")
    screen_hz: float = float("nan")
    location: str = ""
    located_by: str = ""
    multi_point: bool = False
    named_by: str = ""
    exchange: float = float("nan")

    @property
    def named(self) -> bool:
        return self.verdict == Verdict.SECOND_MODE

    @property
    def wrong(self) -> bool:
        """Named at a located frequency more than the tolerance from the truth's (where the
        data carry a second mode: two-mode and uncoupled rows)."""
        return (
            self.named
            and self.located
            and bool(np.isfinite(self.truth_hz))
            and not (abs(self.named_hz - self.truth_hz) <= FREQUENCY_TOLERANCE * self.truth_hz)
        )


def _uncoupled_rig(ratio: float | None) -> ModalRig:
    """The two-mode rig with its second mode off the joint and without the coupling."""
    model = dataclasses.replace(MODAL_RIG_PRESETS["two-mode"].model(ratio),
                                joint_shapes=((1.0, 0.0),), couplings=(),
                                name="two modes, uncoupled")  # fmt: skip
    return ModalRig.preset(
        "two-mode", levels=LEVELS, model=model, name="two-mode uncoupled",
        description="the two-mode rig, its second mode off the joint and uncoupled",
    )  # fmt: skip


def _two_mode_rig_campaign(
    ratio: float | None, seed: int, uncoupled: bool = False
) -> tuple[BackboneSet, float, Callable[[], ModeParticipation]]:
    """A PLL campaign of mode 1 on the two-mode rig (``uncoupled``: :func:`_uncoupled_rig`),
    the truth's second frequency and the second mode's participation read from the
    records' 15 points (their modes file's shapes; read only where the criticism asks)."""
    if uncoupled:
        rig = _uncoupled_rig(ratio)
    else:
        rig = ModalRig.preset("two-mode", levels=LEVELS, ratio=ratio)
    records = []
    for a in range(1, ASSEMBLIES + 1):
        drawn, gain = rig.draw(np.random.default_rng([seed, a]))
        name = f"Config{rig.config}_PRT_Assemb{a}"
        records.append(rig.simulate(drawn, gain, np.random.default_rng([seed, a, 1]), name)[0])
    truth = float(small_amplitude_frequencies_hz(rig.model)[1])

    def participation() -> ModeParticipation:
        table = extract_modal_backbones(records, 2).to_table()
        return ModeParticipation.from_table(table, "the records' modal filter")

    return extract_backbones(records), truth, participation


#: The independent simulator's two-mode system (:class:`independent.decays.ModalSystem`): its
#: own numbers, not the rig's — bending at 101 Hz (ζ 0.3 %), a memoryless joint (a cubic spring
#: that softens the backbone by about 1.5 % at 2 mm: the start model's physics) on which the
#: second mode has shape 0.3, and the 1:2 potential ``κ q₁² q₂``. Whatever else the
#: one-mode model misses is the second mode's.
_INDEPENDENT_F1_HZ, _INDEPENDENT_ZETA = 101.0, 0.003
_INDEPENDENT_CUBIC = -0.03 * (2 * np.pi * 101.0) ** 2 / (0.75 * 2e-3**2)
_INDEPENDENT_SHAPE, _INDEPENDENT_COUPLING = 0.3, 1.2e7
#: The start model of an independent campaign: the lab's cubic-hardening base (linear pair and
#: x³), fitted to the backbones as a user reading one mode would.
_INDEPENDENT_START = lab_hidden_scenario("microslip")


def _independent_system(ratio: float, rng: np.random.Generator) -> ModalSystem:
    """One assembly of the independent two-mode system at ``ratio`` (scatter of
    :class:`independent.campaigns.PopulationScatter`'s sizes on frequencies, damping and the
    joint's terms)."""
    scatter = PopulationScatter()
    stiffness, damping = (np.exp(s * rng.standard_normal(2)) for s in
                          (scatter.stiffness, scatter.damping))  # fmt: skip
    sizes = np.exp(scatter.sizes * rng.standard_normal(2))
    f1 = _INDEPENDENT_F1_HZ * np.sqrt(stiffness)
    return ModalSystem(
        (float(f1[0]), float(ratio * f1[1])),
        (float(_INDEPENDENT_ZETA * damping[0]), float(_INDEPENDENT_ZETA * damping[1])),
        joint_shape=(1.0, _INDEPENDENT_SHAPE),
        joint_terms=(CubicStiffness(_INDEPENDENT_CUBIC * sizes[0]),),
        couplings=(PotentialTerm(_INDEPENDENT_COUPLING * sizes[1], (2, 1)),),
    )  # fmt: skip


def independent_campaign(ratio: float, seed: int) -> tuple[BackboneSet, float, ModeParticipation]:
    """A PLL campaign of mode 1 of the independent two-mode system (its own harmonic
    balance, :func:`independent.modal_resonance.modal_phase_resonance`; hold-fit noise of
    :class:`independent.campaigns.HoldNoise`), the truth's second frequency at rest
    (the nominal system's mode 2: its linear part; the joint's terms are cubic) and mode 2's
    participation (its coordinate's harmonics 1–2, with the harmonics' noise in m: a modal
    filter's reading)."""
    noise, scatter = HoldNoise(), PopulationScatter()
    nominal = 1e-3 * np.geomspace(0.05, 2.0, LEVELS)
    curves, parts = [], []
    for a in range(1, ASSEMBLIES + 1):
        rng = np.random.default_rng([seed, a])
        system = _independent_system(ratio, rng)
        levels = np.sort(nominal * np.exp(scatter.amplitude_jitter * rng.standard_normal(LEVELS)))
        held = modal_phase_resonance(system, 1, levels, harmonics=4, samples=32, tol=1e-10)
        if not held.converged.all():
            raise RuntimeError(f"no phase-resonant state for assembly {a} at seed {seed}")
        small = nominal.min() / levels
        draw = rng.standard_normal((6, LEVELS))
        h_noise = noise.harmonic * (1 + small)
        harmonics = held.participation[:, 0, 1:3] / levels[:, None]
        curves.append(Backbone(
            levels,
            held.frequency_hz + noise.frequency_hz * (1 + np.sqrt(small)) * draw[0],
            held.damping_ratio * (1 + noise.damping * (1 + small) * draw[1]),
            label=f"assembly{a}", source="independent.modal_resonance",
            harmonics=harmonics + h_noise[:, None] * (draw[2:4] + 1j * draw[4:6]).T,
            harmonic_standard_error=np.repeat(h_noise[:, None], 2, axis=1),
            time_s=HOLD_S * (np.arange(LEVELS) + 0.5),
        ))  # fmt: skip
        extra = rng.standard_normal((4, LEVELS))
        second = (
            held.participation[:, 1, :2]
            + (h_noise * levels)[:, None] * (extra[:2] + 1j * extra[2:]).T
        )
        last = curves[-1]
        parts.append(ParticipationCurve(levels, last.frequency_hz, last.damping_ratio, second,
                                        last.label))  # fmt: skip
    participation = ModeParticipation(tuple(parts), 2, "independent.modal_resonance")
    return BackboneSet(curves), ratio * _INDEPENDENT_F1_HZ, participation


def campaign(case: str, seed: int) -> tuple[BackboneSet, JointModel, float, Participation]:
    """The campaign of ``case`` at ``seed``: backbones, the one-mode start model fitted to
    them, the truth's second-mode frequency (NaN for one-mode data; the uncoupled mode's
    where it has one) and the second mode's participation where the campaign has several
    response points (None: one)."""
    if case in TWO_MODE_CASES:
        rig, ratio = TWO_MODE_CASES[case]
        if rig == "two-mode":
            measured, truth, part = _two_mode_rig_campaign(ratio, seed)
            return measured, first_fit(RIG_PRESETS[_TWO_MODE_START].model, measured), truth, part
        if rig == INDEPENDENT:
            measured, truth, part = independent_campaign(ratio, seed)
            start = first_fit(RIG_PRESETS[_INDEPENDENT_START].base_model, measured)
            return measured, start, truth, part
        preset = RIG_PRESETS[rig]
        mode = preset.lab["second_mode"]
        truth = mode.frequency_ratio * preset.model.linear_frequency_hz
    elif case in UNCOUPLED_CASES:
        measured, truth, part = _two_mode_rig_campaign(UNCOUPLED_CASES[case], seed, uncoupled=True)
        return measured, first_fit(RIG_PRESETS[_TWO_MODE_START].model, measured), truth, part
    elif case in ONE_MODE_CASES:
        preset, truth = RIG_PRESETS[case], float("nan")
        rig = case
    else:
        raise ValueError(f"unknown case {case!r}; cases: {', '.join(CASES)}")
    _, measured = rig_campaign(rig, ASSEMBLIES, (seed,), levels=LEVELS)
    return measured, first_fit(preset.base_model, measured), float(truth), None


def second_mode_campaign(
    case: str, seed: int, *, multi_point: bool = True, **options
) -> SecondModeRow:
    """Criticise one campaign of ``case`` (``options`` to ``criticize``) and judge it;
    ``multi_point=False`` withholds the second mode's participation (one response point)."""
    began = time.perf_counter()
    measured, model, truth, participation = campaign(case, seed)
    participation = participation if multi_point else None
    crit = criticize(model, measured, participation=participation, **options)
    mode = crit.second_mode
    named = crit.verdict == Verdict.SECOND_MODE
    two = case in TWO_MODE_CASES
    passed = passes(case, named, mode.mechanism, mode.located, mode.frequency_hz, truth)
    return SecondModeRow(
        case=case, seed=seed, two_modes=two, truth_hz=truth, verdict=str(crit.verdict),
        p_value=float(crit.p_value), named_hz=mode.frequency_hz, ratio=mode.ratio,
        share=mode.share, mechanism=mode.mechanism, gain=mode.gain,
        catalogue_gain=mode.catalogue_gain, threshold=mode.threshold, why=mode.why,
        passed=passed,
        seconds=time.perf_counter() - began, located=mode.located, low_hz=mode.interval_hz[0],
        high_hz=mode.interval_hz[1], screen_hz=mode.screen_frequency_hz, location=mode.location,
        located_by=mode.located_by, multi_point=participation is not None,
        named_by=mode.named_by, exchange=mode.exchange,
    )  # fmt: skip


def passes(
    case: str, named: bool, mechanism: str, located: bool, frequency_hz: float, truth_hz: float
) -> bool:
    """The outcome rule (module notes) of one campaign of ``case``: whether the criticism
    ``named`` a second mode by ``mechanism``, ``located`` at ``frequency_hz``, passes
    against the truth's ``truth_hz`` (NaN on one-mode data)."""
    close = bool(abs(frequency_hz - truth_hz) <= FREQUENCY_TOLERANCE * truth_hz)
    if case in TWO_MODE_CASES:
        return named and located and close
    if case in UNCOUPLED_CASES:
        return not named or (mechanism == SENSOR and located and close)
    return not named


@dataclass(frozen=True)
class Count(Row):
    """Rows of one case counted: named (as the rule says), passed (two-mode data: named and
    located within the tolerance), the campaigns, the Clopper–Pearson interval of the rate,
    the seed kind, named with a located frequency, and named at a wrong frequency."""

    case: str
    two_modes: bool
    named: int
    passed: int
    n: int
    low: float
    high: float
    seeds: str
    located: int = 0
    wrong: int = 0


def count(rows: Sequence[SecondModeRow]) -> list[Count]:
    """Per case: named and passed counts with the 95 % interval of the rule's rate (the
    pass rate on two-mode data, the failure rate on the others: on one-mode data the
    naming rate)."""
    out = []
    for case in dict.fromkeys(r.case for r in rows):
        mine = [r for r in rows if r.case == case]
        two = mine[0].two_modes
        named = sum(r.named for r in mine)
        passed = sum(r.passed for r in mine)
        low, high = clopper_pearson(passed if two else len(mine) - passed, len(mine))
        kinds = {"held-out" if is_held_out(r.seed) else "tuning" for r in mine}
        seeds = f"{min(r.seed for r in mine)}–{max(r.seed for r in mine)} ({'/'.join(kinds)})"
        located = sum(r.named and r.located for r in mine)
        wrong = sum(r.wrong for r in mine)
        out.append(Count(case, two, named, passed, len(mine), low, high, seeds, located, wrong))
    return out
