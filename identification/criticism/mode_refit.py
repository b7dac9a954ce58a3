"""A second mode refitted: the two-mode model's own phase-resonant backbone, not its linearisation.

The linearised columns of :mod:`~identification.criticism.second_mode` are a screen: they
detect that a mode is missing (a calibrated test), but near 1:1 the linearisation fails —
the mode moves with the first through the joint's stiffness at rest and the base's drive,
and the quadratic coupling then feeds the second harmonic from that motion, not from a
resonance near 2ω — and a column that resonates near twice the first mode's frequency can
fit the residual better than any column at the truth's frequency. A frequency named from
the screen may be wrong. This module asks the physics where the mode is:

* the refitted base model becomes mode 1 of a two-mode :class:`~identification.multimode.
  ModalModel` (:meth:`~identification.multimode.ModalModel.from_joint_model`); a second
  mode at ``ω₂ = r ω₁`` (``ζ₂`` the base model's damping ratio at the lowest level, as the
  screen's) shares the joint (shape entry ``b``: the joint's elements act on
  ``u = x + b q``), is driven by the base (participation ``Γ₂``, the first's 1) and
  coupled by the modal potential ``κ x² q`` (forces ``2κ x q`` and ``κ x²``);
* its phase-resonant backbone on mode 1 (:func:`~identification.multimode.solve.
  phase_resonance`, batched) gives the change of the mean prediction (frequency, damping
  ratio, mode 1's harmonics relative to its fundamental) against the model with the second
  mode cut off; whitened in the criticism's metric and projected off the base model's
  directions (its own parameters refitted to first order, as for every column of the
  criticism), its gain is ``|z|² − |z − Δ|²``: the χ² the two-mode model takes off;
* two routes (:data:`FAMILIES`): *through the joint* (ratios 0.85–1.2; ``b``, ``Γ₂``, ``κ``
  fitted) and *through the coupling* (ratios 1.6–2.4; ``κ``, ``b``, ``Γ₂`` fitted). At
  each ratio the route's values start from the best of a small grid and take Gauss–Newton
  steps (batched over the ratios): the *profile* over the ratio is the best gain there.

**Located** (the rule, fixed on tuning seeds 1–4 before the held-out block 8 000 000,
``docs/criticism.md``, "A missing mode"): the best ratio's neighbours on both sides were
solved (:data:`_EDGE_STEPS`: not the grid's end, not the band the backbone crosses, its
range widened by :data:`CROSSING_BANDWIDTHS` half-power bandwidths — a profile best beside
them says "a mode there or beyond", not where), and no ratio more than half of
:data:`LOCATED_WIDTH` from it fits within :data:`~.config.SEPARATION` of it (the frequency is
stated to ±5 %). Its *interval* is every ratio within ``SEPARATION`` of the best.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from identification.criticism import calibration as cal
from identification.criticism.config import SEPARATION
from identification.criticism.directions import mean_prediction
from identification.multimode.model import Coupling, ModalModel, Mode
from identification.multimode.solve import HarmonicSettings, phase_resonance

if TYPE_CHECKING:
    from identification.criticism.decision import Decision

__all__ = [
    "COUPLING_ROUTE",
    "CROSSING_BANDWIDTHS",
    "FAMILIES",
    "JOINT_ROUTE",
    "LOCATED_WIDTH",
    "PARAMETERS",
    "SETTINGS",
    "Family",
    "ModeAdded",
    "RefitProfile",
    "add_mode",
    "backbone_channels",
    "refit_profiles",
    "two_mode_model",
]

#: The route through the joint: the second mode's joint shape entry ``b``.
JOINT_ROUTE = "joint"
#: The route through a quadratic modal coupling ``κ x² q`` (1:2).
COUPLING_ROUTE = "coupling"
#: The widest interval (over its frequency) of a located mode: its frequency stated to ±5 %.
LOCATED_WIDTH = 0.1
#: Grid steps on each side of a located best that must have been solved (not the grid's end,
#: not the band the backbone crosses): the profile is known around it.
_EDGE_STEPS = 1
#: Half-power bandwidths by which the backbone's range is widened to the band the refit
#: leaves out (the screen's linearisation needs more, ``second_mode.CROSSING_BANDWIDTHS``).
CROSSING_BANDWIDTHS = 0.5
#: Harmonic balance of the refit: three harmonics (the measured second harmonic and the
#: mean are in), samples enough for the slip's kinks at these harmonics, a loose tolerance
#: (the gain is read to a fraction of a χ² unit).
SETTINGS = HarmonicSettings(harmonics=3, n_time=48, tol=1e-8, max_iter=20)


@dataclass(frozen=True)
class Family:
    """One route's grid: the ratios ``ω₂/ω₁`` and the starts of its values.

    Attributes
    ----------
    route
        :data:`JOINT_ROUTE` or :data:`COUPLING_ROUTE`.
    ratios
        ``ω₂/ω₁`` tried.
    start_values
        The route's values tried at each ratio before Gauss–Newton refines the best
        (:func:`_parameters`: ``(log b, Γ₂, κ')`` through the joint, ``(log κ', b, Γ₂)``
        through the coupling; ``κ'`` the coupling's force on mode 1 at the top level over
        its stiffness force, ``Γ₂`` the second mode's base participation, the first's 1).
    harmonic
        The harmonic of the first mode's frequency the second mode answers at.
    """

    route: str
    ratios: tuple[float, ...]
    start_values: tuple[tuple[float, float, float], ...]
    harmonic: int


#: The two routes' grids (1 % in ratio near 1:1, 2 % near 1:2).
FAMILIES: tuple[Family, ...] = (
    Family(JOINT_ROUTE, tuple(np.round(np.arange(0.85, 1.2 + 1e-9, 0.01), 4)),
           tuple((float(np.log(b)), g, 0.0) for b in (0.05, 0.15, 0.4)
                 for g in (-1.5, -0.5, 0.5, 1.5)), 1),
    Family(COUPLING_ROUTE, tuple(np.round(np.arange(1.6, 2.4 + 1e-9, 0.02), 4)),
           tuple((float(np.log(k)), 0.0, 0.0) for k in np.geomspace(0.004, 0.25, 6)), 2),
)  # fmt: skip


@dataclass(frozen=True)
class RefitProfile:
    """One route's refit over its grid.

    Attributes
    ----------
    route
        :data:`JOINT_ROUTE` or :data:`COUPLING_ROUTE`.
    ratios
        ``(R,)`` the family's ratios.
    profile
        ``(R,)`` the best gain over the sizes at each ratio (``-inf``: no candidate there —
        a mode the backbone would cross — or no size solved).
    values
        ``(R, 3)`` the route's values that gave it (:class:`Family`).
    first_frequency_hz
        ``ω₁/2π`` the ratios multiply.
    method
        What gave the profile, in the words: ``"refit"`` (this module) or
        ``"participation"`` (:mod:`~identification.criticism.participation`).
    """

    route: str
    ratios: np.ndarray
    profile: np.ndarray
    values: np.ndarray
    first_frequency_hz: float
    method: str = "refit"

    @property
    def best(self) -> int:
        """Index of the best ratio."""
        return int(np.argmax(self.profile))

    @property
    def gain(self) -> float:
        """The best gain (``-inf`` where nothing was solved)."""
        return float(self.profile[self.best])

    @property
    def frequency_hz(self) -> float:
        """The best ratio's frequency."""
        return float(self.ratios[self.best] * self.first_frequency_hz)

    @property
    def interval(self) -> tuple[int, int]:
        """First and last index of the ratios whose profile is within
        :data:`~.config.SEPARATION` of the best."""
        near = np.flatnonzero(self.profile >= self.gain - SEPARATION)
        return int(near.min()), int(near.max())

    @property
    def interval_hz(self) -> tuple[float, float]:
        """The interval in Hz."""
        low, high = self.interval
        return (float(self.ratios[low] * self.first_frequency_hz),
                float(self.ratios[high] * self.first_frequency_hz))  # fmt: skip

    @property
    def why_not_located(self) -> str:
        """Why the frequency is not located (empty: located; the module notes)."""
        if not np.isfinite(self.gain):
            return f"the {self.route} route's {self.method} solved at no ratio"
        best, solved = self.best, np.isfinite(self.profile)
        beside = np.arange(best - _EDGE_STEPS, best + _EDGE_STEPS + 1)
        if beside.min() < 0 or beside.max() >= solved.size or not solved[beside].all():
            return (
                f"the {self.route} route's {self.method} is best beside the end of its grid or the "
                "band the backbone would cross: a mode there or beyond it, not where"
            )
        apart = np.abs(self.ratios / self.ratios[best] - 1) > LOCATED_WIDTH / 2
        rival = apart & (self.profile > self.gain - SEPARATION)
        if rival.any():
            other = float(self.ratios[np.flatnonzero(rival)[0]] * self.first_frequency_hz)
            return (
                f"the {self.route} route's {self.method} fits as well "
                f"{100 * LOCATED_WIDTH / 2:.0f} % and more apart "
                f"(at {other:.4g} Hz as at {self.frequency_hz:.4g} Hz)"
            )
        return ""

    @property
    def located(self) -> bool:
        """Whether the data place the frequency (the module notes)."""
        return not self.why_not_located


