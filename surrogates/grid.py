"""Backbones on a fixed grid of response amplitudes: a representation every parameter set has.

At a response amplitude ``a`` (m) the harmonic balance gives the phase-resonant
frequency, the damping ratio and the base-acceleration amplitude ``A(a)`` the
backbone needs there (:func:`identification.analytical.harmonic.backbone`). On a
fixed amplitude grid these exist for every parameter vector, wherever the model
has a backbone at all; the **mask channel** ``has_backbone`` says where it has
none, one of (:data:`MASK_REASONS`):

``"no_solution"``
    no phase-resonant periodic solution (no positive stiffness) or the
    harmonic balance did not converge;
``"no_power_input"``
    ``A(a) ≤ 0``: the damping is negative there, the structure would self-excite
    rather than need a base excitation;
``"passed"``
    ``A(a)`` is not above every level already needed at a smaller amplitude, or
    falls there: a test stepping its level up jumps past this amplitude (the
    first crossing is the branch it follows, as
    :func:`~surrogates.dataset.generate_dataset`'s excitation-level inversion
    takes it).

``A(a)`` is evaluated on a refined grid (``refine`` points per grid interval and
a lead-in below the first amplitude down to ``1 / lead_in`` of it), so that a
fold between two grid points or below the grid is seen, and once more just
above every grid amplitude (relative step ``1e-6``): an amplitude is held when
its level exceeds every level on the refined grid below it and still rises there.
Masked entries hold the neutral value 0 in every value channel: never NaN, and
never a value a consumer could mistake for a backbone (a frequency of 0 Hz).

Measured curves (:func:`measured_on_grid`) are interpolated onto the grid where
they cover it; their base-acceleration level comes from the power balance of
each point (:func:`point_base_acceleration`). :func:`assembly_scatter` is the
spread of such curves across assemblies, per grid amplitude: the yardstick of
every accuracy figure. It needs at least three curves at an amplitude, so the
grid of a campaign (:func:`measured_grid`, the one definition the pipeline, the
CLI, the demo and the bench use) spans only the amplitudes that many measured
curves cover: beyond, the accuracy figures would have no yardstick, and a
standard deviation of two curves varies by a factor of several from campaign to
campaign.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from itertools import pairwise
from typing import Any

import numpy as np

from identification.analytical.harmonic import backbone
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from surrogates.runtime import REPRESENTATION_CHANNELS

__all__ = [
    "GRID_CHANNELS",
    "MASK_REASONS",
    "MIN_CURVES",
    "GridEvaluation",
    "MeasuredGrid",
    "assembly_scatter",
    "curves_covering",
    "geometric_grid",
    "grid_backbones",
    "grid_counts",
    "highest_before",
    "mask_reasons",
    "measured_grid",
    "measured_on_grid",
    "passed_curves",
    "point_base_acceleration",
]

#: Channels of an amplitude-grid backbone, in the order :func:`grid_backbones` returns them.
GRID_CHANNELS = REPRESENTATION_CHANNELS["amplitude_grid"][:4]
#: Relative step above a grid amplitude at which the slope of ``A(a)`` is taken.
_NUDGE = 1e-6
#: Why an entry is masked; code ``i + 1`` in :func:`grid_backbones`' reasons (0: a backbone).
MASK_REASONS = ("no_solution", "no_power_input", "passed")
#: Measured curves that must cover a grid amplitude: fewer give no assembly scatter there.
MIN_CURVES = 3


def highest_before(drive: np.ndarray, powered: np.ndarray) -> np.ndarray:
    """The largest powered drive before each point along the last axis (−inf at the first):
    the level a test stepping up has passed by the time it reaches the point."""
    highest = np.maximum.accumulate(np.where(powered, drive, -np.inf), axis=-1)
    first = np.full((*drive.shape[:-1], 1), -np.inf)
    return np.concatenate([first, highest[..., :-1]], axis=-1)


def mask_reasons(solved: np.ndarray, powered: np.ndarray, passed: np.ndarray) -> np.ndarray:
    """Each point's mask code: 0 for a backbone point, else ``1 +`` the index in
    :data:`MASK_REASONS` of the first that holds — the balance did not solve there, the
    hold needs no power input, a test stepping its level up has passed it."""
    codes = [1 + MASK_REASONS.index(r) for r in ("no_solution", "no_power_input", "passed")]
    return np.select([~solved, ~powered, passed], codes, default=0)


def passed_curves(reasons: np.ndarray) -> np.ndarray:
    """``(n,)`` True for the sets (rows of mask reasons ``(n, A)``) with an amplitude a test
    stepping its level up has passed."""
    return np.any(reasons == 1 + MASK_REASONS.index("passed"), axis=1)


def grid_counts(reasons: np.ndarray) -> dict[str, Any]:
    """A grid dataset's counts (its provenance's ``counts``) from the mask reasons ``(n, A)``
    of its sets, every set kept (code ``1 +`` the index in :data:`MASK_REASONS`, 0: a point)."""
    n, masked = len(reasons), reasons != 0
    return {
        "requested": n,
        "generated": n,
        "kept": n,
        "failed": 0,
        "non_monotone": int(passed_curves(reasons).sum()),
        "measured": 0,
        "curves_with_mask": int(masked.any(axis=1).sum()),
        "curves_without_backbone": int(masked.all(axis=1).sum()),
        "masked_entries": {
            reason: int(np.sum(reasons == 1 + i)) for i, reason in enumerate(MASK_REASONS)
        },
    }


def geometric_grid(amplitude_range_m: tuple[float, float], n_amplitudes: int) -> np.ndarray:
    """``n_amplitudes`` response amplitudes (m) geometric over ``amplitude_range_m``, ends included.

    The spacing of every amplitude grid (:func:`measured_grid`,
    :func:`~surrogates.dataset.generate_dataset`): equal ratios, as the backbones
    change on a logarithmic amplitude scale.
    """
    low, high = amplitude_range_m
    if not (0 < low < high and np.isfinite(high)) or n_amplitudes < 2:
        raise ValueError(
            f"need n_amplitudes ≥ 2 and 0 < low < high, got {n_amplitudes}, {amplitude_range_m}"
        )
    return np.geomspace(low, high, n_amplitudes)


@dataclass(frozen=True)
class GridEvaluation:
    """How to evaluate a model's backbone on the amplitude grid (what every chunk needs).

    Attributes
    ----------
    amplitudes_m
        The grid (m), increasing, positive.
    method, harmonics
        Harmonic balance: ``"single"`` or ``"multi"`` with ``harmonics``.
    refine
        Evaluation points per grid interval (1: the grid alone).
    lead_in
        The evaluation starts at ``amplitudes_m[0] / lead_in`` (≥ 1).
    lead_in_points
        Evaluation points below the grid.
    """

    amplitudes_m: np.ndarray
    method: str = "single"
    harmonics: int = 5
    refine: int = 4
    lead_in: float = 3.0
    lead_in_points: int = 12

    def __post_init__(self) -> None:
        grid = np.asarray(self.amplitudes_m, dtype=float)
        if grid.ndim != 1 or grid.size < 2 or not (grid[0] > 0 and np.all(np.diff(grid) > 0)):
            raise ValueError(f"amplitudes_m must be positive and increasing, got {grid}")
        if self.refine < 1 or self.lead_in < 1 or self.lead_in_points < 0:
            raise ValueError(
                f"need refine ≥ 1, lead_in ≥ 1, lead_in_points ≥ 0: {self.refine}, "
                f"{self.lead_in}, {self.lead_in_points}"
            )
        object.__setattr__(self, "amplitudes_m", grid)

    @property
    def dense(self) -> tuple[np.ndarray, np.ndarray]:
        """``(amplitudes, index)``: the evaluation points and where the grid lies among them."""
        grid = self.amplitudes_m
        lead = (
            np.geomspace(grid[0] / self.lead_in, grid[0], self.lead_in_points + 1)[:-1]
            if self.lead_in > 1 and self.lead_in_points
            else np.empty(0)
        )
        steps = [np.geomspace(a, b, self.refine + 1)[:-1] for a, b in pairwise(grid)]
        dense = np.concatenate([lead, *steps, grid[-1:]])
        index = lead.size + self.refine * np.arange(grid.size)
        return dense, index


def grid_backbones(
    model: JointModel, names: list[str], parameters: np.ndarray, how: GridEvaluation
) -> tuple[np.ndarray, np.ndarray]:
    """Backbones of parameter sets on the amplitude grid.

    Parameters
    ----------
    model, names
        Template model and the names of the varied parameters.
    parameters
        ``(n, len(names))`` values.
    how
        The grid and the harmonic balance.

    Returns
    -------
    values
        ``(n, n_amplitudes, 4)`` channels :data:`GRID_CHANNELS`: frequency (Hz),
        damping ratio, base acceleration (m/s²), has_backbone (0 or 1); masked
        entries are 0 in every value channel.
    reasons
        ``(n, n_amplitudes)`` int8: 0 where there is a backbone, else ``1 +``
        the index of the reason in :data:`MASK_REASONS`.
    """
    dense, index = how.dense
    sets = np.atleast_2d(parameters)
    result = backbone(
        model, dense, parameters=sets, names=names, method=how.method, harmonics=how.harmonics
    )
    # The base acceleration (m/s²) each parameter set needs at each evaluation amplitude.
    needed_m_s2 = result.base_acceleration
    frequency, damping = result.frequency_hz, result.damping_ratio
    solved = result.converged & np.isfinite(needed_m_s2) & np.isfinite(frequency) & (frequency > 0)
    powered = solved & (needed_m_s2 > 0)
    before = highest_before(needed_m_s2, powered)
    # And the slope at each grid amplitude: a level that falls there lies past a fold
    # (unknown where the nudged point has no backbone: not counted against it).
    nudged = backbone(
        model, dense[index] * (1 + _NUDGE), parameters=sets, names=names, method=how.method,
        harmonics=how.harmonics,
    ).base_acceleration  # fmt: skip
    falling = np.isfinite(nudged) & (nudged <= needed_m_s2[:, index])
    passed = (needed_m_s2[:, index] <= before[:, index]) | falling
    reasons = mask_reasons(solved[:, index], powered[:, index], passed).astype(np.int8)
    exists = reasons == 0
    values = np.stack(
        [
            np.where(exists, frequency[:, index], 0.0),
            np.where(exists, damping[:, index], 0.0),
            np.where(exists, needed_m_s2[:, index], 0.0),
            exists.astype(float),
        ],
        axis=-1,
    )
    return values, reasons


def point_base_acceleration(curve: Backbone, level_gain: float | None = None) -> np.ndarray:
    """Base-acceleration amplitude (m/s²) of each point of a measured curve.

    ``level_gain`` None: from the power balance of the point itself,
    ``A = 2 D ω² a / cos(phase error)`` (the extraction's damping ratio,
    :mod:`identification.measurements.backbone`), which needs no shaker
    calibration. A number: ``excitation_level × level_gain`` (m/s² per unit of the
    record's level, e.g. per shaker volt).
    """
    if level_gain is None:
        phase = 0.0 if curve.phase_error_deg is None else np.radians(curve.phase_error_deg)
        omega = 2 * np.pi * curve.frequency_hz
        excitation_m_s2 = 2 * curve.damping_ratio * omega**2 * curve.amplitude_m / np.cos(phase)
        if np.any(excitation_m_s2 <= 0):
            raise ValueError("a point has no positive power input (damping ratio ≤ 0)")
        return excitation_m_s2
    if curve.excitation_level is None:
        raise ValueError("it has no excitation levels to scale by level_gain")
    return curve.excitation_level * level_gain


def measured_on_grid(
    curve: Backbone,
    amplitudes_m: np.ndarray,
    level_gain: float | None = None,
    *,
    drive: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """A measured curve on the amplitude grid, where it covers it.

    ``drive`` False leaves the base acceleration out (NaN): for curves of free decays, or of
    a mode read through the modal filter, whose points need not have a positive power input.

    Returns
    -------
    values
        ``(n_amplitudes, 3)`` frequency (Hz), damping ratio and base acceleration
        (m/s², :func:`point_base_acceleration`), linear in amplitude between the
        curve's points (equal amplitudes averaged, as :attr:`Backbone.branch`);
        0 outside the curve's range.
    observed
        ``(n_amplitudes,)`` True inside the curve's amplitude range.
    """
    amplitude, inverse = np.unique(curve.amplitude_m, return_inverse=True)
    if amplitude.size < 2:
        raise ValueError("it needs two distinct amplitudes")
    counts = np.bincount(inverse)
    acceleration = (
        point_base_acceleration(curve, level_gain)
        if drive
        else np.full(curve.amplitude_m.shape, np.nan)
    )
    points = (curve.frequency_hz, curve.damping_ratio, acceleration)
    averaged = [np.bincount(inverse, weights=p) / counts for p in points]
    grid = np.asarray(amplitudes_m, dtype=float)
    observed = (grid >= amplitude[0] * (1 - 1e-12)) & (grid <= amplitude[-1] * (1 + 1e-12))
    values = np.stack([np.interp(grid, amplitude, p) for p in averaged], axis=-1)
    return np.where(observed[:, None], values, 0.0), observed


def _placed(
    curves: Iterable[Backbone], amplitudes_m: np.ndarray, level_gain: float | None,
    drive: bool = True,
) -> list[tuple[np.ndarray, np.ndarray]]:  # fmt: skip
    """:func:`measured_on_grid` of every curve it can place (two distinct amplitudes, a
    positive power input at every point); the others are left out."""
    placed = []
    for curve in curves:
        try:
            placed.append(measured_on_grid(curve, amplitudes_m, level_gain, drive=drive))
        except ValueError:
            continue
    return placed


def curves_covering(
    curves: BackboneSet,
    amplitudes_m: np.ndarray,
    *,
    level_gain: float | None = None,
    drive: bool = True,
) -> np.ndarray:
    """``(n_amplitudes,)`` int: how many measured curves cover each amplitude.

    A curve covers the amplitudes between its smallest and largest one; curves
    :func:`assembly_scatter` leaves out are not counted.
    """
    placed = _placed(curves, np.asarray(amplitudes_m, dtype=float), level_gain, drive)
    if not placed:
        return np.zeros(len(amplitudes_m), dtype=int)
    return np.sum([observed for _, observed in placed], axis=0).astype(int)


def assembly_scatter(
    curves: BackboneSet,
    amplitudes_m: np.ndarray,
    *,
    level_gain: float | None = None,
    min_curves: int = MIN_CURVES,
    drive: bool = True,
) -> np.ndarray:
    """Assembly-to-assembly standard deviation of measured curves per grid amplitude.

    ``(n_amplitudes, 3)`` for frequency (Hz), damping ratio and base acceleration
    (m/s²), the sample standard deviation over the curves that cover each
    amplitude; NaN where fewer than ``min_curves`` do. Curves that cannot be put
    on the grid (fewer than two amplitudes, no positive power input) are left out;
    ``drive`` False: the base acceleration is NaN and not asked for
    (:func:`measured_on_grid`).
    """
    if min_curves < 2:
        raise ValueError(f"min_curves must be ≥ 2 for a standard deviation, got {min_curves}")
    placed = _placed(curves, amplitudes_m, level_gain, drive)
    if not placed:
        return np.full((len(amplitudes_m), 3), np.nan)
    stacked = np.array([np.where(observed[:, None], v, np.nan) for v, observed in placed])
    enough = np.sum([observed for _, observed in placed], axis=0) >= min_curves
    scatter = np.full(stacked.shape[1:], np.nan)
    scatter[enough] = np.nanstd(stacked[:, enough], axis=0, ddof=1)
    return scatter


@dataclass(frozen=True)
class MeasuredGrid:
    """The amplitude grid of a campaign, and how many measured curves cover each amplitude.

    Attributes
    ----------
    amplitudes_m
        The grid (m): geometric (:func:`geometric_grid`) over the widest interval
        in which every amplitude is covered by at least ``min_curves`` curves.
    curves_covering
        Measured curves covering each grid amplitude (:func:`curves_covering`).
    min_curves
        The coverage the grid needs.
    measured_range_m
        Smallest and largest amplitude of any measured curve that can be placed.
    n_curves
        Measured curves that can be placed on a grid (:func:`assembly_scatter`'s).
    """

    amplitudes_m: np.ndarray
    curves_covering: np.ndarray
    min_curves: int
    measured_range_m: tuple[float, float]
    n_curves: int

    @property
    def range_m(self) -> tuple[float, float]:
        """The grid's first and last amplitude (m)."""
        return float(self.amplitudes_m[0]), float(self.amplitudes_m[-1])

    def to_dict(self) -> dict:
        """Plain JSON (for a sidecar or a bench record), with why the grid ends where it does."""
        return {
            "range_m": list(self.range_m),
            "n_amplitudes": int(self.amplitudes_m.size),
            "min_curves": self.min_curves,
            "measured_range_m": list(self.measured_range_m),
            "n_curves": self.n_curves,
            "curves_covering": self.curves_covering.tolist(),
            "why": (
                f"the widest amplitude interval where at least {self.min_curves} measured "
                "curve(s) cover every amplitude: the assembly scatter, the yardstick of the "
                f"accuracy figures, needs {MIN_CURVES}"
                + (
                    ""
                    if self.min_curves >= MIN_CURVES
                    else ", so it is undefined where fewer cover"
                )
            ),
        }


def measured_grid(
    curves: BackboneSet,
    n_amplitudes: int = 41,
    *,
    min_curves: int = MIN_CURVES,
    level_gain: float | None = None,
    drive: bool = True,
) -> MeasuredGrid:
    """The amplitude grid of a campaign: where at least ``min_curves`` measured curves cover.

    Every amplitude of the grid is covered by ``min_curves`` or more of the
    curves that can be placed on a grid (:func:`curves_covering`), so the
    assembly scatter (:func:`assembly_scatter`) is defined at each one (with its
    default of 3; ``min_curves=1`` gives the union of overlapping curves' ranges,
    the grid before issue #15). Where the covered amplitudes fall apart into
    several intervals (curves that do not overlap), the widest on a logarithmic
    scale is taken. ``drive`` False places curves without asking for a positive power
    input (:func:`measured_on_grid`).

    Raises
    ------
    ValueError
        When no interval of positive width is covered by ``min_curves`` curves.
    """
    if min_curves < 1:
        raise ValueError(f"min_curves must be ≥ 1, got {min_curves}")
    extents = [
        curve.amplitude_range_m
        for curve in curves
        if _placed([curve], np.array(curve.amplitude_range_m), level_gain, drive)
    ]
    if not extents:
        raise ValueError("no measured curve can be placed on an amplitude grid")
    low, high = np.array(extents).T
    ends = np.unique(np.concatenate([low, high]))
    # Between two consecutive ends the number of covering curves is constant: the curves
    # that start at or below the left end and end at or above the right one.
    segment = (low[:, None] <= ends[None, :-1]) & (high[:, None] >= ends[None, 1:])
    enough = np.concatenate([[False], segment.sum(axis=0) >= min_curves, [False]])
    starts = np.flatnonzero(~enough[:-1] & enough[1:])
    stops = np.flatnonzero(enough[:-1] & ~enough[1:])
    if starts.size == 0:
        raise ValueError(
            f"no amplitude interval is covered by {min_curves} measured curves "
            f"({len(extents)} curves can be placed)"
        )
    widest = np.argmax(np.log(ends[stops]) - np.log(ends[starts]))
    grid = geometric_grid((ends[starts[widest]], ends[stops[widest]]), n_amplitudes)
    return MeasuredGrid(
        amplitudes_m=grid,
        curves_covering=curves_covering(curves, grid, level_gain=level_gain, drive=drive),
        min_curves=min_curves,
        measured_range_m=(float(low.min()), float(high.max())),
        n_curves=len(extents),
    )
