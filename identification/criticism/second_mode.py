"""A missing mode as a finding: a second mode that exchanges energy with the criticised one.

On data that carry a second mode, catalogue effects each mimic a part of what a one-mode
model lacks (a backbone bent near the other mode, damping rising where the energy leaves,
a second harmonic it amplifies). This module asks whether a second mode explains the data
better, with the criticism's linearised statistic and calibrated bootstrap. The screen's
columns and their constants (the upper-case names below) are :mod:`~.mode_columns`'s.

**Two mechanisms, one column each per frequency.** With complex amplitudes at the levels
(``ω(a)`` the refitted base model's backbone, ``a`` the response amplitude):

* *through the joint* — a mode ``q`` at ``ω₂`` sharing ``b`` of the joint displacement
  (``u = x + b q``) is driven by the joint's force beyond what it is at rest,
  ``N(a) = Σ c_i (k_eq,i + iω c_eq,i)(a) − N(0)`` (the base model's own describing
  functions: the linear part at rest is in the modes). Eliminating ``q``
  (``q = −b N x / D₂(ω)``, ``D₂(Ω) = ω₂² − Ω² + 2iζ₂ω₂Ω``) adds
  ``Δ(a) = −b² [N² / D₂ + w a N′(a) Re(N / D₂)]`` to the first mode's dynamic stiffness at
  its own amplitude ``a`` (the second term: the joint moves by ``|u| = a |1 − b² N/D₂|``,
  not ``a``, and its force follows: ``w = 1`` where the sensor sees the first mode alone;
  where it sees the second mode too, ``a`` moves with ``|u|`` and ``w`` is less, so
  ``JOINT_WEIGHTS`` is a grid). The phase-resonant frequency moves by
  ``Re Δ / (2ω)`` and the damping ratio by ``Im Δ / (2ω²)`` — the backbone pushed away
  from the other mode, damping rising where the energy leaves. The column is ``∂/∂b²``
  (one-sided: ``b² ≥ 0``).
* *through a quadratic coupling* (1:2) — a mode near ``2ω`` driven by a modal potential
  ``κ x² q``: its response ``Z = −κ a²/(2 D₂(2ω))`` at ``2ω`` and its mean
  ``−κ a²/(2ω₂²)`` act back on the first mode (force ``2κ x q``), adding
  ``Δ(a) = −κ² a² [1 / (2 D₂(2ω)) + 1/ω₂²]`` to its dynamic stiffness: the column is
  ``∂/∂κ²`` (one-sided, ``COUPLING``). The same
  response adds ``C₂/a − iS₂/a = −θ a / (2 D₂(2ω))`` to the measured second harmonic
  (``θ = κ φ₂``, either sign, ``HARMONIC``; the relative displacement
  ``x = a cos θ + C₂ cos 2θ + S₂ sin 2θ``). As the backbone moves ``2ω`` towards ``ω₂``
  both turn in size and phase, which no catalogue term (whose even harmonics follow the
  first mode's own operator) does.

* *seen at the response sensor* — a mode the sensor sees (shape ``s`` there) and the base
  drives (participation ``Γ₂``) adds ``c/D₂(ω)``, ``c = sΓ₂``, to the measured receptance
  ``1/K₁``. The lock on the measured phase then moves ``ω²`` by ``Re(c I²/D₂)`` and the
  power-balance damping ratio by ``Im(c I²/D₂)/(2ω²)``, ``I = 2ζ(a)ω(a)²`` the first
  mode's damping stiffness: ``Δ = I²/D₂(ω)`` per unit ``c`` (either sign,
  ``SENSOR``), which follows the damping as it changes with amplitude (a constant
  shift is the linear stiffness's).

``ω₂ = r · ω₁`` over ``JOINT_RATIOS`` and ``COUPLING_RATIOS`` (``ω₁`` the base
model's frequency at the lowest level) and ``ζ₂`` the base model's damping ratio there (a
mode damped like the one measured: the data of one mode cannot say more). A mode the
backbone would cross — ``ω₂`` (``ω₂/2`` at 1:2) within the backbone's frequency range
widened by ``CROSSING_BANDWIDTHS`` half-power bandwidths — gets no column: there the
linearisation is singular, and a one-mode backbone could not pass it.

**One mode, its two routes fitted together** (``mode_routes``, ``route_gains``):
a mode sharing the joint is also seen at the sensor and driven by the base; a mode near
``2ω`` moves the backbone and the second harmonic at once. Each pair at one ``ω₂`` is
fitted by least squares in the criticism's whitened frame projected off the base model's
directions, the exchange's coefficient (``b²``, ``κ²``) ≥ 0; its ``Δχ²`` is the mode's gain.

**The rule** (fixed before the study, ``docs/criticism.md``, "A missing mode"). A second
mode is named when

1. the screen locates a mode — its gain less the larger of its family's two grid-end
   gains is at least :data:`~.config.SEPARATION` — and the best located mode's gain is
   above the ``1 − α'`` quantile of the largest mode gain over the decision's bootstrap
   campaigns (``α'``: :attr:`Calibration.level_each`); and
2. it exceeds the catalogue's best gain — linearised or refitted, the larger — by
   :data:`~.config.SEPARATION` (χ²₁, 1 %): within that the catalogue's answer stands.

The decision need not fire: the mode's test is a third test on the decision's bootstrap at
the level each test holds, so a one-mode campaign names a mode with probability at most
``α'`` and :attr:`~.criticism.Criticism.significant` fires with at most ``α + α'``.

**The frequency is the refit's, never the screen's** (near 1:1 a linearised column can
fit best far from the truth). Where 1 and 2 name a mode, the two-mode refit
(:mod:`~identification.criticism.mode_refit`) gives each route's profile over the second
mode's frequency and *locates* it by its rule, its gain beyond the catalogue's best by
``SEPARATION``; otherwise the mode is named "a second mode, frequency not located" with
why (:attr:`SecondMode.location`). The share and where it shows come from the screen's fit.

**Multi-point records place it directly.** Where the records carry the other mode's own
coordinate (``backbones --modes 2``), its participation places the named mode
(:mod:`~identification.criticism.participation`), else the refit does. Where its second
harmonic is located and the coupling's drive takes more than its threshold off, the
participation *names* the mode without the screen: a mode that takes energy from the
criticised one at twice its frequency, which a linear mode driven by the shaker does not.
Where the screen names none but the coordinate's fundamental is located (a mode near the
first), the participation names it as *seen beside the first* (:data:`SENSOR`): the sensors
show a mode the one-mode model lacks; whether it exchanges energy through the joint the
fundamental does not tell.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from identification.criticism import calibration as cal
from identification.criticism.config import SEPARATION
from identification.criticism.mode_columns import (
    COUPLING,
    HARMONIC,
    JOINT,
    SENSOR,
    mode_columns,
    mode_routes,
    route_gains,
    whitened,
)
from identification.criticism.mode_refit import RefitProfile, refit_profiles
from identification.criticism.participation import (
    PARTICIPATION,
    ROUTES,
    ModeParticipation,
    ParticipationLocation,
    locate_by_participation,
)
from identification.multimode.solve import energy_shares

if TYPE_CHECKING:
    from identification.criticism.decision import Decision

__all__ = [
    "PLACED_TOLERANCE",
    "Participation",
    "SecondMode",
    "second_mode",
]

#: How near (relative) the screen's best column must lie to a mode its participation placed
#: for the screen's words to describe that mode: the ±5 % a located frequency claims.
PLACED_TOLERANCE = 0.05


@dataclass(frozen=True)
class SecondMode:
    """The second-mode finding of one criticism.

    Attributes
    ----------
    named
        Whether the rule (module notes) names a second mode.
    mechanism
        :data:`JOINT`, :data:`SENSOR`, :data:`COUPLING` or :data:`HARMONIC`: the route
        named (the exchange where its fitted coefficient is not 0, else its pair's other).
    ratio, frequency_hz
        Its frequency over the first mode's, and in Hz, where the two-mode refit locates it
        (:mod:`~identification.criticism.mode_refit`); NaN where it does not.
    first_frequency_hz
        The first mode's frequency its ratio is to: where located, the one its profile was
        placed against (the holds' lowest level for the participation, the base model's at
        the lowest level for the refit); else the base model's.
    share
        The energy share it carries at the top level (from the linearised fit).
    gain, threshold
        Its ``χ²`` gain (its two routes fitted together, :func:`route_gains`) and the
        calibrated threshold (NaN where the rule was decided before the bootstrap was
        needed).
    catalogue_gain
        The catalogue's best gain, linearised or refitted (what it must exceed by ``SEPARATION``).
    where
        Where it shows, in words (participation, damping, the harmonic it feeds).
    why
        Why it was not named (empty when named).
    located, interval_hz, location
        Whether its frequency is located (where named), the interval (Hz; NaN where not
        located) and why not (empty where located or where the screen named none).
    screen_frequency_hz
        The linear screen's best column's frequency: a diagnostic, never a finding (near
        1:1 a linearised column may fit best far from the truth).
    located_by
        What placed the frequency: ``"participation"`` (the other mode's coordinate in
        multi-point records, :mod:`~identification.criticism.participation`), ``"refit"``
        (the two-mode refit of one response point's backbone); empty where not located.
    named_by, exchange, exchange_threshold
        What named it (``"screen"``, ``"participation"``: the coupling's drive of the other
        mode's coordinate at ``2ω``, or its fundamental shaped by a resonance; empty: not
        named), that drive's χ² and the χ² quantile it must exceed (NaN: none).
    resonance_gain
        Named by its coordinate's fundamental (mechanism :data:`SENSOR`): the χ² its
        resonance takes off a mode too far to resonate
        (:attr:`~.participation.ParticipationLocation.shows`); NaN otherwise.
    """

    named: bool
    mechanism: str
    ratio: float
    frequency_hz: float
    first_frequency_hz: float
    share: float
    gain: float
    threshold: float
    catalogue_gain: float
    where: tuple[str, ...] = ()
    why: str = ""
    located: bool = False
    interval_hz: tuple[float, float] = (float("nan"), float("nan"))
    location: str = ""
    screen_frequency_hz: float = float("nan")
    located_by: str = ""
    named_by: str = ""
    exchange: float = float("nan")
    exchange_threshold: float = float("nan")
    resonance_gain: float = float("nan")

    @property
    def text(self) -> str:
        """ "a second mode near F Hz (ratio r to the first, between L and H Hz) exchanges
        energy with it …", or "a second mode, frequency not located (why) …"."""
        how = {
            JOINT: "exchanges energy with it through the joint",
            SENSOR: "shows in the response beside it (the sensor sees it, the base drives it)",
        }.get(
            self.mechanism,
            "exchanges energy with it through a quadratic coupling at twice its frequency (1:2)",
        )
        if not self.located:
            why = f" ({self.location})" if self.location else ""
            return f"a second mode, frequency not located{why}: it {how}"
        low, high = self.interval_hz
        by = (
            " as its participation at the sensors places it"
            if self.located_by == PARTICIPATION
            else ""
        )
        return (
            f"a second mode near {self.frequency_hz:.4g} Hz (ratio {self.ratio:.3g} to the "
            f"first, between {low:.4g} and {high:.4g} Hz{by}) {how}"
        )

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self) | {"where": list(self.where), "text": self.text}


#: A participation given, or a function giving it (called only where a mode is named:
#: reading it from multi-point records costs an extraction).
type Participation = ModeParticipation | Callable[[], ModeParticipation | None] | None


def second_mode(
    decision: Decision,
    catalogue_refit_gain: float = -np.inf,
    participation: Participation = None,
) -> SecondMode:
    """The second-mode finding at ``decision`` (the rule of the module notes).

    Parameters
    ----------
    decision
        The calibrated decision of the criticism.
    catalogue_refit_gain
        The best admissible catalogue refit's ``Δχ²`` (``-inf``: none refitted).
    participation
        The other mode's participation in the holds (multi-point records), or a function
        giving it: where it locates the named mode, it places the frequency instead of the
        two-mode refit (:mod:`~identification.criticism.participation`).

    Returns
    -------
    SecondMode
        The finding, named or with why not.
    """
    return _Search(decision, catalogue_refit_gain, participation).finding


class _Search:
    """The rule applied to one decision: observed gains first, the bootstrap only where
    the observed gains leave the answer open."""

    def __init__(
        self, decision: Decision, catalogue_refit_gain: float, participation: Participation
    ) -> None:
        self.decision = decision
        self.modes = mode_columns(decision)
        self.routes = mode_routes(self.modes)
        self.catalogue_refit_gain = catalogue_refit_gain
        self.participation = participation

    @cached_property
    def projected(self) -> np.ndarray:
        """The columns whitened and projected off the base model's directions."""
        return cal.project(self.decision.observed, self.modes.columns)

    @cached_property
    def fit(self) -> tuple[np.ndarray, np.ndarray]:
        """Each mode's (route pair's) ``χ²`` gain and its two scaled coefficients."""
        return route_gains(self.projected, self.decision.observed.frame["z"], self.routes,
                           self.modes.one_sided)  # fmt: skip

    @property
    def gains(self) -> np.ndarray:
        """``(K,)`` each mode's gain: its routes fitted together (:func:`route_gains`)."""
        return self.fit[0]

    def threshold(self) -> float:
        """The ``1 − level_each`` quantile of the largest mode gain over the decision's own
        bootstrap campaigns (same seed and batches: the same campaigns), each campaign
        whitened in its own re-estimated covariance as the decision's statistics are."""
        decision = self.decision
        problem, calibration = decision.problem, decision.calibration
        rng = np.random.default_rng(calibration.seed)
        largest = []
        for first in range(0, calibration.n_bootstrap, cal.BOOTSTRAP_BATCH):
            n = min(cal.BOOTSTRAP_BATCH, calibration.n_bootstrap - first)
            residual, covariance = cal.simulate(problem, n, rng)
            projected, z = whitened(problem, residual, covariance, self.modes.columns)
            for b in range(n):
                gains, _ = route_gains(projected[b], z[b], self.routes, self.modes.one_sided)
                largest.append(float(np.max(gains, initial=0.0)))
        return float(np.quantile(largest, 1 - calibration.level_each))

    @cached_property
    def prominence(self) -> np.ndarray:
        """``(K,)`` each mode's gain less the larger of its family's two grid-end gains:
        what the mode's frequency adds. Far from the first mode a family's columns tend to
        one shape of no frequency (``N²``, ``a²``, ``I²``: a catalogue-like term), which
        says nothing of where a mode is."""
        out = np.zeros(self.gains.size)
        modes, first = self.modes, self.routes[:, 0]
        families = list(zip((modes.mechanisms[i] for i in first), modes.weights[first],
                            strict=True))  # fmt: skip
        for family in dict.fromkeys(families):
            rows = np.flatnonzero([f == family for f in families])
            out[rows] = self.gains[rows] - max(self.gains[rows[0]], self.gains[rows[-1]])
        return out

    @cached_property
    def located(self) -> np.ndarray:
        """``(K,)`` the modes whose frequency adds at least :data:`~.config.SEPARATION`."""
        return self.prominence >= SEPARATION

    @cached_property
    def best(self) -> int:
        """The mode that fits best among those whose frequency is located (the one whose
        frequency adds most where none is)."""
        if not self.located.any():
            return int(np.argmax(self.prominence))
        return int(np.argmax(np.where(self.located, self.gains, -np.inf)))

    @cached_property
    def route(self) -> int:
        """The best mode's route named: the one that exchanges energy (through the joint or
        the coupling) where its coefficient is not 0, else the other."""
        exchange, other = self.routes[self.best]
        return int(exchange if self.fit[1][self.best][0] > 0 else other)

    @cached_property
    def finding(self) -> SecondMode:
        decision, modes = self.decision, self.modes
        best, route = self.best, self.route
        gain = float(self.gains[best])
        catalogue = max(float(decision.observed.catalogue[0]), self.catalogue_refit_gain)
        why, threshold = "", float("nan")
        answer = self.participation_answer
        exchanges = answer is not None and answer.exchanges
        if exchanges:
            why = ""  # named by its participation (module notes): the screen is not needed
        elif not self.located.any():
            why = (
                "the linear screen locates no mode: none gains more than a mode at either end of "
                f"its grid by {SEPARATION:g}"
            )
        elif gain < catalogue + SEPARATION:
            why = (
                f"its gain Δχ² {gain:.4g} does not exceed the catalogue's best "
                f"({catalogue:.4g}) by {SEPARATION:g}"
            )
        else:
            threshold = self.threshold()
            if gain <= threshold:
                why = f"its gain Δχ² {gain:.4g} is below its calibrated threshold {threshold:.3g}"
        # Not named by the backbone, a mode its coordinate's fundamental places is still seen
        # beside the first at the sensors (module notes): named so, no exchange claimed.
        shows = bool(why) and answer is not None and answer.shows
        if shows:
            why = ""
        by_participation = exchanges or shows
        refit = self.placed() if not why else None
        location = "" if refit is None else refit.why_not_located
        by_refit = refit is not None and refit.method != PARTICIPATION
        if by_refit and not location and refit.gain < catalogue + SEPARATION:
            location = (
                f"the two-mode refit's gain Δχ² {refit.gain:.4g} does not exceed the "
                f"catalogue's best ({catalogue:.4g}) by {SEPARATION:g}"
            )
        located = refit is not None and not location
        measured = located and refit.method == PARTICIPATION
        if not why and not by_participation and not measured:
            why = self.unmeasured(gain, located)
            located = located and not why  # a mode not named states no frequency
        nan = float("nan")
        # Located, the ratio is to the first frequency its profile was placed against (the
        # participation's: the holds' lowest level; the refit's: the base model's).
        first = refit.first_frequency_hz if located else modes.first_frequency_hz
        mechanism = modes.mechanisms[route] if refit is None else refit.route
        return SecondMode(
            named=not why,
            mechanism=SENSOR if shows else mechanism,
            ratio=refit.frequency_hz / first if located else nan,
            frequency_hz=refit.frequency_hz if located else nan,
            first_frequency_hz=first,
            share=self.share(route),
            gain=gain,
            threshold=threshold,
            catalogue_gain=catalogue,
            where=self.shown(route, refit if located else None),
            why=why,
            located=located,
            interval_hz=refit.interval_hz if located else (nan, nan),
            location=location,
            screen_frequency_hz=float(modes.ratios[route] * modes.first_frequency_hz),
            located_by=refit.method if located else "",
            named_by="" if why else (PARTICIPATION if by_participation else "screen"),
            exchange=float("nan") if answer is None else answer.exchange,
            exchange_threshold=nan if answer is None else answer.exchange_threshold,
            resonance_gain=answer.profile.gain if shows else nan,
        )  # fmt: skip

    def unmeasured(self, gain: float, located: bool) -> str:
        """Why a mode the screen names, with no participation measured to place it, is not
        named (empty: it is).

        From one response point the screen's best column is one more amplitude-dependent
        stiffness and damping, and joint physics outside the catalogue bends a backbone so
        too: an Iwan joint's rest after ẋ|ẋ| took a joint-route column's gain, and the
        two-mode refit placed a mode near 1:1 for it on some campaigns. Such a mode is
        named only where what the free-form reference gains beyond the column is within the
        reference test's calibrated threshold (the column is all that is missing), and,
        where nothing locates it, the decision fires.
        """
        decision = self.decision
        if not located and not decision.significant:
            return (
                "its frequency is not located and the decision does not fire: an unplaced mode "
                "is not told from the model's own misfit"
            )
        rest = float(decision.observed.reference[0]) - gain
        limit = float(decision.calibration.reference_threshold)
        if rest > limit:
            where = "placed by the refit alone" if located else "not located"
            return (
                f"its frequency is {where}, and a free-form stiffness and damping gain "
                f"Δχ² {rest:.4g} beyond it (more than the reference test's threshold "
                f"{limit:.3g}): not told from joint physics outside the catalogue"
            )
        return ""

    def shown(self, route: int, placed: RefitProfile | None) -> tuple[str, ...]:
        """Where the mode shows, in words. Placed by its participation, the measured
        coordinate says it, and the screen's column (a linearised fit to the backbone's
        residual) is described beside it only where it is the placed mode: at the same
        harmonic (the fundamental, or 2ω) and within ``PLACED_TOLERANCE`` of its frequency;
        else the screen's words would describe another mode (docs/criticism.md)."""
        measured = self.measured_where(placed)
        if not measured:
            return self.where(route, None if placed is None else placed.frequency_hz)
        screen_hz = self.modes.ratios[route] * self.modes.first_frequency_hz
        same = self.modes.harmonic(route) == ROUTES[placed.route][0] and (
            abs(screen_hz / placed.frequency_hz - 1) <= PLACED_TOLERANCE
        )
        return (*measured, *self.where(route, placed.frequency_hz)) if same else measured

    @cached_property
    def given(self) -> ModeParticipation | None:
        """The other mode's participation (None where the records carry none)."""
        return self.participation() if callable(self.participation) else self.participation

    @cached_property
    def participation_answer(self) -> ParticipationLocation | None:
        """What the other mode's participation says (None where the records carry none)."""
        return None if self.given is None else locate_by_participation(self.given)

    def placed(self) -> RefitProfile:
        """The profile that places the named mode: its participation's where the records
        carry it and it locates the mode, else the two-mode refit's best route
        (:func:`~.mode_refit.refit_profiles`)."""
        answer = self.participation_answer
        if answer is not None and answer.located:
            return answer.profile
        return max(refit_profiles(self.decision), key=lambda p: p.gain)

    def measured_where(self, placed: RefitProfile | None) -> tuple[str, ...]:
        """The other mode's coordinate at the sensors, in words, where it placed the mode."""
        if placed is None or placed.method != PARTICIPATION:
            return ()
        return (self.given.words(ROUTES[placed.route][0]),)

    def coefficient(self, index: int) -> float:
        """Column ``index``'s coefficient per unit of its physical coefficient: from the
        best mode's routes fitted together where it is one of them, else its own
        linearised fit ``g⊥ᵀz / |g⊥|²``."""
        pair = list(self.routes[self.best])
        if index in pair:
            return float(self.fit[1][self.best][pair.index(index)] / self.modes.scale[index])
        column = self.projected[:, index]
        norm2 = float(column @ column)
        z = self.decision.observed.frame["z"]
        return float(column @ z / norm2 / self.modes.scale[index]) if norm2 > 1e-18 else 0.0

    def amplitudes(self, index: int) -> np.ndarray:
        """The second mode's amplitude at the levels (``|q|`` through the joint, ``|κ| a²/
        (2|D₂|)`` through the coupling, at the sensor for the harmonic column, ``|c| I a/
        |D₂|`` seen at the sensor), moving at :meth:`~.mode_columns.ModeColumns.harmonic`."""
        modes, theta = self.modes, self.coefficient(index)
        mechanism, h = modes.mechanisms[index], modes.harmonic(index)
        operator = modes.linear_operator(index, h)
        if mechanism == JOINT:  # |q| = b |N| a / |D₂(ω)|, b = √b²
            force = np.sqrt(max(theta, 0.0)) * modes.joint_force
            return np.abs(force * modes.levels_m / operator)
        if mechanism == SENSOR:  # driven by the base, A = I a at phase resonance
            return np.abs(theta * modes.damping_stiffness * modes.levels_m / operator)
        coupling = np.sqrt(max(theta, 0.0)) if mechanism == COUPLING else theta
        return np.abs(coupling * modes.levels_m**2 / (2 * operator))

    def share(self, index: int) -> float:
        """Energy share of the second mode at the top level."""
        modes = self.modes
        second, harmonic = self.amplitudes(index), modes.harmonic(index)
        coefficients = np.zeros((2, 5))  # modes × (mean, cos 1, sin 1, cos 2, sin 2)
        coefficients[0, 1] = modes.levels_m[-1]
        coefficients[1, 2 * harmonic - 1] = second[-1]
        omega = 2 * np.pi * modes.frequency_hz[-1]
        modal = 2 * np.pi * modes.first_frequency_hz * np.array([1.0, modes.ratios[index]])
        return float(energy_shares(coefficients, np.asarray(omega), modal)[1])

    def where(self, index: int, frequency_hz: float | None) -> tuple[str, ...]:
        """Where the mode shows, in words: the participation, the damping it takes, the
        frequency it bends, the harmonic it feeds (its frequency ``frequency_hz`` where
        located, else none stated)."""
        modes = self.modes
        pair = self.routes[self.best] if index in self.routes[self.best] else (index,)
        table = sum(self.coefficient(int(c)) * modes.tables[c] for c in pair)
        channels = list(self.decision.data.channels)
        mm = 1e3 * modes.levels_m
        second = self.amplitudes(index)
        out = [
            f"participation: {100 * second[-1] / modes.levels_m[-1]:.2g} % of the response "
            f"amplitude at {mm[-1]:.2g} mm ({100 * self.share(index):.2g} % of the energy)"
        ]
        if modes.mechanisms[index] != HARMONIC:
            damping = table[:, channels.index("damping_ratio")]
            frequency = table[:, channels.index("frequency_hz")]
            top = int(np.argmax(np.abs(damping)))
            onset = int(np.argmax(np.abs(damping) >= 0.5 * abs(damping[top])))
            sensor = modes.mechanisms[index] == SENSOR
            out.append(
                ("the measured damping moved with it" if sensor
                 else "damping rising where the energy leaves")
                + f": {100 * damping[top]:+.2g} %-points at {mm[top]:.2g} mm, from about "
                f"{mm[onset]:.2g} mm"
            )  # fmt: skip
            j = int(np.argmax(np.abs(frequency)))
            out.append(
                f"the backbone pushed {'down' if frequency[j] < 0 else 'up'} by "
                f"{abs(frequency[j]):.2g} Hz at {mm[j]:.2g} mm"
                + (", following the damping" if sensor else ", away from the other mode")
            )
        else:
            ratio = second / modes.levels_m
            d2 = modes.linear_operator(index, 2)
            turn = np.degrees(np.ptp(np.unwrap(np.angle(1 / d2))))
            out.append(
                f"the second harmonic it feeds: {100 * ratio[-1]:.2g} % of the fundamental at "
                f"{mm[-1]:.2g} mm, its phase turning by {turn:.0f}° over the levels as 2ω "
                + ("nears the second mode" if frequency_hz is None
                   else f"nears {frequency_hz:.4g} Hz")
            )  # fmt: skip
        return tuple(out)