def two_mode_model(decision: Decision) -> tuple[ModalModel, float]:
    """The refitted base model as mode 1 of a two-mode model whose second mode shares the
    joint (shape entry ``b``), the quadratic coupling ``κ x² q`` and the base's drive
    (participation ``Γ₂``) — all 0 here: a batch sets them, :data:`PARAMETERS` — and
    ``ω₁/2π`` (the base model's frequency at the lowest level, as the screen's)."""
    one = ModalModel.from_joint_model(decision.base.model)
    table = mean_prediction(decision.data, decision.base.predicted)
    channels = list(decision.data.channels)
    first = float(table[0, channels.index("frequency_hz")])
    zeta = float(table[0, channels.index("damping_ratio")])
    second = Mode(first, max(zeta, 0.0), 0.0)
    model = ModalModel(
        modes=(one.modes[0], second), joint_shapes=((1.0, 0.0),), elements=one.elements,
        couplings=(Coupling(1, (1, 1), 0.0), Coupling(2, (2, 0), 0.0)),
        name="a second mode through the joint and a quadratic coupling",
    )  # fmt: skip
    return model, first


#: The parameters a batch of :func:`two_mode_model` sets: mode 2's frequency, its joint
#: shape entry ``b``, the coupling's two coefficients (``2κ`` on mode 1, ``κ`` on mode 2)
#: and its base participation ``Γ₂``.
PARAMETERS = [
    "mode2.frequency_hz", "joint1.mode2", "coupling1", "coupling2", "mode2.participation",
]  # fmt: skip


