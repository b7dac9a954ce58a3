"""Studies that run the library end to end (used by bench/, case_studies/ and slow tests;
nothing in the library imports this module).

* :func:`criticism_study` — a rig scenario (ideal or lab) through the criticism loop,
  from the start a user has: the bare linear model, a SINDy-identified one, or the
  preset's base model (the truth minus what is hidden).
* :func:`simulated_campaign` and :func:`null_study` — the false-discovery rate of the
  calibrated decision over many fast null campaigns: harmonic-balance backbones of
  assemblies drawn around a truth, with amplitude jitter and heteroscedastic noise,
  criticised with the truth's own structure (anything found is a false discovery).
* :func:`swap_study` — the swap step of the stepwise loop over the same fast campaigns:
  how often it undoes a right addition (truth = base + an effect with a near-collinear
  rival), how often it corrects a wrong one.
* :func:`term_group_study` — model-term groups over the same fast campaigns: how often a
  term of the truth's structure is grouped with a stand-in the data can tell it from.
* :func:`clopper_pearson` — the two-sided exact binomial interval of a rate.
* :func:`table5_study` — the paper's Table 5: surrogate accuracy against training size.
* :func:`synthetic_campaign` and :func:`population_coverage` — the calibration of the
  hierarchical model's intervals.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from identification.analytical.harmonic import backbone as harmonic_backbone
from identification.analytical.pll import pll_backbones
from identification.criticism.criticism import Criticism, SwapTrial, criticize, run_rounds
from identification.effects import CATALOGUE
from identification.fitting.data import FitData
from identification.fitting.fitter import Fitter
from identification.fitting.least_squares import FitResult
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Record
from identification.model import JointModel
from identification.rig import RIG_PRESETS, rig_for_preset
from identification.rig.presets import LAB_OUT_OF_CATALOGUE_SCENARIOS, lab_hidden_scenario
from pm_joint.analysis import convergence_verdict
from pm_joint.inference import HIERARCHICAL_TARGET_ACCEPT, hierarchical_model, sample
from surrogates.dataset import BackboneDataset
from surrogates.evaluate import PAPER_TABLE5
from surrogates.train import TrainingConfig, train_on_dataset

__all__ = [
    "KEY_CHANNEL",
    "NULL_CONDITIONS",
    "NULL_TRUTHS",
    "START_LIBRARY",
    "SWAP_TRUTHS",
    "TERM_TRUTHS",
    "Coverage",
    "StudyResult",
    "binomial_bounds",
    "clopper_pearson",
    "criticism_study",
    "null_study",
    "pll_campaign",
    "population_coverage",
    "rows_table",
    "scenario_kind",
    "simulated_campaign",
    "swap_study",
    "synthetic_campaign",
    "table5_study",
    "term_group_study",
]


# --------------------------------------------------------------------------
# Rig scenarios through the criticism loop


#: The channel whose error a hidden effect must take down (by ≥ 80 %) in the studies.
#: Damping effects leave the frequency at the noise level already; even effects (x², ẋ²,
#: x·ẋ) show in the second harmonic of the records, which the backbone alone misses.
KEY_CHANNEL = {
    "hidden-cubic": "frequency_hz",
    "hidden-microslip": "frequency_hz",
    "hidden-two": "frequency_hz",
    "hidden-quadratic": "harmonics",
    "hidden-quadratic-damping": "damping_ratio",
    "hidden-coulomb": "damping_ratio",
    # each catalogue effect's lab scenario: the key channel its module states
    **{
        lab_hidden_scenario(name): effect.hidden_scenario.key_channel
        for name, effect in CATALOGUE.items()
        if effect.hidden_scenario is not None
    },
}
_STEP_RMSE = {
    "frequency_hz": "frequency_rmse_hz",
    "damping_ratio": "damping_rmse",
    "harmonics": "harmonic_rmse",
}
#: The library of a SINDy start: every monomial up to cubic in (x, ẋ), what a pysindy
#: user starts from (:data:`identification.sindy.POLYNOMIAL_LIBRARY`).
START_LIBRARY = "polynomial"


def scenario_kind(scenario: str) -> str:
    """``"null"`` (nothing to find), ``"hidden"`` (a catalogue effect hidden) or
    ``"out of catalogue"``."""
    if scenario in LAB_OUT_OF_CATALOGUE_SCENARIOS:
        return "out of catalogue"
    return "hidden" if RIG_PRESETS[scenario].hidden_effects else "null"


def _bare_linear(model: JointModel) -> JointModel:
    return JointModel(
        {e: model.coefficient(e) for e in ("linear_stiffness", "viscous_damping")},
        name="linear",
    )


@dataclass
class StudyResult:
    """One rig scenario run through the criticism loop from one start.

    Keeps the measured backbones, the records and the start model, so the same
    data can be criticised again another way.
    """

    scenario: str
    seed: int
    start_kind: str
    truth: JointModel
    hidden: tuple[str, ...]
    measured: BackboneSet
    records: list[Record]
    start: JointModel
    criticisms: list[Criticism] = field(default_factory=list)
    seconds: float = float("nan")

    @property
    def kind(self) -> str:
        return scenario_kind(self.scenario)

    @property
    def history(self):
        return self.criticisms[-1].history

    @property
    def added(self) -> list[str]:
        """The effects the loop added, in order (a swap's replacement after its round's),
        as each step records them (:attr:`~identification.criticism.criticism.Step.added`)."""
        return [effect for step in self.history for effect in step.added]

    @property
    def kept(self) -> list[str]:
        """The effects the last model holds beyond the start (after every swap)."""
        return [e for e in self.criticisms[-1].base.model.effects if e not in self.start]

    @property
    def first(self) -> str | None:
        """The effect ranked first by the first criticism (None: nothing proposed)."""
        proposed = self.criticisms[0].missing()
        return proposed[0].effect if proposed else None

    @property
    def verdict(self) -> str:
        """The first criticism's verdict."""
        return self.criticisms[0].verdict

    def _round_of(self, effect: str) -> int | None:
        """The first round whose proposed effect or group holds ``effect``."""
        for k, crit in enumerate(self.criticisms):
            proposed = crit.missing()
            if not proposed:
                return None
            group = next((g.effects for g in crit.groups if proposed[0].effect in g.effects),
                         (proposed[0].effect,))  # fmt: skip
            if effect in group:
                return k
        return None

    @property
    def in_start(self) -> bool:
        """Whether the start model already holds every hidden effect (SINDy found them)."""
        return bool(self.hidden) and all(e in self.start for e in self.hidden)

    @property
    def hit(self) -> bool | None:
        """Hidden scenarios: every hidden effect the start lacks is ranked first or in the
        first group of a round, with only effects of the truth added before; or the last
        model (after the loop's swaps and trial additions) holds every one of them and no
        effect beyond the truth's (None for other kinds)."""
        if self.kind != "hidden":
            return None
        missing = [e for e in self.hidden if e not in self.start]
        # forward-backward: the last model holds them, and only effects of the truth
        kept = self.kept
        if missing and all(e in kept for e in missing) and all(e in self.truth for e in kept):
            return True
        rounds = [self._round_of(e) for e in missing]
        if any(r is None for r in rounds):
            return False
        wrong = [e for e in self.added[: max(rounds, default=0)] if e not in self.truth]
        return not wrong

    def reduction(self, channel: str) -> float | None:
        """Fractional RMSE reduction of a channel from the first criticism's refitted model
        to the last one's."""
        before = getattr(self.criticisms[0].base, _STEP_RMSE[channel])
        after = getattr(self.criticisms[-1].base, _STEP_RMSE[channel])
        return None if before is None or after is None else float(1 - after / before)

    @property
    def false_discovery(self) -> bool | None:
        """Null scenarios: the first criticism says something is missing (None otherwise)."""
        if self.kind != "null":
            return None
        return self.verdict not in ("nothing missing", "drift")

    @property
    def start_adequate(self) -> bool:
        """Hidden scenarios: the start lacks a hidden effect by name (not :attr:`in_start`),
        yet its first criticism is :attr:`~identification.criticism.criticism.Criticism.adequate`
        — nothing significant, and the refitted start's residual within the calibrated
        scatter in every channel group, the same test a proposed candidate must pass. The
        start's own terms reproduce the hidden effect on these data (e.g. SINDy's x², x³
        and ẋ² terms an exponential spring): it is not missing from this start, so the row
        is neither a hit nor a miss."""
        if self.kind != "hidden" or self.in_start:
            return False
        return self.criticisms[0].adequate

    @property
    def truth_gap(self) -> float | None:
        """Start-adequate rows: the largest gap between the rig's truth and the refitted
        start, in standard errors of the measured mean (None on other rows). Both are
        predicted at the levels by a multi-harmonic balance driven by the measured
        excitation; frequency and damping are taken less their gap at the lowest level
        (the drawn assemblies' offsets, not the hidden effect). The ground truth's view of
        what the start may still miss below the criticism's calibrated bounds: beyond the
        where-bound (about 3.7) it would be a missed effect, not an adequate start."""
        if not self.start_adequate:
            return None
        crit = self.criticisms[0]
        data = crit.data
        truth = crit.predict_at(self.truth, data.levels_m, method="multi")
        start = crit.predict_at(crit.base.model, data.levels_m, method="multi")
        gap = truth - start
        for channel in ("frequency_hz", "damping_ratio"):
            j = data.column(channel)
            gap[:, j] -= gap[0, j]
        se = np.column_stack([crit.residual(c)[1] for c in data.channels])
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.abs(gap) / se
        return float(np.nanmax(z[:, data.used]))

    @property
    def term_group(self) -> dict[str, str] | None:
        """Start-adequate rows: per hidden effect the start lacks, the start's term that the
        first criticism's model-term groups
        (:attr:`~identification.criticism.criticism.Criticism.term_groups`) say it is
        consistent with; None unless every one of them is in such a group."""
        if not self.start_adequate:
            return None
        groups = self.criticisms[0].term_groups
        found = {}
        for effect in (e for e in self.hidden if e not in self.start):
            group = next((g for g in groups if effect in g.alternatives), None)
            if group is None:
                return None
            found[effect] = group.term
        return found

    @cached_property
    def _linear_fit(self) -> FitResult:
        """The bare linear model refitted to the first criticism's data."""
        crit = self.criticisms[0]
        return crit.refits.structure(_bare_linear(crit.base.model))

    def _linear_rmse(self, channel: str) -> float | None:
        return getattr(self._linear_fit, _STEP_RMSE[channel])

    def term_reduction(self, channel: str) -> float | None:
        """Rows with a :attr:`term_group` of one hidden effect: fractional RMSE reduction of
        a channel from the bare linear model (refitted to these data) to the start with the
        hidden effect in place of the term it is grouped with (as the group refitted it).
        Nothing is added on such a row (the start holds a stand-in already), so the effect's
        worth is measured against the model without any nonlinearity (None otherwise)."""
        found = self.term_group
        if found is None or len(found) != 1:
            return None
        ((effect, term),) = found.items()
        groups = self.criticisms[0].term_groups
        after = getattr(next(g for g in groups if g.term == term).fits[effect], _STEP_RMSE[channel])
        before = self._linear_rmse(channel)
        return None if before is None or after is None else float(1 - after / before)

    def start_reduction(self, channel: str) -> float | None:
        """Start-adequate rows: fractional RMSE reduction of a channel from the bare linear
        model (refitted to these data) to the refitted start (None on other rows)."""
        if not self.start_adequate:
            return None
        after = getattr(self.criticisms[0].base, _STEP_RMSE[channel])
        before = self._linear_rmse(channel)
        return None if before is None or after is None else float(1 - after / before)

    @property
    def outcome(self) -> str | None:
        """Hidden scenarios: ``"hit"`` (:attr:`passed`, the start lacking the effect),
        ``"hit (start term swapped)"`` (a start-adequate row whose start term is grouped with
        the hidden effect, :attr:`term_group`, :attr:`passed`, and the loop's swap step put
        the effect in its place: :attr:`hit`), ``"hit (start term group)"`` (the same, the
        data not preferring the effect to the term), ``"start adequate"``
        (:attr:`start_adequate`, otherwise) or ``"miss"``; None for other kinds."""
        if self.kind != "hidden":
            return None
        if self.start_adequate:
            if not self.passed:
                return "start adequate"
            return "hit (start term swapped)" if self.hit else "hit (start term group)"
        return "hit" if self.passed else "miss"

    @property
    def passed(self) -> bool | None:
        """Null: nothing found. Hidden: :attr:`hit` (or already in the start) and the key
        channel's error down ≥ 80 %; when the start holds every hidden effect already, the
        loop adds only effects of the truth (SINDy may miss another one, e.g. the viscous
        term beside ẋ³) and ends with nothing significant. When the start is adequate
        without it (:attr:`start_adequate`): the first criticism's model-term groups hold it
        (:attr:`term_group`) and the key channel's error with it in place of the start's
        term is down ≥ 80 % from the bare linear model's (:meth:`term_reduction`); None
        (not judged) when no group holds it. Out of catalogue: "not explained by the
        catalogue" or "partly explained" (proposals are admissible by construction)."""
        if self.kind == "null":
            return not self.false_discovery
        if self.kind == "out of catalogue":
            return self.verdict in ("not explained by the catalogue", "partly explained")
        if self.start_adequate:
            if self.term_group is None:
                return None
            key = self.term_reduction(KEY_CHANNEL[self.scenario])
            return key is not None and key >= 0.8
        if self.in_start:
            return all(e in self.truth for e in self.added) and not (
                self.criticisms[-1].significant
            )
        key = self.reduction(KEY_CHANNEL[self.scenario])
        return bool(self.hit) and key is not None and key >= 0.8

    def row(self) -> dict[str, Any]:
        """Table row of the study."""
        first = self.criticisms[0]
        groups = [list(g.effects) for g in first.groups]
        return {
            "scenario": self.scenario,
            "kind": self.kind,
            "seed": self.seed,
            "start": self.start_kind,
            "start_model": self.start.equation(),
            "hidden": list(self.hidden),
            "verdict": self.verdict,
            "explained_share": first.explained_share,
            "p_value": first.p_value,
            "threshold": first.threshold,
            "ranked_first": self.first,
            "groups": groups,
            "added": self.added,
            "kept": self.kept,
            "swaps": [s.to_dict() for c in self.criticisms for s in c.swaps if s.kept],
            "in_start": self.in_start,
            "start_adequate": self.start_adequate,
            "truth_gap_se": self.truth_gap,
            "term_groups": [
                {"term": g.term, "effects": list(g.alternatives), "separation": g.separation}
                for g in first.term_groups
            ],
            "term_group": self.term_group,
            "term_reduction": {c: self.term_reduction(c) for c in _STEP_RMSE}
            if self.term_group
            else None,
            "start_reduction": {c: self.start_reduction(c) for c in _STEP_RMSE}
            if self.start_adequate
            else None,
            "beyond_scatter": list(first.beyond_scatter),
            "hit": self.hit,
            "frequency_rmse_hz": [c.base.frequency_rmse_hz for c in self.criticisms],
            "damping_rmse": [c.base.damping_rmse for c in self.criticisms],
            "harmonic_rmse": [c.base.harmonic_rmse for c in self.criticisms],
            "reduction": {c: self.reduction(c) for c in _STEP_RMSE},
            "key_channel": KEY_CHANNEL.get(self.scenario),
            "drift": [d.channel for d in first.drift if d.significant],
            "passed": self.passed,
            "outcome": self.outcome,
            "seconds": self.seconds,
        }


