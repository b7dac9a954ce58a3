"""Shape parameters of library columns, scanned over the records' range, never left at a default.

A column with a shape parameter (``tanh(x/x_s)``, ``exp(x/x_s) − 1``,
``sign(ẋ)·exp(−(ẋ/v_s)²)``, the Jenkins element's slip force) is a different
column at every shape. At a fixed default shape it imitates other columns with
fixed ratios that are the default's, not the data's (``exp(x/1 mm) − 1`` is
``x/x_s + x²/(2x_s²) + x³/(6x_s³) + …``), and the selection may take the
imitation over the physics. So every shape parameter the caller does not fix is
scanned over the grid its effect module gives for the records' scale
(``Effect.shape_grid`` of a :class:`~identification.effects.base.FitScale`, as
the criticism's fits do; :func:`scanned_parameters`), and the value with the
lowest held-out error of a least-squares fit of the library's other columns
plus this one is kept (:func:`scan_shapes`). Each effect is scanned with the
unscanned columns alone, so the scans do not depend on each other's order. A
value at which the column is the other columns in disguise is skipped: where
less than :data:`MIN_NOVELTY` of its mean square is left once the library's
unscanned columns have explained what they can (``tanh(x/x_s)`` with ``x_s``
above the amplitudes is ``x/x_s − x³/(3x_s³)`` there, ``exp(x/x_s) − 1`` is
``x/x_s + x²/(2x_s²) + …``). At such a shape the column adds nothing the
polynomials cannot say, yet its fixed ratios of powers take the polynomials'
place: on a free decay of an asymmetric oscillator, acceleration sensor, the
paper's library chose ``exp(x/5.6 mm)`` for the linear stiffness and its
backbone was 5 % off. An effect with no shape left is dropped from the
library for these records (:attr:`ShapeScan.chosen` None), and the report says so.

The scan works on the fold Gram matrices: each grid column is built and
band-passed once and only its products with the other columns are added
(:func:`augmented_fold_grams`).
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from identification.effects import CATALOGUE
from identification.effects.base import FitScale
from identification.measurements.signals import Kinematics
from identification.sindy.design import Design
from identification.sindy.library import (
    RANK_DEFICIENT,
    LibraryTerm,
    RankDeficientLibraryError,
    column_correlation,
    feature_rows,
)
from identification.sindy.selection import cross_validation

#: Condition number of the library (unit columns) above which a shape is not scanned: a
#: hundredth of the rank-deficiency limit, so that the scanned columns together stay below it.
SCAN_CONDITION = RANK_DEFICIENT / 100
#: Least fraction of a shaped column's mean square the library's unscanned columns must
#: leave unexplained (1 − R²) for the shape to count: 1e-4 is a 1 % RMS difference.
MIN_NOVELTY = 1e-4


@dataclass(frozen=True)
class ShapeScan:
    """The scan of one effect's shape: grid points, their held-out errors, the one kept.

    Attributes
    ----------
    effect
        Catalogue name.
    shapes
        The grid points (shape parameter values, SI).
    held_out, held_out_se
        Held-out mean square (weighted, scaled) of a least-squares fit of the
        library's unscanned columns plus this one, per grid point, and its
        standard error over the folds; NaN where the point was skipped.
    condition_number
        Of that library (unit columns); points above :data:`SCAN_CONDITION` are skipped.
    novelty
        Fraction of the column's mean square the unscanned columns leave unexplained;
        points below :data:`MIN_NOVELTY` are skipped.
    chosen
        Index of the kept grid point; None where every point was skipped (the effect is
        left out of the library).
    """

    effect: str
    shapes: tuple[dict[str, float], ...]
    held_out: np.ndarray
    held_out_se: np.ndarray
    condition_number: np.ndarray
    novelty: np.ndarray
    chosen: int | None

    def text(self) -> str:
        """One line for reports."""
        if self.chosen is None:
            return (f"{self.effect}: left out, the other columns in disguise at each of the "
                    f"{len(self.shapes)} shapes scanned (largest novelty "
                    f"{np.nanmax(self.novelty):.2g} < {MIN_NOVELTY:g})")  # fmt: skip
        values = ", ".join(f"{k}={v:.3g}" for k, v in self.shapes[self.chosen].items())
        skipped = int(np.count_nonzero(np.isnan(self.held_out)))
        note = f", {skipped} nearly rank-deficient skipped" if skipped else ""
        return f"{self.effect}: {values} (best of {len(self.shapes)} scanned{note})"


def fit_scale(kins: Sequence[Kinematics], amplitudes_m: np.ndarray) -> FitScale:
    """The records' scale: amplitude range, RMS frequencies ``rms(ẋ)/rms(x)`` of the records."""
    frequency_hz = [
        float(np.sqrt(np.mean(k.velocity[k.valid] ** 2) / np.mean(k.displacement[k.valid] ** 2)))
        / (2 * np.pi)
        for k in kins
    ]
    return FitScale.from_measurements(
        [amplitudes_m.min(), amplitudes_m.max()],
        [min(frequency_hz), max(frequency_hz)],
        stiffness=(2 * np.pi * float(np.median(frequency_hz))) ** 2,
    )


def scanned_parameters(
    effects: Sequence[str], shapes: Mapping[str, Mapping[str, Any]] | None, scale: FitScale
) -> dict[str, dict[str, np.ndarray]]:
    """Per library effect, the grid of each shape parameter the caller did not give."""
    shapes = shapes or {}
    scanned = {}
    for name in effects:
        grid = {param: np.asarray(values, dtype=float)
                for param, values in CATALOGUE[name].shape_grid(scale).items()
                if param not in shapes.get(name, {})}  # fmt: skip
        if grid:
            scanned[name] = grid
    return scanned


