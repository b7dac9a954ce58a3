"""The linear screen's columns of a second mode: what a mode at each trial frequency adds
to the one-mode backbone through each route (the joint, a quadratic coupling, the harmonic
it feeds, the sensor), and the gain of a mode's routes fitted together.

The physics and the rules are :mod:`identification.criticism.second_mode`'s module notes;
this module builds what its search scans.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from identification.criticism import calibration as cal
from identification.criticism.config import LINEAR_PAIR
from identification.criticism.directions import Direction, mean_prediction
from identification.effects import CATALOGUE

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
    "ONE_SIDED",
    "SENSOR",
    "ModeColumns",
    "added_stiffness",
    "fed_harmonic",
    "joint_force",
    "mode_columns",
    "mode_routes",
    "route_gains",
    "whitened",
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
ONE_SIDED = {JOINT: True, COUPLING: True, HARMONIC: False, SENSOR: False}
#: Half-power bandwidths (2ζ of the frequency) by which the backbone's frequency range is
#: widened to find the modes it would cross.
CROSSING_BANDWIDTHS = 2.0
#: Amplitude (relative to the lowest level) at which the joint counts as at rest.
_AT_REST = 1e-3


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
            Direction(f"second mode ({m})", {"ratio": float(r)}, int(ONE_SIDED[m]))
            for m, r in zip(self.mechanisms, self.ratios, strict=True)
        ]

    @property
    def one_sided(self) -> np.ndarray:
        """``(M,)`` whether each column's coefficient has one physical sign."""
        return np.array([ONE_SIDED[m] for m in self.mechanisms])

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


def whitened(
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