def _start_model(
    start: str, scenario: str, records: Sequence[Record], measured: BackboneSet
) -> JointModel:
    preset = RIG_PRESETS[scenario]
    if start == "base":
        model = preset.base_model
    elif start == "linear":
        model = _bare_linear(preset.base_model)
    elif start == "sindy":
        from identification.sindy import POLYNOMIAL_LIBRARY, identify

        return identify(list(records)[:3], POLYNOMIAL_LIBRARY).model
    else:
        raise ValueError(f"start must be 'base', 'linear' or 'sindy', got {start!r}")
    # the user's first fit: frequency and damping of the backbones alone
    return Fitter.from_backbones(measured.without_harmonics()).fit(model).model


def criticism_study(
    scenario: str,
    seed: int = 0,
    *,
    start: str = "base",
    assemblies: int = 3,
    levels: int = 8,
    hold_s: float = 2.5,
    rounds: int = 3,
    **options: Any,
) -> StudyResult:
    """Run a rig scenario through the loop: criticise the start model, add, repeat.

    The rig (:func:`identification.rig.rig_for_preset`, ideal or lab) draws
    ``assemblies`` assemblies and their noise as :meth:`~identification.rig.Rig.write_campaign`
    does (seeds ``[seed, a]`` and ``[seed, a, 1]``) but keeps the records in memory. The
    start (``"base"``: the preset's base model, the truth minus what is hidden;
    ``"linear"``: the bare linear-viscous model; ``"sindy"``: SINDy on the first three
    records with the polynomial library) is fitted to the backbones alone (frequency
    and damping, as a user's first fit is; SINDy's own coefficients for ``"sindy"``);
    the criticism uses the harmonics the backbones carry too. The loop is forward-backward
    stepwise (:func:`~identification.criticism.criticism.run_rounds`): each round adds the
    effect proposed first and may swap out an effect an earlier round added, until nothing
    is proposed or ``rounds`` effects were added.
    ``options`` go to :func:`identification.criticism.criticism.criticize`.
    """
    began = time.perf_counter()
    rig = rig_for_preset(scenario, levels=levels, hold_s=hold_s)
    records = []
    for a in range(1, assemblies + 1):
        drawn, gain = rig.draw(np.random.default_rng([seed, a]))
        name = f"Config{rig.config}_PRT_Assemb{a}"
        records.append(rig.simulate(drawn, gain, np.random.default_rng([seed, a, 1]), name))
    measured = extract_backbones(records)
    preset = RIG_PRESETS[scenario]
    model = _start_model(start, scenario, records, measured)
    result = StudyResult(
        scenario, seed, start, preset.model, preset.hidden_effects, measured, records, model
    )
    result.criticisms = run_rounds(criticize(model, measured, **options), rounds)
    result.seconds = time.perf_counter() - began
    return result


