"""Model criticism: where a joint model fails, which physics it lacks, and when the
catalogue does not explain it.

The loop a user runs::

    crit = criticize(model, measured)   # compare, decide, locate, rank
    crit.verdict, crit.where()          # calibrated: nothing missing / explained / …
    crit.missing()                      # catalogue effects that explain it, best first
    crit2 = crit.add(effect)            # refit with it, look again
    plot_history(crit2.history, ax)     # the error falling
    chain = run_rounds(crit, 3)         # the same, forward-backward stepwise

**Stepwise.** :func:`run_rounds` adds the effect proposed first, then (swap step,
:class:`~.moves.Swap`) tries removing each effect an earlier round added, or replacing
it by one of that round's significant runners-up, and keeps a change the same ``χ²``
supports: a removal that costs less than the calibrated threshold, a replacement that
gains more than :data:`SEPARATION`. With two effects missing, a stand-in that mimics
both alone gives way to the true effect once the other is in. The loop stops when the
next candidate captures less than :data:`~.config.STOP_SHARE` of the free-form gain left, when
nothing is proposed, or when the next model would be inadmissible; its answer is the last
criticism's ``loop_end`` (:class:`~identification.criticism.ending.LoopEnd`).

**One statistic.** Everything is judged by one likelihood
(:mod:`identification.fitting.data`): the residual of the *mean* curve at common
amplitude levels with the covariance of that mean — the between-curve scatter over
the number of curves (points of a curve share its assembly's offsets), shrunk and
floored, plus stated systematic floors. The base model's structure is refitted in
it; every candidate is refitted in it; ``where()`` reads its standardised residual.

**One decision, calibrated.** Around the refitted base model
(:mod:`identification.criticism.calibration`), the gain in ``χ²`` of the best
catalogue column (every effect over its shape grid, linearised) and of a free-form
reference (smooth equivalent stiffness, damping and harmonics against amplitude)
are compared with their distribution under the refitted model itself: a parametric
bootstrap of whole campaigns, the covariance re-estimated on each. Something is
missing when either gain exceeds its threshold (the two calibrated jointly, so that a
null campaign fires either with probability ``alpha``): that alone decides
(:attr:`Criticism.significant`; a second mode's own calibrated test beside it).
``where()`` describes where, against its own calibrated bound; a finding no single level
shows is **small** (:attr:`Criticism.small`: seen in the trend over the levels, within
the scatter at each). Threshold, ``alpha`` and the bootstrap size come with the verdict.

**Explained, or not.** Significant candidates are refitted (nonlinear) and judged:
admissible as physics (non-negative damping over the tested range, friction
opposing motion, no cancelling terms: :mod:`identification.criticism.adequacy`),
no channel worse beyond its noise, residual within the calibrated scatter in every
channel, and the share of the reference's gain they capture
(:func:`identification.criticism.reference.explained_share`). The verdict
(:class:`~identification.criticism.config.Verdict`) is "explained" (adequate, share ≥
:data:`EXPLAINED`), "partly explained" (share ≥ :data:`PARTLY`), "not explained by the
catalogue", or, where the decision does not fire, "nothing missing" or "drift"; a candidate
that improves the fit without being admissible or adequate is listed as "improves
the fit but does not explain it" and never proposed. A slip element of which the test
holds only the onset (its damping peak, at twice the slip amplitude, above the top level)
is at most "partly explained" and grouped with a nearby mode outside the catalogue, which
one sensor cannot tell from it (:func:`~identification.criticism.adequacy.onset_only`).
Candidates whose signatures the data cannot separate form **groups** (a ranking inside
a group is not a finding), with what would separate them. The model's own terms get
**model-term groups** (:attr:`Criticism.term_groups`): a term the data need that a
catalogue effect the model lacks reproduces in its place ("the model's ẋ² is consistent
with quadratic stiffness x² on these data") — a statement of what the data cannot tell,
never a proposal. Up- and down-stepped branches
that differ by time, not amplitude, are reported as **drift**
(:mod:`identification.criticism.drift`).

Figures are drawn by :mod:`identification.criticism.plots`; posterior draws from
PyMC come in through ``pm_joint``'s adapter (this engine imports no PyMC).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.artifacts import atomic_write_text
from identification.criticism import report, words
from identification.criticism.candidates import Ranking
from identification.criticism.config import (
    ALPHA,
    EXPLAINED,
    LINEAR_PAIR,
    MAX_REFITS,
    MAX_TERM_REFITS,
    N_BOOTSTRAP,
    PARTLY,
    SEPARATION,
    TERM_OVERLAP,
    VERDICTS,
    WORSE,
    CriticismConfig,
    Verdict,
)
from identification.criticism.decision import Decision
from identification.criticism.ending import LoopEnd
from identification.criticism.groups import Groups
from identification.criticism.mode_refit import ModeAdded, add_mode
from identification.criticism.moves import Add, Swap, SwapTerm, run_rounds
from identification.criticism.plots import write_figures
from identification.criticism.records import (
    Candidate,
    FailureRange,
    Group,
    Step,
    SwapTrial,
    TermGroup,
    Trial,
)
from identification.criticism.refits import Refits
from identification.criticism.second_mode import Participation, SecondMode, second_mode
from identification.effects import CATALOGUE, get_effect
from identification.fitting.data import FitData, fit_data
from identification.fitting.fitter import Fitter
from identification.fitting.least_squares import FitResult
from identification.measurements.backbone import BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Record
from identification.model import JointModel

__all__ = [
    "ALPHA",
    "EXPLAINED",
    "LINEAR_PAIR",
    "MAX_REFITS",
    "MAX_TERM_REFITS",
    "N_BOOTSTRAP",
    "PARTLY",
    "SEPARATION",
    "TERM_OVERLAP",
    "VERDICTS",
    "WORSE",
    "Candidate",
    "Criticism",
    "CriticismConfig",
    "FailureRange",
    "Group",
    "Step",
    "SwapTrial",
    "TermGroup",
    "Trial",
    "Verdict",
    "criticize",
    "run_rounds",
]


class _Part:
    """An attribute of one of the criticism's parts, read through (the part computes and
    keeps it; the criticism only names it)."""

    def __init__(self, part: str) -> None:
        self.part = part

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, owner: type | None = None) -> Any:
        if obj is None:
            return self
        return getattr(getattr(obj, self.part), self.name)


class Criticism:
    """A model criticised against measured backbones (build it with :func:`criticize`).

    It holds the state of one criticism — the model, the data, the settings
    (:class:`~identification.criticism.config.CriticismConfig`), the loop's history,
    earlier rounds and swap trials — and its parts, each with one contract:
    :attr:`refits` (:class:`~identification.criticism.refits.Refits`), :attr:`decision`
    (:class:`~identification.criticism.decision.Decision`: the statistics and where the
    model fails), :attr:`ranking` (:class:`~identification.criticism.candidates.Ranking`:
    the candidates judged) and :attr:`grouping`
    (:class:`~identification.criticism.groups.Groups`). Their results are read through
    under the names below; words are :mod:`~identification.criticism.words`', JSON
    :mod:`~identification.criticism.report`'s, and the moves
    (:mod:`~identification.criticism.moves`) return the next criticism.

    Attributes
    ----------
    model
        The model criticised (the posterior median when a posterior was given).
    data
        The measured data (:class:`identification.fitting.data.FitData`).
    fit
        The model as given against the data (no refit).
    history
        Steps of the loop so far, this model last.
    previous_rounds
        The earlier rounds' reports (:meth:`round_report`), first first.
    executor
        Where the candidates' refits run (see :func:`criticize`); None: here.
    loop_end
        The loop's final answer (:class:`~identification.criticism.ending.LoopEnd`) on
        the last criticism :func:`run_rounds` keeps; None elsewhere.
    swaps
        The changes the swap step tried after this round's addition
        (:class:`~identification.criticism.records.SwapTrial`), each with whether it was
        kept.

    Settings are keywords as :func:`criticize` takes them, or ``config``; ``added``/
    ``removed`` (keywords) are what this model gained and lost against the previous
    step's (:class:`Step`).
    """

    def __init__(
        self,
        model: JointModel,
        data: FitData,
        *,
        config: CriticismConfig | None = None,
        method: str | None = None,
        weights: Mapping[str, float] | None = None,
        candidates: Sequence[str] | None = None,
        criterion: str | None = None,
        alpha: float | None = None,
        n_bootstrap: int | None = None,
        seed: int | None = None,
        posterior: tuple[list[str], np.ndarray] | None = None,
        posterior_kind: str | None = None,
        history: Sequence[Step] = (),
        rounds: Sequence[Mapping[str, Any]] = (),
        action: str | None = None,
        prefitted: Mapping[str, FitResult] | None = None,
        executor: Any = None,
        swaps: Sequence[SwapTrial | Mapping[str, Any]] = (),
        added: Sequence[str] = (),
        removed: Sequence[str] = (),
        participation: Participation = None,
    ) -> None:
        self.config = CriticismConfig.of(
            config, method=method, weights=weights, criterion=criterion, alpha=alpha,
            n_bootstrap=n_bootstrap, seed=seed, posterior_kind=posterior_kind,
        )  # fmt: skip
        self.model = model
        self.data = data
        self.posterior = posterior
        self.participation = participation
        self.candidate_effects = _candidate_list(model, candidates)
        self.previous_rounds = [dict(r) for r in rounds]
        self.swaps = [s if isinstance(s, SwapTrial) else SwapTrial.from_dict(s) for s in swaps]
        self.fitter = Fitter(data, self.config.method, self.config.weights)
        self.refits = Refits(
            self.fitter, model, posterior=posterior is not None, executor=executor,
            prefitted=prefitted,
        )  # fmt: skip
        self.fit = self.fitter.evaluate(model)
        criterion = self.config.criterion
        step = Step(
            action=action or ("start" if not history else "criticize"),
            equation=model.equation(),
            effects=tuple(model.effects),
            frequency_rmse_hz=self.fit.frequency_rmse_hz,
            damping_rmse=self.fit.damping_rmse,
            harmonic_rmse=self.fit.harmonic_rmse,
            information_criterion=float(self.fit.information_criterion(criterion)),
            criterion=criterion,
            added=tuple(added),
            removed=tuple(removed),
        )
        previous = list(history)
        if previous and previous[-1].equation == step.equation:
            previous.pop()  # the same model criticised again: one step
        self.history: list[Step] = [*previous, step]
        self.loop_end: LoopEnd | None = None  # set on the last criticism run_rounds keeps

    # ------------------------------------------------------------------ parts
    @cached_property
    def base(self) -> FitResult:
        """The refitted base model (the posterior median with a posterior): what the
        statistics, ``where()`` and the comparison judge."""
        return self.refits.base()

    @cached_property
    def decision(self) -> Decision:
        """The statistics: calibrated tests, the comparison, where the model fails."""
        return Decision(
            self.fitter, self.base, self.candidate_effects, self.config, self.posterior,
            self.model,
        )  # fmt: skip

    @cached_property
    def ranking(self) -> Ranking:
        """The catalogue's candidates refitted, judged and ranked."""
        return Ranking(self.decision, self.refits, self.candidate_effects, self.config)

    @cached_property
    def grouping(self) -> Groups:
        """The ambiguity groups and the model-term groups."""
        return Groups(self.decision, self.refits, self.ranking)

    # settings
    method = _Part("config")
    weights = _Part("config")
    criterion = _Part("config")
    alpha = _Part("config")
    n_bootstrap = _Part("config")
    seed = _Part("config")
    posterior_kind = _Part("config")
    executor = _Part("refits")
    # the decision
    metric = _Part("decision")
    problem = _Part("decision")
    observed = _Part("decision")
    calibration = _Part("decision")
    effect_gains = _Part("decision")
    threshold = _Part("decision")
    p_value = _Part("decision")
    comparison = _Part("decision")
    residual = _Part("decision")
    where = _Part("decision")
    fires = _Part("decision")
    small = _Part("decision")
    beyond_scatter = _Part("decision")
    reference = _Part("decision")
    drift = _Part("decision")
    # the candidates
    candidates = _Part("ranking")
    missing = _Part("ranking")
    best = _Part("ranking")
    explained_share = _Part("ranking")
    provisional = _Part("ranking")
    alternatives = _Part("ranking")
    # the groups
    groups = _Part("grouping")
    term_trials = _Part("grouping")
    term_groups = _Part("grouping")

    @property
    def significant(self) -> bool:
        """Something is missing: the calibrated decision fires, or a second mode is named —
        by its own calibrated test, or by its participation at the sensors
        (:mod:`~identification.criticism.second_mode`)."""
        return self.decision.significant or self.second_mode.named

    @cached_property
    def second_mode(self) -> SecondMode:
        """The second-mode finding (:mod:`~identification.criticism.second_mode`): whether
        a second mode exchanging energy with this one explains the data better than the
        catalogue, its frequency, share and where it shows."""
        refits = [
            c.delta_chi2 for c in self.candidates if c.delta_chi2 is not None and not c.problems
        ]
        return second_mode(self.decision, max(refits, default=-np.inf), self.participation)

    @property
    def verdict(self) -> Verdict:
        """The verdict (:class:`~identification.criticism.config.Verdict`): the ranking's,
        or "explained by a second mode" where :attr:`second_mode` is named."""
        verdict = self.ranking.verdict
        if self.significant and self.second_mode.named:
            return Verdict.SECOND_MODE
        return verdict

    @property
    def unexplained(self) -> bool:
        """Whether something is missing that the catalogue does not (fully) explain."""
        return self.verdict in (
            Verdict.PARTLY_EXPLAINED, Verdict.NOT_EXPLAINED, Verdict.SECOND_MODE
        )  # fmt: skip

    @property
    def adequate(self) -> bool:
        """Nothing is missing and the refitted model's residual is within the calibrated
        scatter in every channel group: whatever physics the truth holds, this model's
        terms already reproduce what the data show of it."""
        return not self.significant and not self.beyond_scatter

    @property
    def ambiguous(self) -> list[dict[str, Any]]:
        """The groups as ``{effects, text}`` (the earlier report's name for them)."""
        return [{"effects": list(g.effects), "text": g.text} for g in self.groups]

    def predict_at(
        self,
        model: JointModel,
        amplitude_m: ArrayLike,
        channels: Sequence[str] | None = None,
        *,
        method: str | None = None,
        parameters: ArrayLike | None = None,
        names: Sequence[str] | None = None,
    ) -> np.ndarray:
        """A model's prediction at amplitudes other than the points (the levels, a plotting
        grid), driven as the points are (:meth:`~identification.fitting.fitter.Fitter.predict`);
        ``method`` defaults to the refitted base model's."""
        return self.fitter.predict(
            model, amplitude_m, channels, method=method or self.base.method,
            parameters=parameters, names=names,
        )  # fmt: skip

    # ------------------------------------------------------------------ moves
    def add(self, effect: str, **shape: float) -> Criticism:
        """Criticism of the model with ``effect`` added and everything refitted
        (:class:`~identification.criticism.moves.Add`; ``shape``: start values of its
        fit). The returned criticism's :attr:`history` and rounds continue this one's."""
        return Add(effect, shape).apply(self)

    def add_mode(self) -> ModeAdded:
        """The model with the named second mode added (:func:`~.mode_refit.add_mode`): a
        two-mode :class:`~identification.multimode.ModalModel` and the χ² before and after.

        Raises
        ------
        ValueError
            No second mode is named at a located frequency (the finding's reason).
        """
        mode = self.second_mode
        if not (mode.named and mode.located):
            why = mode.why or mode.location or "its frequency is not located"
            raise ValueError(f"no second mode to add: {why}")
        return add_mode(self.decision, mode.frequency_hz)

    def swap(self, alternatives: Mapping[str, Sequence[str]], last: str) -> Criticism:
        """The backward/swap step (:class:`~identification.criticism.moves.Swap`)."""
        return Swap(alternatives, last).apply(self)

    def swap_term(self) -> Criticism | None:
        """The swap step for the model's own terms
        (:class:`~identification.criticism.moves.SwapTerm`); None when nothing changes."""
        return SwapTerm().apply(self)

    def successor(
        self,
        fit: FitResult,
        candidates: Sequence[str],
        rounds: Sequence[Mapping[str, Any]],
        action: str,
        swaps: Sequence[SwapTrial] = (),
        history: Sequence[Step] | None = None,
        added: Sequence[str] = (),
        removed: Sequence[str] = (),
    ) -> Criticism:
        """The criticism of ``fit``'s model on the same data and settings, continuing
        ``history`` (default: this one's); ``added``/``removed`` as :class:`Step`'s."""
        return Criticism(
            fit.model,
            self.data,
            config=self.config,
            candidates=candidates,
            history=self.history if history is None else history,
            rounds=rounds,
            action=action,
            prefitted={f"base:{fit.method}": fit},
            executor=self.executor,
            swaps=swaps,
            added=added,
            removed=removed,
            participation=self.participation,
        )

    # ------------------------------------------------------------ words, JSON
    @property
    def verdict_text(self) -> str:
        """The verdict in one sentence."""
        return words.verdict_text(self)

    @property
    def caveats(self) -> list[str]:
        """What the user must know to read the verdict."""
        return words.caveats(self)

    def summary(self) -> str:
        """A few lines in words: the decision, where the model fails, what it lacks."""
        return words.summary(self)

    def no_solution_texts(self) -> list[str]:
        """Where the refitted model has no periodic solution, in words."""
        return words.no_solution_texts(self)

    def round_report(self) -> dict[str, Any]:
        """This round: the model, the decision, the ranking and the groups."""
        return report.round_report(self)

    @property
    def rounds(self) -> list[dict[str, Any]]:
        """Every round's report so far, this one last."""
        return [*self.previous_rounds, self.round_report()]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready report (see :meth:`write`)."""
        return report.to_dict(self)

    def to_json(self) -> str:
        """:meth:`to_dict` as JSON text (NaN and inf written as null)."""
        return report.to_json(self)

    def write(self, folder: str | Path) -> dict[str, Path]:
        """Write ``criticism.json`` and the figures (PNG) into ``folder``.

        Figures (:func:`identification.criticism.plots.write_figures`):
        ``comparison.png`` (measured vs predicted with residual bands),
        ``signatures.png`` (residual with the top candidates' signatures),
        ``freeform.png`` (the free-form describing functions against the model's),
        ``history.png`` (the error along the loop).
        """
        paths = {"json": atomic_write_text(Path(folder) / "criticism.json", self.to_json())}
        return paths | write_figures(self, folder)

    def __repr__(self) -> str:
        """The model and, once decided, the verdict (a repr computes nothing)."""
        text = f"<Criticism of {self.model.equation()}"
        if "ranking" in self.__dict__ and "candidates" in self.ranking.__dict__:
            return f"{text}: {self.verdict_text}>"
        return f"{text}: not decided yet (crit.verdict decides)>"


def _candidate_list(model: JointModel, candidates: Sequence[str] | None) -> list[str]:
    if candidates is None:
        return [e for e in CATALOGUE if e not in model]
    out = []
    for effect in candidates:
        get_effect(effect)
        if effect in model:
            raise ValueError(f"candidate {effect!r} is already in the model")
        out.append(effect)
    return out


# --------------------------------------------------------------------------
# Entry point


def criticize(
    model: JointModel,
    measured: BackboneSet | None = None,
    *,
    records: Sequence[Record] | None = None,
    posterior: tuple[Sequence[str], ArrayLike] | None = None,
    posterior_kind: str = "population",
    candidates: Sequence[str] | None = None,
    history: Sequence[Step | Mapping[str, Any]] = (),
    criterion: str = "bic",
    alpha: float = ALPHA,
    n_bootstrap: int = N_BOOTSTRAP,
    seed: int = 0,
    method: str = "auto",
    weights: Mapping[str, float] | None = None,
    noise_floor: Mapping[str, float] | None = None,
    n_periods: int = 70,
    executor: Any = None,
    participation: Participation = None,
) -> Criticism:
    """Compare a model with measured backbones, decide whether something is missing, rank
    what the catalogue offers, and say when it does not explain the data.

    Parameters
    ----------
    model
        The model to criticise; its structure is refitted to the data.
    measured
        Measured backbones. The harmonics they carry (backbones extracted from test
        records keep their 2nd and 3rd harmonics) become a fitted channel (see the
        module notes); backbones without them are compared in frequency and damping.
    records
        Test records to extract the backbones from when ``measured`` is None
        (:func:`identification.measurements.extraction.extract_backbones`).
    posterior
        Posterior draws of the model's parameters, ``(names, (n_draws, n_names))``,
        names among the model's parameter names (``pm_joint``'s ``criticize`` takes a
        DataTree from ``pm.sample``): the model is judged at their medians (not
        refitted), with the predictive band and its coverage, and the covariance is
        widened by the uncertainty of the population-mean curve the posterior implies.
    posterior_kind
        ``"population"`` (default: the draws spread like the population, as the paper's
        population matching gives; the mean curve's uncertainty is their spread over the
        number of curves) or ``"mean"`` (the draws are of the population mean, as a
        hierarchical model's mean parameters are; their spread is that uncertainty).
    candidates
        Effects to try; default every catalogue effect the model lacks.
    history
        Steps of an earlier criticism (``crit.history``) to continue.
    criterion
        ``"bic"`` or ``"aic"``: the information criterion *reported* per candidate
        (decisions are the calibrated tests').
    alpha
        Probability that a campaign the model explains gets a finding (default 0.01).
    n_bootstrap, seed
        Bootstrap campaigns of the calibration (≥ 10/alpha) and their seed.
    method
        Harmonic balance: ``"auto"``, ``"single"`` or ``"multi"``.
    weights, noise_floor
        See :func:`identification.fitting.least_squares.fit_backbones`.
    n_periods
        Periods per hold used for the backbone points of ``records``.
    executor
        Where the candidates' nonlinear refits run, each a task: anything with
        ``submit(fn, *args, **kwargs)`` (a dask ``Client``, a ``concurrent.futures``
        executor); None: here, one after the other. The result does not depend on it.

    Raises
    ------
    ValueError
        Bad input (both or neither of ``measured`` and ``records``); data too sparse
        (fewer than 3 points per curve in the shared range).
    """
    if not isinstance(model, JointModel):
        raise ValueError(
            f"model must be a JointModel, got {type(model).__name__} (a posterior from "
            "pm.sample is criticised through pm_joint's criticize)"
        )
    draws = None
    if posterior is not None:
        draws = _checked_draws(model, posterior)
        model = model.with_parameters(dict(zip(draws[0], np.median(draws[1], axis=0), strict=True)))
    if measured is None:
        if not records:
            raise ValueError("give the measured backbones or the records to extract them from")
        measured = extract_backbones(records, n_periods=n_periods)
    elif records is not None:
        raise ValueError(
            "give the measured backbones or the records to extract them from, not both "
            "(the backbones carry the harmonics their hold fits measured)"
        )
    data = fit_data(measured, noise_floor)
    steps = [s if isinstance(s, Step) else Step.from_dict(s) for s in history]
    return Criticism(
        model, data, method=method, weights=weights, candidates=candidates, criterion=criterion,
        alpha=alpha, n_bootstrap=n_bootstrap, seed=seed, posterior=draws,
        posterior_kind=posterior_kind, history=steps, executor=executor,
        participation=functools.cache(participation) if callable(participation) else participation,
    )  # fmt: skip


def _checked_draws(
    model: JointModel, posterior: tuple[Sequence[str], ArrayLike]
) -> tuple[list[str], np.ndarray]:
    """``(names, draws)`` checked against the model: known names, one column each, finite."""
    try:
        names, draws = list(posterior[0]), np.asarray(posterior[1], dtype=float)
    except (TypeError, ValueError, IndexError):
        raise ValueError("posterior must be a (names, draws) pair of parameter draws") from None
    if draws.ndim != 2 or draws.shape[1] != len(names) or draws.shape[0] == 0:
        raise ValueError(f"posterior draws must be (n_draws, {len(names)}), got {draws.shape}")
    unknown = [n for n in names if n not in model.parameter_names]
    if unknown:
        raise ValueError(
            f"posterior names {unknown} are not parameters of the model ({model.parameter_names})"
        )
    if not np.isfinite(draws).all():
        raise ValueError("posterior draws contain NaN or inf")
    return names, draws