def backbone_channels(
    model: ModalModel,
    levels_m: np.ndarray,
    channels: Sequence[str],
    parameters: np.ndarray | None = None,
) -> np.ndarray:
    """``(n_sets, n_levels, n_channels)`` mode 1's phase-resonant backbone as the criticism's
    channels read it: ``frequency_hz``, ``damping_ratio`` (the power balance
    ``Γ₁A/(2ω²a)``) and ``harmonic{k}_cos``/``_sin`` (``C_k/a``, ``S_k/a`` of mode 1 in the
    frame where its fundamental is ``a cos θ``); NaN for other channels and where the
    balance failed.

    Parameters
    ----------
    model
        The model (template when ``parameters`` is given).
    levels_m
        Mode 1's fundamental amplitudes, any order.
    channels
        The channels' names.
    parameters
        ``(n_sets, len(PARAMETERS))`` overrides of :data:`PARAMETERS`; None: the model.
    """
    levels = np.asarray(levels_m, float)
    order = np.argsort(levels)
    solution = phase_resonance(
        model, levels[order], settings=SETTINGS, parameters=parameters,
        names=None if parameters is None else PARAMETERS,
    )  # fmt: skip
    frequency, damping = np.atleast_2d(solution.frequency_hz, solution.damping_ratio)
    mode1 = solution.coefficients[..., 0, :].reshape((*frequency.shape, -1))
    amplitude = np.broadcast_to(solution.amplitude_m, frequency.shape)
    out = np.full((frequency.shape[0], levels.size, len(channels)), np.nan)
    for c, channel in enumerate(channels):
        if channel == "frequency_hz":
            values = frequency
        elif channel == "damping_ratio":
            values = damping
        elif channel.startswith("harmonic") and channel[8:-4].isdigit():
            k = int(channel[8:-4])
            if k > SETTINGS.harmonics:
                continue
            values = mode1[..., 2 * k - 1 if channel.endswith("_cos") else 2 * k] / amplitude
        else:
            continue
        out[:, order, c] = values
    return out