# --------------------------------------------------------------------------
# Null campaigns: the false-discovery rate


#: Truths of the null campaigns (the criticised model has each truth's structure).
NULL_TRUTHS: dict[str, str] = {
    "linear": "lab-pure",
    "hardening": "lab-all-hardening",
    "friction": "lab-hidden-coulomb-friction",
    "arch": "lab-hidden-quadratic-stiffness",
    "joint": "trc-like",
}

#: Lab conditions of the null campaigns (options of :func:`simulated_campaign`): levels
#: stepped up and down, a distorting shaker (4 % 2nd, 3 % 3rd harmonic at most), the
#: controller ripple's leak into the hold fits' harmonics (up to 4e-5 of the fundamental:
#: twice the largest 3rd harmonic the hold fit left on ``lab-ripple``).
NULL_CONDITIONS: dict[str, dict[str, Any]] = {
    "up-down": {"up_down": True},
    "distorted": {"shaker_distortion": (0.04, 0.03)},
    "ripple": {"ripple_leak": 2e-5},
}


def simulated_campaign(
    model: JointModel,
    n_curves: int,
    seed: int,
    *,
    levels: int = 10,
    amplitude_range_mm: tuple[float, float] = (0.05, 2.0),
    stiffness_spread: float = 0.005,
    damping_spread: float = 0.05,
    nonlinear_spread: float = 0.03,
    amplitude_jitter: float = 0.05,
    frequency_noise_hz: float = 0.003,
    damping_noise: float = 0.005,
    harmonic_noise: float = 3e-4,
    up_down: bool = False,
    shaker_distortion: tuple[float, float] = (0.0, 0.0),
    ripple_leak: float = 0.0,
) -> BackboneSet:
    """A campaign of ``n_curves`` assemblies, fast: multi-harmonic-balance backbones.

    Each assembly draws its coefficients around ``model`` (lognormal: the linear
    stiffness by ``stiffness_spread``, the viscous damping by ``damping_spread``, every
    other coefficient by ``nonlinear_spread``); its points sit at geometric levels over
    ``amplitude_range_mm`` jittered by ``amplitude_jitter`` (the same voltage holds a
    different amplitude on each assembly). Measurement noise grows at small amplitude
    like a sensor noise floor does: frequency ``frequency_noise_hz·(1 + √(a_lo/a))``,
    damping ratio relative ``damping_noise·(1 + a_lo/a)``, harmonics ``harmonic_noise·(1 +
    a_lo/a)`` of the fundamental (its standard error is carried).

    Lab conditions (all off by default):

    * ``up_down``: the levels are stepped up, then down again (a second branch with its
      own amplitude jitter and noise; points carry their hold times).
    * ``shaker_distortion``: the largest 2nd and 3rd harmonic of the base acceleration
      (fractions of its fundamental). Each assembly's shaker draws its own, between
      half and all of it, with random phases, growing with the drive level from half
      to full; the response is driven by it (the harmonic balance's forcing) and each
      point carries the excitation harmonics it measured (with the harmonics' noise).
    * ``ripple_leak``: what the controller's frequency ripple leaves in the measured
      harmonics after the hold fit removed it (fraction of the fundamental): a bias
      locked to the response, of random size (up to twice this) and phase per assembly
      and order, the same at every level of that record.
    """
    rng = np.random.default_rng(seed)
    low, high = 1e-3 * np.asarray(amplitude_range_mm)
    nominal = np.geomspace(low, high, levels)
    branches = 2 if up_down else 1
    hold_s = 2.5
    curves = []
    for i in range(n_curves):
        spread = {
            name: {"linear_stiffness": stiffness_spread, "viscous_damping": damping_spread}.get(
                name, nonlinear_spread
            )
            for name in model.parameter_names
            if "." not in name or name == "microslip.F_s"
        }
        drawn = model.with_parameters(
            {n: model.parameters[n] * np.exp(s * rng.standard_normal()) for n, s in spread.items()}
        )
        jittered = [
            np.sort(nominal * np.exp(amplitude_jitter * rng.standard_normal(levels)))
            for _ in range(branches)
        ]
        a = np.concatenate([jittered[0], *[b[::-1] for b in jittered[1:]]])
        drive = np.concatenate([nominal, nominal[::-1]][:branches]) / high
        forcing = None  # the random streams of conditions left off are not drawn
        if np.any(shaker_distortion):
            shaker = np.asarray(shaker_distortion) * rng.uniform(0.5, 1.0, 2)
            phases = np.exp(2j * np.pi * rng.uniform(size=2))
            forcing = (0.5 + 0.5 * drive)[:, None] * (shaker * phases)[None, :]
        hb = harmonic_backbone(drawn, a, method="multi", harmonics=5, excitation_harmonics=forcing)
        if not hb.converged.all():
            raise RuntimeError(f"no periodic solution for assembly {i} of {model.equation()}")
        points = a.size
        ratio = low / a
        f_noise = frequency_noise_hz * (1 + np.sqrt(ratio))
        z_noise = damping_noise * (1 + ratio) * np.abs(hb.damping_ratio)
        h_noise = harmonic_noise * (1 + ratio)
        relative = (hb.harmonics_cos_m[:, 2:4] - 1j * hb.harmonics_sin_m[:, 2:4]) / a[:, None]
        leak = 0.0
        if ripple_leak:
            leak = ripple_leak * rng.uniform(0, 2, 2) * np.exp(2j * np.pi * rng.uniform(size=2))
        relative = (
            relative
            + leak
            + h_noise[:, None]
            * (rng.standard_normal((points, 2)) + 1j * rng.standard_normal((points, 2)))
        )
        measured_excitation = None
        if forcing is not None:
            measured_excitation = forcing + h_noise[:, None] * (
                rng.standard_normal((points, 2)) + 1j * rng.standard_normal((points, 2))
            )
        curves.append(
            Backbone(
                a,
                hb.frequency_hz + f_noise * rng.standard_normal(points),
                hb.damping_ratio + z_noise * rng.standard_normal(points),
                label=f"assembly{i + 1}",
                harmonics=relative,
                harmonic_standard_error=np.repeat(h_noise[:, None], 2, axis=1),
                excitation_harmonics=measured_excitation,
                time_s=hold_s * (np.arange(points) + 0.5),
            )
        )
    return BackboneSet(curves)


