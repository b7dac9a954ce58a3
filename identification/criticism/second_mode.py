"""A missing mode as a finding: a second mode that exchanges energy with the criticised one.

On data that carry a second mode, catalogue effects each mimic a part of what a one-mode
model lacks (a backbone bent near the other mode, damping rising where the energy leaves,
a second harmonic it amplifies). This module asks whether a second mode explains the data
better, with the criticism's linearised statistic and calibrated bootstrap.

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
  :data:`JOINT_WEIGHTS` is a grid). The phase-resonant frequency moves by
  ``Re Δ / (2ω)`` and the damping ratio by ``Im Δ / (2ω²)`` — the backbone pushed away
  from the other mode, damping rising where the energy leaves. The column is ``∂/∂b²``
  (one-sided: ``b² ≥ 0``).
* *through a quadratic coupling* (1:2) — a mode near ``2ω`` driven by a modal potential
  ``κ x² q``: its response ``Z = −κ a²/(2 D₂(2ω))`` at ``2ω`` and its mean
  ``−κ a²/(2ω₂²)`` act back on the first mode (force ``2κ x q``), adding
  ``Δ(a) = −κ² a² [1 / (2 D₂(2ω)) + 1/ω₂²]`` to its dynamic stiffness: the column is
  ``∂/∂κ²`` (one-sided, :data:`COUPLING`). The same
  response adds ``C₂/a − iS₂/a = −θ a / (2 D₂(2ω))`` to the measured second harmonic
  (``θ = κ φ₂``, either sign, :data:`HARMONIC`; the relative displacement
  ``x = a cos θ + C₂ cos 2θ + S₂ sin 2θ``). As the backbone moves ``2ω`` towards ``ω₂``
  both turn in size and phase, which no catalogue term (whose even harmonics follow the
  first mode's own operator) does.

* *seen at the response sensor* — a mode the sensor sees (shape ``s`` there) and the base
  drives (participation ``Γ₂``) adds ``c/D₂(ω)``, ``c = sΓ₂``, to the measured receptance
  ``1/K₁``. The lock on the measured phase then moves ``ω²`` by ``Re(c I²/D₂)`` and the
  power-balance damping ratio by ``Im(c I²/D₂)/(2ω²)``, ``I = 2ζ(a)ω(a)²`` the first
  mode's damping stiffness: ``Δ = I²/D₂(ω)`` per unit ``c`` (either sign,
  :data:`SENSOR`), which follows the damping as it changes with amplitude (a constant
  shift is the linear stiffness's).

``ω₂ = r · ω₁`` over :data:`JOINT_RATIOS` and :data:`COUPLING_RATIOS` (``ω₁`` the base
model's frequency at the lowest level) and ``ζ₂`` the base model's damping ratio there (a
mode damped like the one measured: the data of one mode cannot say more). A mode the
backbone would cross — ``ω₂`` (``ω₂/2`` at 1:2) within the backbone's frequency range
widened by :data:`CROSSING_BANDWIDTHS` half-power bandwidths — gets no column: there the
linearisation is singular, and a one-mode backbone could not pass it.

**One mode, its two routes fitted together** (:func:`mode_routes`, :func:`route_gains`):
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
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import TYPE_CHECKING, Any

import numpy as np

from identification.criticism import calibration as cal
from identification.criticism.config import LINEAR_PAIR, SEPARATION
from identification.criticism.directions import Direction, mean_prediction
from identification.criticism.mode_refit import RefitProfile, refit_profiles
from identification.criticism.participation import (
    PARTICIPATION,
    ModeParticipation,
    ParticipationLocation,
    locate_by_participation,
)
from identification.effects import CATALOGUE
from identification.multimode.solve import energy_shares

if TYPE_CHECKING:
    from identification.criticism.decision import Decision
    from identification.model import JointModel

__all__ = [
    "COUPLING",
    "COUPLING_RATIOS",
    "CROSSING_BANDWIDTHS",
    "HARMONIC",
    "JOINT",
    "JOINT_RATIOS",
    "JOINT_WEIGHTS",
    "SENSOR",
    "ModeColumns",
    "SecondMode",
    "added_stiffness",
    "fed_harmonic",
    "joint_force",
    "mode_columns",
    "mode_routes",
    "route_gains",
    "second_mode",
]

#: The mechanism of a mode near the first, coupled through the joint's force.
JOINT = "joint"
#: A mode near twice the first, coupled quadratically: as the first mode's backbone sees it.
COUPLING = "coupling"
#: The same mode as the second harmonic of the response sees it.
HARMONIC = "harmonic"
#: A mode near the first that the response sensor sees beside it.
SENSOR = "sensor"
#: Second-mode frequencies over the first's tried through the joint (0.5 % steps).
JOINT_RATIOS = tuple(np.round(np.arange(0.8, 1.25 + 1e-9, 0.005), 4))
#: Weights ``w`` of the joint's amplitude term (module notes): what the sensor sees of the
#: second mode is not known from one sensor.
JOINT_WEIGHTS = (0.0, 0.5, 1.0)
#: Second-mode frequencies over the first's tried through a quadratic coupling.
COUPLING_RATIOS = tuple(np.round(np.arange(1.6, 2.4 + 1e-9, 0.005), 4))
#: Whether a column's coefficient (``b²``, ``κ²``; ``κφ₂``) has one physical sign.
_ONE_SIDED = {JOINT: True, COUPLING: True, HARMONIC: False, SENSOR: False}
#: Half-power bandwidths (2ζ of the frequency) by which the backbone's frequency range is
#: widened to find the modes it would cross.
CROSSING_BANDWIDTHS = 2.0
#: Amplitude (relative to the lowest level) at which the joint counts as at rest.
_AT_REST = 1e-3
#: How near (relative) the screen's best column must lie to a mode its participation placed
#: for the screen's words to describe that mode: the ±5 % a located frequency claims.
PLACED_TOLERANCE = 0.05


@dataclass(frozen=True, eq=False)
class ModeColumns:
    """The second-mode columns of one criticism (see the module notes).

    Attributes
    ----------
    tables
        ``(M, n_levels, n_channels)`` change of the mean prediction per unit coefficient.
    columns
        ``(p, M)`` the same, weighted kept entries (the likelihood's space), each divided
        by its ``scale`` (coefficients of very different sizes: ``b²`` is of order 1,
        ``κ²`` of order 10¹⁴ N²/m⁶).
    scale
        ``(M,)`` the largest absolute weighted entry of each column (1 where it is 0).
    mechanisms, ratios, weights
        ``(M,)`` each column's mechanism (:data:`JOINT`, :data:`SENSOR`, :data:`COUPLING`,
        :data:`HARMONIC`), ``ω₂/ω₁`` and the joint's amplitude weight (1 elsewhere).
    first_frequency_hz, damping_ratio
        ``ω₁/2π`` and the ``ζ₂`` the columns use (the base model's, at the lowest level).
    frequency_hz, levels_m
        The base model's backbone at the levels and the levels.
    joint_force, joint_slope
        ``(n_levels,)`` ``N(a)``, the joint's complex stiffness beyond rest, and
        ``a N′(a)``.
    damping_stiffness
        ``(n_levels,)`` ``I = 2ζ(a)ω(a)²`` of the base model's backbone.
    """

    tables: np.ndarray
    columns: np.ndarray
    scale: np.ndarray
    mechanisms: tuple[str, ...]
    ratios: np.ndarray
    weights: np.ndarray
    first_frequency_hz: float
    damping_ratio: float
    frequency_hz: np.ndarray
    levels_m: np.ndarray
    joint_force: np.ndarray
    joint_slope: np.ndarray
    damping_stiffness: np.ndarray

    @property
    def directions(self) -> list[Direction]:
        """Each column as the statistics read it (the joint's ``b²`` is one-sided)."""
        return [
            Direction(f"second mode ({m})", {"ratio": float(r)}, int(_ONE_SIDED[m]))
            for m, r in zip(self.mechanisms, self.ratios, strict=True)
        ]

    @property
    def one_sided(self) -> np.ndarray:
        """``(M,)`` whether each column's coefficient has one physical sign."""
        return np.array([_ONE_SIDED[m] for m in self.mechanisms])

    def harmonic(self, index: int) -> int:
        """The harmonic of the first mode's frequency column ``index``'s mode moves at."""
        return 2 if self.mechanisms[index] in (COUPLING, HARMONIC) else 1

    def linear_operator(self, index: int, harmonic: int) -> np.ndarray:
        """``D₂(hω)`` of column ``index`` at the levels."""
        return _operator(
            self.first_frequency_hz * self.ratios[index], self.damping_ratio,
            harmonic * self.frequency_hz,
        )  # fmt: skip


def _operator(frequency_hz: np.ndarray, damping_ratio: float, at_hz: np.ndarray) -> np.ndarray:
    """``D₂(Ω) = ω₂² − Ω² + 2iζ₂ω₂Ω`` of a mode at ``frequency_hz``, at ``at_hz``."""
    omega2, omega = 2 * np.pi * np.asarray(frequency_hz), 2 * np.pi * np.asarray(at_hz)
    return omega2**2 - omega**2 + 2j * damping_ratio * omega2 * omega


def joint_force(model: JointModel, levels_m: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """``N(a)``: the complex stiffness ``Σ c (k_eq + iω c_eq)`` of the model's terms beyond
    the linear pair, less its value at rest (the modes at rest hold that part)."""
    rest = np.full_like(levels_m, _AT_REST * np.min(levels_m))
    total = np.zeros(levels_m.size, complex)
    for term in model.terms:
        if term.effect in LINEAR_PAIR:
            continue
        spec = CATALOGUE[term.effect]
        k_eq, c_eq = spec.describing(levels_m, omega, **term.shape)
        k_0, c_0 = spec.describing(rest, omega, **term.shape)
        total += term.coefficient * ((k_eq - k_0) + 1j * omega * (c_eq - c_0))
    return total


def added_stiffness(
    mechanism: str,
    amplitude_m: np.ndarray,
    operator: np.ndarray,
    joint_force: np.ndarray | None = None,
    joint_slope: np.ndarray | None = None,
    at_rest: np.ndarray | None = None,
    damping_stiffness: np.ndarray | None = None,
) -> np.ndarray:
    """``Δ``, the first mode's added complex dynamic stiffness per unit coefficient, at its
    own amplitude ``a``.

    ``−[N² / D₂(ω) + a N′ Re(N / D₂(ω))]`` per unit ``b²`` through the joint
    (``joint_force`` ``N(a)``, ``joint_slope`` ``a N′(a)``, ``operator`` ``D₂(ω)``);
    ``−a² [1 / (2 D₂(2ω)) + 1/D₂(0)]`` per unit ``κ²`` through a quadratic coupling
    (``operator`` ``D₂(2ω)``, ``at_rest`` ``D₂(0) = ω₂²``: the second mode's mean);
    ``I² / D₂(ω)`` per unit ``sΓ₂`` seen at the sensor (``damping_stiffness`` ``I``). The
    phase-resonant frequency moves by ``Re Δ / (2ω)`` (rad/s) and the damping ratio by
    ``Im Δ / (2ω²)``.
    """
    if mechanism == JOINT:
        if joint_force is None or joint_slope is None:
            raise ValueError("the joint's mechanism needs joint_force and joint_slope")
        ratio = joint_force / operator
        return -(joint_force * ratio + joint_slope * ratio.real)
    if mechanism == COUPLING:
        if at_rest is None:
            raise ValueError("the coupling's mechanism needs at_rest, D₂(0)")
        return -(amplitude_m**2) * (1 / (2 * operator) + 1 / at_rest)
    if mechanism == SENSOR:
        if damping_stiffness is None:
            raise ValueError("the sensor's mechanism needs damping_stiffness, 2ζω²")
        return damping_stiffness**2 / operator
    raise ValueError(f"mechanism must be {JOINT!r}, {COUPLING!r} or {SENSOR!r}, got {mechanism!r}")


def fed_harmonic(amplitude_m: np.ndarray, operator: np.ndarray) -> np.ndarray:
    """``(C₂ − iS₂)/a`` per unit ``κφ₂``: the second harmonic of the response (relative to
    the fundamental ``a cos θ``) that a mode with ``operator`` ``D₂(2ω)`` adds."""
    return -amplitude_m / (2 * operator)


def mode_columns(decision: Decision) -> ModeColumns:
    """The second-mode columns at the decision's refitted base model."""
    data, metric = decision.data, decision.metric
    table = mean_prediction(data, decision.base.predicted)
    channels = list(data.channels)
    frequency = table[:, channels.index("frequency_hz")]
    damping = table[:, channels.index("damping_ratio")]
    levels = data.levels_m
    omega = 2 * np.pi * frequency
    first, zeta = float(frequency[0]), float(damping[0])
    force = joint_force(decision.base.model, levels, omega)
    stiffness = 2 * damping * omega**2  # I
    # a N'(a) by a central difference in log amplitude (hysteretic elements included)
    step = 1e-4
    slope = (
        joint_force(decision.base.model, levels * np.exp(step), omega)
        - joint_force(decision.base.model, levels * np.exp(-step), omega)
    ) / (2 * step)
    families = (
        *((JOINT, JOINT_RATIOS, w) for w in JOINT_WEIGHTS), (SENSOR, JOINT_RATIOS, 1.0),
        (COUPLING, COUPLING_RATIOS, 1.0), (HARMONIC, COUPLING_RATIOS, 1.0),
    )  # fmt: skip
    mechanisms = tuple(m for m, grid, _ in families for _ in grid)
    ratios = np.concatenate([grid for _, grid, _ in families])
    weights = np.concatenate([np.full(len(grid), w) for _, grid, w in families])
    tables = np.zeros((ratios.size, levels.size, len(channels)))
    f, z = channels.index("frequency_hz"), channels.index("damping_ratio")
    for mechanism, _, weight in families:
        rows = np.array([m == mechanism for m in mechanisms]) & (weights == weight)
        h = 2 if mechanism in (COUPLING, HARMONIC) else 1
        operator = _operator(first * ratios[rows, None], zeta, h * frequency)  # D₂(hω)
        if mechanism == HARMONIC:
            if "harmonic2_cos" in channels:
                fed = fed_harmonic(levels, operator)
                tables[rows, :, channels.index("harmonic2_cos")] = fed.real
                tables[rows, :, channels.index("harmonic2_sin")] = -fed.imag
            continue
        at_rest = _operator(first * ratios[rows, None], zeta, 0 * frequency)
        added = added_stiffness(
            mechanism, levels, operator, force, weight * slope, at_rest, stiffness
        )
        tables[rows, :, f] = added.real / (2 * omega) / (2 * np.pi)
        tables[rows, :, z] = added.imag / (2 * omega**2)
    # a mode the backbone would cross: no column (see the module notes)
    widen = CROSSING_BANDWIDTHS * 2 * zeta
    low, high = np.nanmin(frequency) * (1 - widen), np.nanmax(frequency) * (1 + widen)
    harmonic = np.array([2.0 if m in (COUPLING, HARMONIC) else 1.0 for m in mechanisms])
    crossed = (ratios * first / harmonic >= low) & (ratios * first / harmonic <= high)
    tables[crossed] = 0.0
    flat = tables.reshape(ratios.size, -1)[:, metric.keep]
    columns = np.nan_to_num((metric.weights * flat).T, nan=0.0, posinf=0.0, neginf=0.0)
    scale = np.max(np.abs(columns), axis=0, initial=0.0)
    scale[scale == 0] = 1.0
    return ModeColumns(
        tables=tables, columns=columns / scale, scale=scale, mechanisms=mechanisms, ratios=ratios,
        weights=weights,
        first_frequency_hz=first, damping_ratio=zeta, frequency_hz=frequency,
        levels_m=levels, joint_force=force, joint_slope=slope, damping_stiffness=stiffness,
    )  # fmt: skip


def _whitened(
    problem: cal.Problem, residual: np.ndarray, covariance: np.ndarray, columns: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Bootstrap campaigns' ``(B, p, M)`` columns and ``(B, p)`` residuals whitened in each
    campaign's own covariance and projected off the base model's directions: the frame of
    :func:`~.calibration.statistics`, for columns fitted two at a time."""
    inverse = np.linalg.inv(np.linalg.cholesky(problem.weighted(covariance)))
    batch, p = residual.shape
    # one flat product: a stack of small BLAS calls costs far more in threads and overhead
    white = np.concatenate([
        (inverse.reshape(-1, p) @ columns).reshape(batch, p, -1),
        np.einsum("bij,bj->bi", inverse, residual)[:, :, None],
    ], axis=2)  # fmt: skip
    basis, _ = np.linalg.qr(np.einsum("bij,jk->bik", inverse, problem.base))
    projected = white - np.einsum("bik,bkm->bim", basis, np.einsum("bik,bim->bkm", basis, white))
    return projected[:, :, :-1], projected[:, :, -1]


def mode_routes(modes: ModeColumns) -> np.ndarray:
    """``(K, 2)`` the columns of one mode's two routes, fitted together: through the joint
    (each weight ``w``) with seen at the sensor, and through the quadratic coupling with
    the second harmonic it feeds, each pair at one frequency ``ω₂``."""
    index = {
        (m, float(w), float(r)): i
        for i, (m, w, r) in enumerate(zip(modes.mechanisms, modes.weights, modes.ratios,
                                          strict=True))
    }  # fmt: skip
    pairs = [
        (i, index[(SENSOR, 1.0, r)] if m == JOINT else index[(HARMONIC, 1.0, r)])
        for (m, _, r), i in index.items()
        if m in (JOINT, COUPLING)
    ]
    return np.array(pairs, dtype=int).reshape(-1, 2)


def route_gains(
    projected: np.ndarray, z: np.ndarray, routes: np.ndarray, one_sided: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Each mode's ``χ²`` gain with its two routes' columns fitted together.

    Parameters
    ----------
    projected
        ``(p, M)`` the columns whitened and projected off the base model's directions.
    z
        ``(p,)`` the residual, whitened and projected alike.
    routes
        ``(K, 2)`` each mode's two columns (:func:`mode_routes`).
    one_sided
        ``(M,)`` whether a column's coefficient has one physical sign.

    Returns
    -------
    gains, coefficients
        ``(K,)`` the least-squares gain ``|z|² − min |z − θ₁g₁ − θ₂g₂|²`` with each
        one-sided coefficient ≥ 0 (an unconstrained optimum outside is replaced by the
        better route alone: the optimum of a concave quadratic on the boundary), and
        ``(K, 2)`` the coefficients in the columns' own (scaled) units.
    """
    g1, g2 = projected[:, routes[:, 0]], projected[:, routes[:, 1]]
    s1, s2 = one_sided[routes[:, 0]], one_sided[routes[:, 1]]
    n11, n22, n12 = np.sum(g1 * g1, 0), np.sum(g2 * g2, 0), np.sum(g1 * g2, 0)
    d1, d2 = g1.T @ z, g2.T @ z
    live1, live2 = n11 > 1e-18, n22 > 1e-18
    # each route alone (0 where silent or of the wrong sign)
    t1 = np.where(live1 & ~(s1 & (d1 < 0)), d1 / np.where(live1, n11, 1.0), 0.0)
    t2 = np.where(live2 & ~(s2 & (d2 < 0)), d2 / np.where(live2, n22, 1.0), 0.0)
    alone1, alone2 = t1 * d1, t2 * d2
    # both together, where they are not collinear and the signs are physical
    det = n11 * n22 - n12**2
    both = live1 & live2 & (det > 1e-9 * n11 * n22)
    safe = np.where(both, det, 1.0)
    b1, b2 = (n22 * d1 - n12 * d2) / safe, (n11 * d2 - n12 * d1) / safe
    both &= ~(s1 & (b1 < 0)) & ~(s2 & (b2 < 0))
    gains = np.where(both, b1 * d1 + b2 * d2, np.maximum(alone1, alone2))
    first = alone1 >= alone2
    coefficients = np.stack([
        np.where(both, b1, np.where(first, t1, 0.0)),
        np.where(both, b2, np.where(first, 0.0, t2)),
    ], axis=1)  # fmt: skip
    return gains, coefficients


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
        located) and why not (empty where located or not named).
    screen_frequency_hz
        The linear screen's best column's frequency: a diagnostic, never a finding (near
        1:1 a linearised column may fit best far from the truth).
    located_by
        What placed the frequency: ``"participation"`` (the other mode's coordinate in
        multi-point records, :mod:`~identification.criticism.participation`), ``"refit"``
        (the two-mode refit of one response point's backbone); empty where not located.
    named_by, exchange, exchange_threshold
        What named it (``"screen"``, ``"participation"``: the coupling's drive of the other
        mode's coordinate at ``2ω``; empty: not named), that drive's χ² and the χ² quantile
        it must exceed (NaN: none).
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
            projected, z = _whitened(problem, residual, covariance, self.modes.columns)
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
        by_participation = answer is not None and answer.exchanges
        if by_participation:
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
        refit = self.placed() if not why else None
        location = "" if refit is None else refit.why_not_located
        by_refit = refit is not None and refit.method != PARTICIPATION
        if by_refit and not location and refit.gain < catalogue + SEPARATION:
            location = (
                f"the two-mode refit's gain Δχ² {refit.gain:.4g} does not exceed the "
                f"catalogue's best ({catalogue:.4g}) by {SEPARATION:g}"
            )
        located = refit is not None and not location
        nan = float("nan")
        # Located, the ratio is to the first frequency its profile was placed against (the
        # participation's: the holds' lowest level; the refit's: the base model's).
        first = refit.first_frequency_hz if located else modes.first_frequency_hz
        return SecondMode(
            named=not why,
            mechanism=modes.mechanisms[route] if refit is None else refit.route,
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
        )  # fmt: skip

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
        placed_harmonic = 2 if placed.route == COUPLING else 1
        same = self.modes.harmonic(route) == placed_harmonic and (
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
        return (self.given.words(2 if placed.route == COUPLING else 1),)

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
        |D₂|`` seen at the sensor), moving at :meth:`ModeColumns.harmonic`."""
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