def scan_shapes(
    kins: Sequence[Kinematics],
    design: Design,
    terms: Sequence[LibraryTerm],
    scanned: Mapping[str, Mapping[str, np.ndarray]],
    offsets: Sequence[np.ndarray | None],
) -> tuple[dict[str, dict[str, float]], list[ShapeScan]]:
    """The shape of each scanned effect (those with none left out), and the scans.

    Parameters
    ----------
    kins
        Kinematics of the records.
    design
        Weighted design of the library's unscanned columns (possibly none).
    terms
        The library, scanned effects included (their other shape parameters as given).
    scanned
        Grids per effect (:func:`scanned_parameters`).
    offsets
        Displacement offsets of the design.
    """
    chosen, scans = {}, []
    weighted = design.weighted_rows()
    for term in terms:
        if term.effect not in scanned:
            continue
        grid = scanned[term.effect]
        points = [dict(zip(grid, values, strict=True))
                  for values in itertools.product(*grid.values())]  # fmt: skip
        held_out, se, condition, novelty = np.full((4, len(points)), np.nan)
        # Every grid column of the effect in one band-pass per record (one filter design,
        # one 2-D zero-phase pass): the scan's cost is the filtering of its columns.
        columns = [LibraryTerm(term.effect, {**term.shape, **point}) for point in points]
        grid_rows = [feature_rows(k, columns, o) for k, o in zip(kins, offsets, strict=True)]
        candidates = augmented_fold_grams(design, weighted, grid_rows)
        for i in range(len(points)):
            grams = list(candidates[i])
            correlation, condition[i] = column_correlation(sum(grams))
            novelty[i] = _novelty(correlation)
            if condition[i] > SCAN_CONDITION or novelty[i] < MIN_NOVELTY:
                continue
            n = grams[0].shape[0] - 1
            mean, error = cross_validation(grams, design.sizes, [np.ones(n, dtype=bool)])
            held_out[i], se[i] = mean[0], error[0]
        if np.all(np.isnan(held_out)):
            if np.all(condition > SCAN_CONDITION):
                raise RankDeficientLibraryError(
                    f"every scanned shape of {term.effect} makes the library (nearly) "
                    "rank-deficient on these records; drop it or fix its shape"
                )
            scans.append(ShapeScan(term.effect, tuple(points), held_out, se, condition,
                                   novelty, None))  # fmt: skip
            continue
        lowest = int(np.nanargmin(held_out))
        tied = np.flatnonzero(held_out <= held_out[lowest] + se[lowest])
        best = int(tied[np.argmin(condition[tied])])
        chosen[term.effect] = {k: float(v) for k, v in points[best].items()}
        scans.append(ShapeScan(term.effect, tuple(points), held_out, se, condition, novelty,
                               best))  # fmt: skip
    return chosen, scans


def _novelty(correlation: np.ndarray) -> float:
    """1 − R² of the last column on the others, from the columns' correlation matrix."""
    if correlation.shape[0] == 1:
        return 1.0
    # Least squares, not an inverse: the other columns may be singular among themselves.
    others, column = correlation[:-1, :-1], correlation[:-1, -1]
    explained = float(column @ np.linalg.lstsq(others, column, rcond=None)[0])
    return max(0.0, 1.0 - explained)


def augmented_fold_grams(
    design: Design, weighted: Sequence[np.ndarray], columns: Sequence[np.ndarray]
) -> np.ndarray:
    """The design's fold Grams with one more column, inserted before the target, per candidate.

    ``weighted`` are the design's weighted, scaled rows (:meth:`.Design.weighted_rows`);
    ``columns`` are per record ``(n_candidates, n_valid)`` candidate columns (valid samples,
    unscaled, unweighted); each is weighted like the rows and divided by its peak. Returns
    ``(n_candidates, n_folds, n + 1, n + 1)``: one augmented design per candidate, the
    products of all candidates with the rows taken in one matrix product per fold and record.
    """
    peak = np.max([np.max(np.abs(c), axis=1) for c in columns], axis=0)
    n = design.fold_grams[0].shape[0]
    grams = np.zeros((peak.size, len(design.fold_grams), n + 1, n + 1))
    for k, g in enumerate(design.fold_grams):
        grams[:, k, : n - 1, : n - 1] = g[:-1, :-1]
        grams[:, k, : n - 1, -1] = grams[:, k, -1, : n - 1] = g[:-1, -1]
        grams[:, k, -1, -1] = g[-1, -1]
    for record, (rows, column, w) in enumerate(zip(weighted, columns, design.weights,
                                                   strict=True)):  # fmt: skip
        fold = np.full(rows.shape[1], -1)
        for block in design.blocks:
            if block.record == record:
                fold[block.start : block.stop] = block.fold
        scaled = column * w / peak[:, None]
        for k in range(len(design.fold_grams)):
            held = fold == k
            c = scaled[:, held]
            cross = c @ rows[:, held].T  # (n_candidates, n): products with Θ's columns and y
            grams[:, k, n - 1, n - 1] += np.einsum("pi,pi->p", c, c)
            grams[:, k, : n - 1, n - 1] += cross[:, :-1]
            grams[:, k, n - 1, : n - 1] += cross[:, :-1]
            grams[:, k, n - 1, -1] += cross[:, -1]
            grams[:, k, -1, n - 1] += cross[:, -1]
    return grams