def _lab_campaign(
    truth: JointModel, n_curves: int, seed: int, k: int
) -> tuple[list[str], int, BackboneSet]:
    """Campaign ``k`` of a study seeded ``seed``: its lab conditions (each of
    :data:`NULL_CONDITIONS` present with probability ½), its levels per branch (5, 6 or 8),
    drawn from its own seed, and the simulated campaign."""
    draw = np.random.default_rng([seed, k, 7])
    present = [name for name in NULL_CONDITIONS if draw.uniform() < 0.5]
    levels = int(draw.choice([5, 6, 8]))
    conditions = {o: v for name in present for o, v in NULL_CONDITIONS[name].items()}
    measured = simulated_campaign(
        truth, n_curves, seed=seed * 100_003 + k, levels=levels, **conditions
    )
    return present, levels, measured


def _campaigns(
    campaigns: int,
    truths: Sequence[str],
    curve_counts: Sequence[int],
    seed: int,
    preset: Callable[[str], str],
):
    """The campaigns of a study, truths in turn and curve counts in turn per round of
    truths: ``(k, truth's name, curve count, truth, when its simulation began, its lab
    campaign)`` (:func:`_lab_campaign`; ``preset`` names the rig preset of a truth)."""
    for k in range(campaigns):
        name = truths[k % len(truths)]
        n_curves = curve_counts[(k // len(truths)) % len(curve_counts)]
        truth = RIG_PRESETS[preset(name)].model
        began = time.perf_counter()
        yield k, name, n_curves, truth, began, _lab_campaign(truth, n_curves, seed, k)


def null_study(
    campaigns: int,
    *,
    truths: Sequence[str] = tuple(NULL_TRUTHS),
    curve_counts: Sequence[int] = (1, 3, 5, 10),
    seed: int = 0,
    progress: Callable[[dict], None] | None = None,
    **options: Any,
) -> list[dict[str, Any]]:
    """``campaigns`` null campaigns (truths and curve counts in turn), each criticised with
    its truth's structure; a row per campaign with the verdict and whether it is a false
    discovery (anything but "nothing missing" or "drift"). ``options`` go to
    :func:`identification.criticism.criticism.criticize`.

    Each campaign draws its lab conditions (:data:`NULL_CONDITIONS`, each present with
    probability ½, and 5, 6 or 8 levels per branch) from its own seed, so a run of any
    length mixes clean and artefact-laden campaigns over every truth and curve count.
    """
    rows = []
    for k, truth_name, n_curves, truth, began, campaign in _campaigns(
        campaigns, truths, curve_counts, seed, NULL_TRUTHS.__getitem__
    ):
        present, levels, measured = campaign
        crit = criticize(truth, measured, **options)
        row = {
            "campaign": k,
            "truth": truth_name,
            "n_curves": n_curves,
            "levels": levels,
            "conditions": present,
            "verdict": crit.verdict,
            "p_value": crit.p_value,
            "catalogue_gain": float(crit.observed.catalogue[0]),
            "catalogue_threshold": crit.calibration.catalogue_threshold,
            "reference_gain": float(crit.observed.reference[0]),
            "reference_threshold": crit.calibration.reference_threshold,
            "reference_dof": crit.observed.reference_rank,
            "false_discovery": crit.verdict not in ("nothing missing", "drift"),
            "proposed": [c.effect for c in crit.missing()],
            "seconds": time.perf_counter() - began,
        }
        rows.append(row)
        if progress is not None:
            progress(row)
    return rows


#: Truths of the swap study: each catalogue effect of the lab scenarios that has a rival
#: the data may hardly tell from it (cubic hardening: tanh/exponential/microslip; the
#: damping laws among themselves; Coulomb and Stribeck friction), on the lab base model.
SWAP_TRUTHS: tuple[str, ...] = (
    "cubic_stiffness",
    "tanh_saturation",
    "exponential",
    "microslip",
    "quadratic_damping",
    "cubic_damping",
    "van_der_pol",
    "coulomb_friction",
    "stribeck_friction",
)


def swap_study(
    campaigns: int,
    *,
    wrong_first: bool = False,
    truths: Sequence[str] = SWAP_TRUTHS,
    curve_counts: Sequence[int] = (1, 3, 5, 10),
    seed: int = 0,
    progress: Callable[[dict], None] | None = None,
    **options: Any,
) -> list[dict[str, Any]]:
    """The swap step's decisions (:meth:`~identification.criticism.criticism.Criticism.swap`)
    over ``campaigns`` fast campaigns (truths and curve counts in turn, lab conditions as
    :func:`null_study` draws them). ``options`` go to
    :func:`identification.criticism.criticism.criticize`.

    Each campaign's truth is the lab base model plus one effect ``B`` (the preset
    ``lab-hidden-<B>``). Round 1 criticises the truth without ``B``; its significant
    refitted runners-up are the alternatives the swap may put in place of the effect
    added (:meth:`~identification.criticism.criticism.Criticism.alternatives`, as
    :func:`~identification.criticism.criticism.run_rounds` passes them).

    * ``wrong_first=False`` (the false-swap rate): ``B`` itself is added, so the model
      judged has the truth's structure; any change the swap keeps (a replacement or a
      removal of ``B``) is a false swap.
    * ``wrong_first=True`` (the power): round 1's best proposed candidate other than ``B``
      (what the loop could have added), else its best refitted significant one, is added
      instead; the swap corrects it when it puts ``B`` in its place.
      Campaigns where round 1 has no such candidate have no decision (``added`` None).

    The swap judges the effect added as it judges one an earlier round added (``last``
    names no effect here): the decision is the same, made one round earlier. Each row also
    says whether round 1 proposed ``B`` first, round 1's ambiguity groups, and the false
    vetoes of the truth: the channels :data:`~identification.criticism.criticism.WORSE`
    flags when ``B`` is refitted in round 1 (``add_worse``, None when ``B`` was not
    refitted), and, with ``wrong_first``, in the swap's trial of ``B`` (``swap_veto``).
    """
    rows = []
    for k, effect, n_curves, truth, began, campaign in _campaigns(
        campaigns, truths, curve_counts, seed, lab_hidden_scenario
    ):
        present, levels, measured = campaign
        first = criticize(truth.without(effect), measured, **options)
        proposed = first.missing()
        refitted = {c.effect: c for c in first.candidates if c.fit is not None}
        added = effect
        if wrong_first:
            # what the loop could have added (proposed), else any significant runner-up
            rivals = [c.effect for c in proposed if c.effect != effect]
            rivals = rivals or first.alternatives(effect)
            added = rivals[0] if rivals else None
        row: dict[str, Any] = {
            "campaign": k,
            "truth": effect,
            "n_curves": n_curves,
            "levels": levels,
            "conditions": present,
            "proposed_first": proposed[0].effect if proposed else None,
            "groups": [list(g.effects) for g in first.groups],
            "add_worse": list(refitted[effect].worse) if effect in refitted else None,
            "added": added,
            "added_was_proposed": added in [c.effect for c in proposed],
        }
        if added is not None:
            alternatives = first.alternatives(added)
            swapped = first.add(added).swap({added: alternatives}, last="")
            trials = [
                {key: getattr(t, key) for key in ("add", "delta_chi2", "kept", "why")}
                for t in swapped.swaps
            ]
            kept = [t for t in swapped.swaps if t.kept]
            change = kept[0] if kept else None
            truth_trial = [t for t in swapped.swaps if t.add == effect]
            row |= {
                "alternatives": alternatives,
                "trials": trials,
                "best_replacement_gain": max(
                    (t.delta_chi2 for t in swapped.swaps if t.add is not None),
                    default=None,
                ),
                "decision": _swap_decision(change),
                "false_swap": None if wrong_first else change is not None,
                "corrected": (change is not None and change.add == effect) if wrong_first else None,
                "swap_veto": ("worse" in truth_trial[0].why) if truth_trial else None,
            }
        row["seconds"] = time.perf_counter() - began
        rows.append(row)
        if progress is not None:
            progress(row)
    return rows


#: Truths of the model-term group study (:func:`term_group_study`): the swap study's (each
#: with near-collinear catalogue rivals) and the even pair SINDy confuses (x², ẋ²).
TERM_TRUTHS: tuple[str, ...] = (*SWAP_TRUTHS, "quadratic_stiffness", "velocity_squared")


def term_group_study(
    campaigns: int,
    *,
    truths: Sequence[str] = TERM_TRUTHS,
    curve_counts: Sequence[int] = (1, 3, 5, 10),
    seed: int = 0,
    progress: Callable[[dict], None] | None = None,
    **options: Any,
) -> list[dict[str, Any]]:
    """Model-term groups (:attr:`~identification.criticism.criticism.Criticism.term_groups`)
    over ``campaigns`` fast campaigns (truths and curve counts in turn, lab conditions as
    :func:`null_study` draws them), each criticised with its truth's own structure: the
    lab base model plus one effect ``T`` (the preset ``lab-hidden-<T>``). ``options`` go to
    :func:`identification.criticism.criticism.criticize`.

    Each trial of a stand-in ``C`` in place of a model term (``T`` or a term of the lab
    base) gets its separation at the design, ``lambda``: the stand-in's structure refitted
    to the noise-free truth — the population model's prediction at the campaign's points,
    driven by the excitation they measured — with the campaign's own covariance, its
    ``χ²`` in the campaign's metric. That is the noncentrality of the trial's ``Δχ²``
    (the truth's structure fits the noise-free prediction exactly: ``lambda_truth``, ≈ 0):
    where it is large the data can tell the term from ``C``, and a group holding ``C``
    is a false flag. Each row also carries the campaign's verdict (a null campaign for the
    truth's structure: groups do not alter it) and its groups.
    """
    rows = []
    for k, effect, n_curves, truth, began, campaign in _campaigns(
        campaigns, truths, curve_counts, seed, lab_hidden_scenario
    ):
        present, levels, measured = campaign
        crit = criticize(truth, measured, **options)
        twin = _noise_free_twin(crit, truth)
        trials = []
        for trial in crit.term_trials:
            keys = ("term", "effect", "needed", "delta_chi2", "why", "standing")
            entry = {key: getattr(trial, key) for key in keys}
            if trial.effect is not None:
                stand_in = crit.base.model.without(trial.term).with_effect(trial.effect, 0.0)
                entry["lambda"] = _twin_chi2(crit, twin, stand_in)
            trials.append(entry)
        row = {
            "campaign": k,
            "truth": effect,
            "n_curves": n_curves,
            "levels": levels,
            "conditions": present,
            "verdict": crit.verdict,
            "false_discovery": crit.verdict not in ("nothing missing", "drift"),
            "lambda_truth": _twin_chi2(crit, twin, crit.base.model),
            "trials": trials,
            "term_groups": [[*g.effects] for g in crit.term_groups],
            "seconds": time.perf_counter() - began,
        }
        rows.append(row)
        if progress is not None:
            progress(row)
    return rows


def _noise_free_twin(crit: Criticism, truth: JointModel) -> FitData:
    """The criticism's data with every measured value replaced by the truth's prediction at
    its point (driven by the point's measured excitation), keeping the campaign's metrics:
    the covariance of the noisy campaign, estimated from its scatter."""
    data = crit.data
    data.metric()
    data.metric(crit.base.weights)  # the metrics a refit asks for, estimated on the campaign
    predicted = crit.fitter.predict(truth)
    values = np.where(np.isfinite(data.values), predicted, np.nan)
    return dataclasses.replace(data, values=values, _metrics=dict(data._metrics))


def _twin_chi2(crit: Criticism, twin: FitData, model: JointModel) -> float:
    """``model``'s structure refitted to the noise-free twin, its ``χ²`` there in the
    campaign's metric."""
    keys = set(twin._metrics)
    fit = Fitter(twin, crit.method, crit.weights).fit(model, method=crit.fitter.method_for(model))
    if set(twin._metrics) != keys:
        raise RuntimeError("the refit asked for a metric the campaign's data did not estimate")
    z = crit.metric.whiten(twin.mean_residual(fit.predicted))
    return float(z @ z)


def _swap_decision(change: SwapTrial | None) -> str:
    """A swap step's outcome in words: "kept", "replaced by <effect>" or "removed"."""
    return "kept" if change is None else change.decision


def clopper_pearson(k: int, n: int, confidence: float = 0.95) -> tuple[float, float]:
    """Two-sided exact (Clopper–Pearson) interval of a binomial rate ``k / n``."""
    interval = stats.binomtest(k, n).proportion_ci(confidence_level=confidence, method="exact")
    return float(interval.low), float(interval.high)


def rows_table(rows: Sequence[dict[str, Any]], columns: Sequence[str]) -> str:
    """Rows as a fixed-width text table of the given columns."""

    def text(value: Any) -> str:
        if isinstance(value, float):
            return f"{value:.3g}"
        if isinstance(value, list | tuple):
            return ",".join(text(v) for v in value) or "—"
        return "—" if value is None else str(value)

    cells = [[text(r.get(c)) for c in columns] for r in rows]
    widths = [max([len(c)] + [len(row[i]) for row in cells]) for i, c in enumerate(columns)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(columns, widths, strict=True))]
    lines += ["  ".join(v.ljust(w) for v, w in zip(row, widths, strict=True)) for row in cells]
    return "\n".join(lines)


# ---------------------------------------------------------------------------
# Table-5 study


def table5_study(
    dataset: BackboneDataset,
    *,
    sizes: Sequence[int] = (200, 300, 400, 500),
    config: TrainingConfig | None = None,
    seed: int = 0,
    scatter: Mapping[str, ArrayLike] | None = None,
) -> list[dict[str, Any]]:
    """The paper's Table 5: accuracy against the number of training curves, on test figures.

    Each size trains a fresh surrogate on the first ``size`` curves of one seeded
    permutation of the dataset's train split (so the sets are nested), stops it
    early on the whole validation split and scores it on the test split, beside
    the linear, cubic and mean-curve baselines fitted on the same curves
    (:func:`~surrogates.evaluate.accuracy_report`).

    Returns
    -------
    list of dict
        One row per size: ``n_train``, ``n_validation``, ``n_test``; the
        frequency RMSE (Hz) of the surrogate and the baselines on the test
        split's analytical curves, with the ratios to the linear and cubic
        baselines and to the scatter; the paper's amplitude figures at excitation levels
        (:func:`~surrogates.evaluate.table5_figures`; ``table5_representation`` says how they were
        made); the training seconds; the paper's MSE / MAE / MAPE for that
        size (None where the paper has no row).
    """
    train = np.random.default_rng(seed).permutation(dataset.in_split("train"))
    others = np.concatenate([dataset.in_split("validation"), dataset.in_split("test")])
    if max(sizes) > train.size:
        raise ValueError(f"size {max(sizes)} asked for, only {train.size} training curves exist")
    rows = []
    for size in sizes:
        subset = dataset.subset(np.sort(np.concatenate([train[:size], others])))
        surrogate = train_on_dataset(subset, config, scatter=scatter)
        report = surrogate.test_report
        analytical = report["analytical"] or {}
        frequency = {
            name: figures.get("frequency_hz", {}).get("rmse")
            for name, figures in analytical.get("models", {}).items()
        }
        ratios = analytical.get("ratios", {}).get("frequency_hz", {})
        table5 = report["table5"] or {}
        paper = PAPER_TABLE5.get(size, (None, None, None))
        rows.append(
            {
                "n_train": size,
                "n_validation": surrogate.n_validation,
                "n_test": report["counts"]["all"]["test"],
                "rmse_frequency_hz": frequency.get("surrogate"),
                "rmse_frequency_hz_linear": frequency.get("linear"),
                "rmse_frequency_hz_cubic": frequency.get("cubic"),
                "rmse_frequency_hz_mean_curve": frequency.get("mean_curve"),
                "frequency_to_linear": ratios.get("to_linear"),
                "frequency_to_cubic": ratios.get("to_cubic"),
                "frequency_to_scatter_max": ratios.get("to_scatter_max"),
                "table5_representation": table5.get("representation"),
                "mse_amplitude_mm2": table5.get("surrogate", {}).get("mse_amplitude_mm2"),
                "mae_amplitude_mm": table5.get("surrogate", {}).get("mae_amplitude_mm"),
                "mape_amplitude_pct": table5.get("surrogate", {}).get("mape_amplitude_pct"),
                "train_s": surrogate.train_seconds,
                "paper_mse": paper[0],
                "paper_mae": paper[1],
                "paper_mape": paper[2],
            }
        )
    return rows


# ---------------------------------------------------------------------------
# Population-coverage study


def synthetic_campaign(
    model: JointModel,
    names: Sequence[str],
    log_mean: ArrayLike,
    log_spread: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    n_curves: int = 25,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    rng: np.random.Generator | int | None = None,
) -> tuple[BackboneSet, np.ndarray]:
    """Backbones of assemblies drawn from a known population, with measurement noise.

    Curve i has ``θ_i = θ0·exp(log_mean + log_spread·N(0, 1))`` (θ0 the template's
    values of ``names``, the hierarchical model's population), its
    single-harmonic backbone at ``amplitudes_m``, and independent Normal noise:
    ``frequency_noise_hz`` on each frequency, ``damping_noise`` relative on each
    damping ratio. Returns the curves and the θ_i ``(n_curves, len(names))``.
    """
    rng = np.random.default_rng(rng)
    theta0 = np.array([model.parameters[n] for n in names])
    eta = np.asarray(log_mean, float) + np.asarray(log_spread, float) * rng.standard_normal(
        (n_curves, theta0.size)
    )
    theta = theta0 * np.exp(eta)
    hb = harmonic_backbone(model, amplitudes_m, parameters=theta, names=names)
    if not hb.converged.all():
        raise ValueError(
            f"some draws of the population of {list(names)} have no backbone at every amplitude "
            "(no positive stiffness?): narrow log_spread or move log_mean"
        )
    frequency = hb.frequency_hz + frequency_noise_hz * rng.standard_normal(hb.frequency_hz.shape)
    damping = hb.damping_ratio * (1 + damping_noise * rng.standard_normal(hb.damping_ratio.shape))
    curves = [
        Backbone(hb.amplitude_m, f, d, label=f"assembly{i + 1}", source="synthetic_campaign")
        for i, (f, d) in enumerate(zip(frequency, damping, strict=True))
    ]
    return BackboneSet(curves), theta


def pll_campaign(
    model: JointModel,
    names: Sequence[str],
    theta: np.ndarray,
    excitation_levels: ArrayLike,
    *,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    noise_slope: float = -0.3,
    rng: np.random.Generator | int | None = None,
) -> BackboneSet:
    """Backbones of assemblies ``theta`` as the PLL simulator measures them, with noise.

    Each assembly is held at every base-acceleration level of
    ``excitation_levels`` (m/s²) under phase-locked-loop control
    (:func:`~identification.analytical.pll.pll_backbones`: time integration,
    every harmonic, not the single-harmonic balance the hierarchical model
    infers with). Noise grows towards small responses, as extraction noise
    does: ``frequency_noise_hz·(a/a_ref)^noise_slope`` on each frequency and
    the relative ``damping_noise`` times the same factor on each damping ratio
    (``a_ref`` the geometric mean of the campaign's amplitudes). Holds the
    loop did not lock are left out of their curve.
    """
    rng = np.random.default_rng(rng)
    result = pll_backbones(model, excitation_levels, theta, list(names), progress=False)
    locked = result.locked & np.isfinite(result.frequency_hz)
    amplitude = result.amplitude_m
    factor = (amplitude / np.exp(np.mean(np.log(amplitude[locked])))) ** noise_slope
    frequency = result.frequency_hz + frequency_noise_hz * factor * rng.standard_normal(
        amplitude.shape
    )
    damping = result.damping_ratio * (
        1 + damping_noise * factor * rng.standard_normal(amplitude.shape)
    )
    return BackboneSet(
        Backbone(
            amplitude[i, ok],
            frequency[i, ok],
            damping[i, ok],
            label=f"assembly{i + 1}",
            source="pll_campaign",
        )
        for i, ok in enumerate(locked)
    )


def binomial_bounds(n: int, prob: float, level: float = 0.95) -> tuple[int, int]:
    """Two-sided ``level`` acceptance region of a Binomial(n, prob) count (equal tails)."""
    tail = 0.5 * (1 - level)
    return int(stats.binom.ppf(tail, n, prob)), int(stats.binom.isf(tail, n, prob))


@dataclass(frozen=True)
class Coverage:
    """Central intervals of the population parameters over simulated campaigns.

    ``truth_mean``/``truth_spread`` are the ``(n_campaigns, n_params)`` log-locations
    ``μ`` and log-spreads ``σ`` each campaign was drawn with (from the prior);
    ``mean_interval``/``spread_interval`` the ``(n_campaigns, n_params, 2)``
    central ``prob`` intervals; ``divergences`` and ``max_rhat`` per campaign.
    """

    names: tuple[str, ...]
    truth_mean: np.ndarray
    truth_spread: np.ndarray
    mean_interval: np.ndarray
    spread_interval: np.ndarray
    divergences: np.ndarray
    max_rhat: np.ndarray
    prob: float

    @staticmethod
    def _inside(interval: np.ndarray, truth: np.ndarray) -> np.ndarray:
        return (interval[..., 0] <= truth) & (truth <= interval[..., 1])

    @property
    def mean_covered(self) -> np.ndarray:
        return self._inside(self.mean_interval, self.truth_mean)

    @property
    def spread_covered(self) -> np.ndarray:
        return self._inside(self.spread_interval, self.truth_spread)

    @property
    def n_campaigns(self) -> int:
        return int(self.truth_mean.shape[0])

    def bounds(self, level: float = 0.95) -> tuple[int, int]:
        """Counts per parameter a calibrated model gives with probability ``level``.

        Campaigns are independent, so each parameter's count is Binomial(n_campaigns,
        prob); the parameters of one campaign share its data, so counts pooled over
        parameters are not binomial and get no bounds here.
        """
        return binomial_bounds(self.n_campaigns, self.prob, level)

    def within_bounds(self, level: float = 0.95) -> bool:
        low, high = self.bounds(level)
        counts = np.concatenate([self.mean_covered.sum(0), self.spread_covered.sum(0)])
        return bool(np.all((counts >= low) & (counts <= high)))

    def to_dict(self, level: float = 0.95) -> dict[str, Any]:
        low, high = self.bounds(level)
        return {
            "parameters": list(self.names),
            "n_campaigns": self.n_campaigns,
            "prob": self.prob,
            "binomial_bounds": [low, high],
            "bounds_level": level,
            "mean_covered": dict(zip(self.names, self.mean_covered.sum(0).tolist(), strict=True)),
            "spread_covered": dict(
                zip(self.names, self.spread_covered.sum(0).tolist(), strict=True)
            ),
            "within_bounds": self.within_bounds(level),
            "divergences": self.divergences.tolist(),
            "max_rhat": self.max_rhat.tolist(),
        }

    def __str__(self) -> str:
        low, high = self.bounds()
        parts = []
        for label, covered in (("mean", self.mean_covered), ("spread", self.spread_covered)):
            counts = ", ".join(
                f"{n} {c}/{self.n_campaigns}"
                for n, c in zip(self.names, covered.sum(0), strict=True)
            )
            parts.append(f"log-{label}: {counts}")
        return (
            f"{100 * self.prob:g} % intervals holding the truth over {self.n_campaigns} "
            f"campaigns ({'; '.join(parts)}); calibrated: each count in [{low}, {high}] "
            f"(two-sided 95 % binomial); divergences per campaign {self.divergences.tolist()}, "
            f"max r̂ {float(self.max_rhat.max()):.3f}"
        )


def population_coverage(
    model: JointModel,
    names: Sequence[str],
    excitation_levels: ArrayLike,
    amplitudes_m: ArrayLike | None = None,
    *,
    n_campaigns: int = 20,
    n_curves: int = 25,
    location_scale: float = 0.05,
    population_scale: float = 0.1,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    prob: float = 0.9,
    sampler: str = "nuts",
    target_accept: float = HIERARCHICAL_TARGET_ACCEPT,
    draws: int = 500,
    tune: int = 500,
    chains: int = 2,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    seed: int = 0,
    centred: bool | str = "auto",
    truncation: int | None = 5,
    progress: bool = True,
) -> Coverage:
    """Simulation-based calibration of :func:`hierarchical_model` on PLL-simulated campaigns.

    Each of ``n_campaigns`` campaigns draws its truth from the model's own
    prior, ``μ ~ N(0, location_scale)`` and ``σ ~ HalfNormal(population_scale)``
    per parameter, then ``n_curves`` assemblies ``θ_i = θ0·exp(μ + σ z_i)``,
    measured by the PLL simulator at ``excitation_levels`` with noise
    (:func:`pll_campaign`); the hierarchical model, with the same priors, is
    sampled on every measured point (``amplitudes_m`` None, as
    ``pm-joint update --population hierarchical`` runs it) or on each curve
    interpolated at those of ``amplitudes_m`` it reached. A calibrated model
    holds the truth in its central ``prob`` intervals of ``log_mean`` and
    ``log_spread`` in about ``prob`` of the campaigns (:meth:`Coverage.bounds`
    gives the two-sided binomial region). The data
    come from the time-domain PLL, the inference from single-harmonic
    balance: model error shows here as undercoverage (``truncation``, the
    hierarchical model's, subtracts the harmonic-balance gap). ``target_accept`` is
    closer to 1 than PyMC's 0.8: spreads drawn from the prior come near 0,
    where the posterior of the spread narrows and NUTS diverges at large steps.
    ``centred`` picks the hierarchical model's parametrisation (its ``centred``).
    """
    from tqdm.auto import tqdm

    names = tuple(names)
    theta0 = np.array([model.parameters[n] for n in names])
    truths_mean, truths_spread, means, spreads, divergences, rhats = [], [], [], [], [], []
    tail = 0.5 * (1 - prob)
    for campaign in tqdm(range(n_campaigns), desc="campaigns", disable=not progress):
        rng = np.random.default_rng([seed, campaign])
        mu = location_scale * rng.standard_normal(theta0.size)
        sigma = np.abs(population_scale * rng.standard_normal(theta0.size))
        theta = theta0 * np.exp(mu + sigma * rng.standard_normal((n_curves, theta0.size)))
        measured = pll_campaign(
            model, names, theta, excitation_levels, frequency_noise_hz=frequency_noise_hz,
            damping_noise=damping_noise, rng=rng,
        )  # fmt: skip
        pm_model = hierarchical_model(
            model, measured, names, amplitudes_m=amplitudes_m, channels=channels,
            location_scale=location_scale, population_scale=population_scale, centred=centred,
            truncation=truncation,
        )  # fmt: skip
        idata = sample(
            pm_model, sampler=sampler, draws=draws, tune=tune, chains=chains,
            random_seed=seed + campaign, progressbar=False,
            step_options={"target_accept": target_accept},
        )  # fmt: skip
        intervals = []
        for variable in ("log_mean", "log_spread"):
            values = idata.posterior[variable].values.reshape(-1, len(names))
            intervals.append(np.quantile(values, [tail, 1 - tail], axis=0).T)
        truths_mean.append(mu)
        truths_spread.append(sigma)
        means.append(intervals[0])
        spreads.append(intervals[1])
        divergences.append(int(idata.sample_stats["diverging"].sum()))
        rhats.append(max(r["r_hat"] for r in convergence_verdict(idata).parameters))
    return Coverage(
        names, np.array(truths_mean), np.array(truths_spread), np.array(means),
        np.array(spreads), np.array(divergences), np.array(rhats), prob,
    )  # fmt: skip