def _predictions(decision: Decision, model: ModalModel, parameters: np.ndarray) -> np.ndarray:
    """:func:`backbone_channels` at the decision's levels and channels."""
    return backbone_channels(model, decision.data.levels_m, decision.data.channels, parameters)


def _crossed(decision: Decision, family: Family, first_hz: float) -> np.ndarray:
    """Ratios whose mode the backbone crosses (its own range, widened by
    :data:`CROSSING_BANDWIDTHS` half-power bandwidths): a one-mode backbone could not pass
    such a mode, and the balance there follows an internal resonance."""
    table = mean_prediction(decision.data, decision.base.predicted)
    channels = list(decision.data.channels)
    frequency = table[:, channels.index("frequency_hz")]
    zeta = float(table[0, channels.index("damping_ratio")])
    widen = CROSSING_BANDWIDTHS * 2 * zeta
    low, high = np.nanmin(frequency) * (1 - widen), np.nanmax(frequency) * (1 + widen)
    at = np.asarray(family.ratios) * first_hz / family.harmonic
    return (at >= low) & (at <= high)


def _whitened(decision: Decision, change: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(p, n)`` changes ``(n, n_levels, n_channels)`` whitened and projected off the base
    model's directions, and ``(n,)`` whether each was solved everywhere it is compared."""
    metric = decision.metric
    columns = (metric.weights * change.reshape(change.shape[0], -1)[:, metric.keep]).T
    solved = np.all(np.isfinite(columns), axis=0)
    return cal.project(decision.observed, np.nan_to_num(columns)), solved


class _Gains:
    """The χ² gain of parameter sets of one decision's two-mode model (module notes)."""

    def __init__(self, decision: Decision) -> None:
        self.decision = decision
        self.model, self.first_hz = two_mode_model(decision)
        self.z = decision.observed.frame["z"]
        # κ in units of its force on mode 1 at the top level over mode 1's stiffness force
        self.coupling_unit = (2 * np.pi * self.first_hz) ** 2 / float(
            np.max(decision.data.levels_m)
        )
        cut = np.array([[self.first_hz, 0.0, 0.0, 0.0, 0.0]])
        self.cut = _predictions(decision, self.model, cut)[0]

    def columns(self, ratio: np.ndarray, values: np.ndarray, route: str) -> np.ndarray:
        """``(p, n)`` whitened, projected changes at ``ratio`` ``(n,)`` and the route's
        values ``(n, 3)`` (:func:`_parameters`); NaN columns where unsolved."""
        sets = _parameters(ratio * self.first_hz, values, route, self.coupling_unit)
        change = _predictions(self.decision, self.model, sets) - self.cut
        projected, solved = _whitened(self.decision, change)
        projected[:, ~solved] = np.nan
        return projected

    def gains(self, columns: np.ndarray) -> np.ndarray:
        """``(n,)`` ``|z|² − |z − g|²`` (``-inf`` where unsolved)."""
        out = 2 * columns.T @ self.z - np.sum(columns**2, axis=0)
        return np.where(np.isfinite(out), out, -np.inf)


def _parameters(frequency_hz: np.ndarray, values: np.ndarray, route: str,
                coupling_unit: float) -> np.ndarray:  # fmt: skip
    """``(n, 5)`` :data:`PARAMETERS` of the route's values ``(n, 3)``: through the joint
    ``(log b, Γ₂, κ')``, through the coupling ``(log κ', b, Γ₂)`` (``κ' = κ`` over
    ``coupling_unit``)."""
    if route == JOINT_ROUTE:
        b, gamma, kappa = np.exp(values[:, 0]), values[:, 1], values[:, 2] * coupling_unit
    else:
        kappa, b, gamma = np.exp(values[:, 0]) * coupling_unit, values[:, 1], values[:, 2]
    return np.column_stack([frequency_hz, b, 2 * kappa, kappa, gamma])


#: Finite-difference steps of the route's values (:func:`_parameters`) for Gauss–Newton.
_STEPS = np.array([0.05, 0.05, 0.002])


def _refine(gains: _Gains, route: str, ratio: np.ndarray, values: np.ndarray,
            best: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``steps`` Gauss–Newton steps in all three of the route's values at once (batched over
    the ratios; a step is kept where it gains)."""
    for _ in range(steps):
        n = ratio.size
        probes = np.concatenate([values] + [values + _STEPS[k] * np.eye(3)[k] for k in range(3)])
        columns = gains.columns(np.tile(ratio, 4), probes, route)
        here = columns[:, :n]
        jacobian = np.stack([(columns[:, (k + 1) * n:(k + 2) * n] - here) / _STEPS[k]
                             for k in range(3)], axis=2)  # (p, n, 3)  # fmt: skip
        residual = gains.z[:, None] - here
        step = np.zeros((n, 3))
        for i in range(n):
            if np.all(np.isfinite(jacobian[:, i])) and np.all(np.isfinite(residual[:, i])):
                step[i] = np.linalg.lstsq(jacobian[:, i], residual[:, i], rcond=1e-8)[0]
        step = np.clip(step, -_MAX_STEP, _MAX_STEP)
        tried = values + step
        gained = gains.gains(gains.columns(ratio, tried, route))
        better = gained > best
        values = np.where(better[:, None], tried, values)
        best = np.where(better, gained, best)
    return values, best


#: Gauss–Newton steps after the grid, and the largest step in each value.
_GAUSS_NEWTON_STEPS, _MAX_STEP = 3, np.array([0.7, 1.0, 0.05])
#: Sweeps in which each ratio starts again from its neighbours' values (a profile is a
#: maximum: a ratio whose own start led Gauss–Newton astray takes its neighbour's).
_SWEEPS = 3


def _continue(gains: _Gains, route: str, ratio: np.ndarray, values: np.ndarray,
              best: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Each ratio tries its neighbours' values, then one Gauss–Newton step, :data:`_SWEEPS`
    times."""
    for _ in range(_SWEEPS):
        below = np.vstack([values[:1], values[:-1]])
        above = np.vstack([values[1:], values[-1:]])
        tried = gains.gains(gains.columns(np.tile(ratio, 2), np.vstack([below, above]), route))
        for start, gained in zip((below, above), tried.reshape(2, -1), strict=True):
            better = gained > best
            values = np.where(better[:, None], start, values)
            best = np.where(better, gained, best)
        values, best = _refine(gains, route, ratio, values, best, 1)
    return values, best


def _family_profile(gains: _Gains, family: Family) -> RefitProfile:
    """One route's profile over its grid (module notes)."""
    ratios = np.asarray(family.ratios)
    crossed = _crossed(gains.decision, family, gains.first_hz)
    live = ratios[~crossed]
    grid = np.array(family.start_values)
    values = np.repeat(grid[None], live.size, 0).reshape(-1, 3)
    ratio = np.repeat(live, grid.shape[0])
    start = gains.gains(gains.columns(ratio, values, family.route)).reshape(live.size, -1)
    pick = np.argmax(start, axis=1)
    values, best = _refine(gains, family.route, live, grid[pick], start.max(axis=1),
                           _GAUSS_NEWTON_STEPS)  # fmt: skip
    values, best = _continue(gains, family.route, live, values, best)
    profile = np.full(ratios.size, -np.inf)
    profile[~crossed] = best
    fitted = np.full((ratios.size, 3), np.nan)
    fitted[~crossed] = values
    return RefitProfile(family.route, ratios, profile, fitted, gains.first_hz)


def refit_profiles(decision: Decision) -> tuple[RefitProfile, ...]:
    """Each route's refit profile at ``decision`` (:data:`FAMILIES`, module notes)."""
    gains = _Gains(decision)
    return tuple(_family_profile(gains, family) for family in FAMILIES)


@dataclass(frozen=True)
class ModeAdded:
    """A second mode added to the criticised model (:func:`add_mode`).

    Attributes
    ----------
    model
        The two-mode model: the refitted base model as mode 1, the second mode at
        ``frequency_hz`` with the route's values at the refit's grid ratio nearest it.
    route
        :data:`JOINT_ROUTE` or :data:`COUPLING_ROUTE`: the refit's family it was taken from.
    frequency_hz
        The second mode's frequency in the model (the grid ratio's).
    chi2_before, chi2_after
        χ² of the data against the one-mode and the two-mode model in the criticism's
        whitened metric, the base model's own parameters refitted to first order (as every
        column of the criticism).
    reference_gain
        What the free-form reference (a stiffness and a damping free at every level) takes
        off the one-mode model, for scale.
    """

    model: ModalModel
    route: str
    frequency_hz: float
    chi2_before: float
    chi2_after: float
    reference_gain: float

    @property
    def gain(self) -> float:
        """The χ² the second mode takes off."""
        return self.chi2_before - self.chi2_after

    @property
    def text(self) -> str:
        """One line: the mode added and the error falling."""
        return (
            f"added a second mode at {self.frequency_hz:.4g} Hz ({self.route} route): χ² "
            f"{self.chi2_before:.4g} → {self.chi2_after:.4g} (Δχ² {self.gain:.4g}; the "
            f"free-form reference takes {self.reference_gain:.4g})"
        )


def add_mode(decision: Decision, frequency_hz: float) -> ModeAdded:
    """The criticised model with a second mode near ``frequency_hz`` added.

    The route is the refit family whose grid holds ``frequency_hz`` over the base model's
    first frequency (:data:`FAMILIES`); its profile is refitted (module notes) and the
    values at the grid ratio nearest ``frequency_hz`` set the second mode's joint shape
    entry, coupling and base participation.

    Parameters
    ----------
    decision
        The criticism's decision (its data, metric and base model).
    frequency_hz
        Where the second mode was located (by its participation or by the refit).

    Raises
    ------
    ValueError
        No family's grid holds the frequency, or the refit solved no ratio near it (a mode
        the backbone crosses).
    """
    gains = _Gains(decision)
    ratio = frequency_hz / gains.first_hz
    family = next(
        (f for f in FAMILIES if min(f.ratios) - 0.05 <= ratio <= max(f.ratios) + 0.05), None
    )
    if family is None:
        raise ValueError(
            f"a second mode at {frequency_hz:.4g} Hz (ratio {ratio:.3g}) is on neither route's "
            f"grid ({', '.join(f'{f.route} {min(f.ratios)}–{max(f.ratios)}' for f in FAMILIES)})"
        )
    profile = _family_profile(gains, family)
    distance = np.where(np.isfinite(profile.profile), np.abs(profile.ratios - ratio), np.inf)
    best = int(np.argmin(distance))
    if not np.isfinite(distance[best]) or distance[best] > LOCATED_WIDTH / 2:
        raise ValueError(
            f"the refit solved no ratio within {LOCATED_WIDTH / 2:.0%} of {ratio:.3g}: the "
            "backbone crosses the mode there"
        )
    at_hz = profile.ratios[best : best + 1] * gains.first_hz
    sets = _parameters(at_hz, profile.values[best : best + 1], family.route, gains.coupling_unit)
    model = gains.model.with_parameters(dict(zip(PARAMETERS, sets[0], strict=True)))
    before = float(gains.z @ gains.z)
    return ModeAdded(
        model=dataclasses.replace(model, name="the criticised model with a second mode added"),
        route=family.route, frequency_hz=float(at_hz[0]), chi2_before=before,
        chi2_after=before - float(profile.profile[best]),
        reference_gain=float(decision.observed.reference[0]),
    )  # fmt: skip
