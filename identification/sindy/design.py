"""The regression's data: each record's library, weighted, scaled to group shares, Grams per fold.

**Weighted.** Each row is divided by the residual standard deviation the error
model gives it (:mod:`.weighting`), so that every amplitude of a record counts
by its accuracy, not by its size: a free decay is fitted and cross-validated
over its whole amplitude range, not on its first periods alone.

**Scaled to group shares.** Columns are divided by their maxima (the paper's
scaling, applied per column so that non-polynomial features scale too) and then
measured against their group's force: conservative columns (even in ``ẋ``; the
Jenkins element, a stiffness with hysteresis) against the restoring force,
dissipative columns (odd in ``ẋ``) against the dissipative force
(:data:`.library.GROUPS`, :func:`.regression.group_force`). The normalised
coefficient ``ξ_i = c_i max|φ_i| / max|f_group|`` is the term's share of its
group's force, and each group has its own STLSQ threshold. A single share of
the total force cannot work for resonance data: at phase resonance the
dissipative force balances the excitation, ``2ζ`` of the restoring force
(0.5–2 %), so viscous damping, structurally essential, ranks with the spurious
terms and is dropped, while dissipative terms that are spurious can carry more
of their group than true stiffness terms carry of theirs. The weights leave
these shares as they are (both sides of the regression are multiplied by them).

**Folds.** Every record is cut into blocks of :data:`CV_BLOCK_PERIODS` periods
of its band's lower edge (shorter for short records, so that each fold gets at
least :data:`BLOCKS_PER_FOLD` blocks of it), and the blocks of all records, in
order of their force amplitude, are dealt to the cross-validation folds in turn
(:func:`deal_blocks`): every fold spans every amplitude. Contiguous fifths of a
stepped-level record would hold out whole levels, and the held-out error would
measure extrapolation to amplitudes no training block has seen (on the trc-like
rig records this made the two-term, undamped model "best"); a decay dealt in
20-period blocks puts its start in one fold alone. Each fold is reduced to the
Gram matrix of its rows (:mod:`.regression`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from itertools import pairwise

import numpy as np

from identification.measurements.signals import Kinematics, unscale_coefficients
from identification.sindy.library import Columns, LibraryTerm, design_rows, is_dissipative
from identification.sindy.regression import group_force

#: Length of the cross-validation blocks, in periods of the band's lower edge.
CV_BLOCK_PERIODS = 20
#: Blocks per fold a short record is cut into at least (while blocks stay above
#: :data:`MIN_BLOCK_PERIODS`).
BLOCKS_PER_FOLD = 4
#: Shortest block, in periods of the band's lower edge: many times the correlation time of
#: the band-limited residual (about one over the bandwidth, a few ms).
MIN_BLOCK_PERIODS = 2


@dataclass(frozen=True)
class Block:
    """A run of valid samples of one record, held out together."""

    record: int
    start: int
    stop: int
    fold: int


@dataclass(frozen=True, eq=False)
class Design:
    """Weighted, scaled Gram matrices of one library on a set of records, one per fold."""

    fold_grams: list[np.ndarray]  # augmented [Θ | y], weighted, columns divided by `scale`
    sizes: np.ndarray  # rows per fold
    scale: np.ndarray  # per column, max|φ_i| · max|y| / max|group force|; then max|y|
    dissipative: np.ndarray  # per column, whether it is in the dissipative group
    tss: float  # total sum of squares of y (SI, unweighted)
    unweighted_gram: np.ndarray  # augmented Gram of all rows, unweighted, scaled
    rows: Sequence[np.ndarray]  # per record, unscaled and unweighted
    weights: Sequence[np.ndarray]  # per record and valid sample, max|y| / σ (ones: unweighted)
    blocks: Sequence[Block]

    @property
    def gram(self) -> np.ndarray:
        """Weighted Gram matrix of all rows (scaled)."""
        return sum(self.fold_grams)

    @property
    def n_rows(self) -> int:
        """Regression rows over all records."""
        return int(self.sizes.sum())

    def thresholds(self, pair: np.ndarray) -> np.ndarray:
        """Per-column thresholds from a (conservative, dissipative) pair."""
        return np.where(self.dissipative, pair[1], pair[0])

    def model_coefficients(self, xi: np.ndarray) -> np.ndarray:
        """SI coefficients in the model convention (``c_i = −w_i``) of normalised ones."""
        return -unscale_coefficients(xi, self.scale[:-1], self.scale[-1])

    def residuals(self, xi: np.ndarray) -> list[np.ndarray]:
        """Per record, the unweighted residual ``y − Θ c`` (m/s²) of normalised coefficients."""
        weights = np.append(-xi / self.scale[:-1], 1.0 / self.scale[-1]) * self.scale[-1]
        return [weights @ r for r in self.rows]

    def weighted_rows(self) -> list[np.ndarray]:
        """Per record, the scaled rows multiplied by their weights (what the fold Grams hold)."""
        return [r * w / self.scale[:, None] for r, w in zip(self.rows, self.weights, strict=True)]


def build_design(
    kins: Sequence[Kinematics],
    terms: Sequence[LibraryTerm],
    offsets: Sequence[np.ndarray | None],
    n_folds: int,
    sigma: Sequence[np.ndarray] | None = None,
    columns: Columns | None = None,
) -> Design:
    """Band-passed library of every record, weighted and reduced to per-fold Gram matrices.

    Parameters
    ----------
    kins
        Band-limited kinematics of each record.
    terms
        Library columns.
    offsets
        Per record, the slow mean of the displacement to add back
        (:func:`.library.mean_offset`, or a measured one), or None.
    n_folds
        Cross-validation folds the blocks are dealt to.
    sigma
        Per record, the residual standard deviation at each valid sample (m/s²,
        :class:`.weighting.ErrorModel`); rows are divided by it. None: unweighted.
    columns
        The records' columns computed so far (with the same ``offsets``), or None.

    Raises
    ------
    ValueError
        A library column is zero on every record.
    """
    if columns is None:
        rows = [design_rows(k, terms, o) for k, o in zip(kins, offsets, strict=True)]
    else:
        rows = columns.rows(terms)
    peak = np.max([np.max(np.abs(r), axis=1) for r in rows], axis=0)
    zero = np.flatnonzero(peak[:-1] == 0)
    if zero.size:
        raise ValueError(
            f"library column(s) {[terms[i].effect for i in zero]} are zero on these records"
        )
    if sigma is None:
        weights = [np.ones(r.shape[1]) for r in rows]
    else:
        weights = [peak[-1] / s for s in sigma]
    blocks = deal_blocks(kins, [r[-1] * w for r, w in zip(rows, weights, strict=True)], n_folds)
    fold_grams = [np.zeros((peak.size, peak.size)) for _ in range(n_folds)]
    sizes = np.zeros(n_folds, dtype=int)
    unweighted = np.zeros((peak.size, peak.size))
    for block in blocks:
        r = rows[block.record][:, block.start : block.stop]
        rw = r * weights[block.record][block.start : block.stop]
        fold_grams[block.fold] += rw @ rw.T
        sizes[block.fold] += block.stop - block.start
        unweighted += r @ r.T
    dissipative = np.array([is_dissipative(t) for t in terms])
    scale = peak.copy()
    scale[:-1] /= group_force(sum(fold_grams) / np.outer(peak, peak), rows, peak, dissipative)
    y_sum = sum(float(np.sum(r[-1])) for r in rows)
    return Design(
        fold_grams=[g / np.outer(scale, scale) for g in fold_grams],
        sizes=sizes,
        scale=scale,
        dissipative=dissipative,
        tss=float(unweighted[-1, -1]) - y_sum**2 / sizes.sum(),
        unweighted_gram=unweighted / np.outer(scale, scale),
        rows=rows,
        weights=weights,
        blocks=blocks,
    )


def deal_blocks(
    kins: Sequence[Kinematics], targets: Sequence[np.ndarray], n_folds: int
) -> list[Block]:
    """Cut each record into blocks and deal them to the folds in order of amplitude.

    ``targets`` is each record's (weighted) target over its valid samples; a
    block's amplitude is its RMS. Blocks are :data:`CV_BLOCK_PERIODS` periods of
    the band's lower edge, shorter where a record would otherwise give fewer than
    :data:`BLOCKS_PER_FOLD` per fold (not below :data:`MIN_BLOCK_PERIODS`), and
    never longer than an equal share of all rows per fold. Sorted by amplitude,
    they are dealt back and forth (0, 1, …, K−1, K−1, …, 0, …), so that the folds'
    amplitude mixes match.
    """
    total = sum(y.size for y in targets)
    cut = []
    for index, (kin, y) in enumerate(zip(kins, targets, strict=True)):
        period = kin.sampling_rate_hz / kin.band_hz[0]
        length = min(
            math.ceil(CV_BLOCK_PERIODS * period),
            max(math.ceil(MIN_BLOCK_PERIODS * period), y.size // (BLOCKS_PER_FOLD * n_folds)),
            max(1, total // n_folds),
        )
        bounds = np.linspace(0, y.size, max(1, y.size // length) + 1).astype(int)
        for start, stop in pairwise(bounds):
            cut.append((float(np.sqrt(np.mean(y[start:stop] ** 2))), index, int(start), int(stop)))
    cut.sort(key=lambda block: block[0])
    blocks = []
    for rank, (_, index, start, stop) in enumerate(cut):
        turn, position = divmod(rank, n_folds)
        fold = position if turn % 2 == 0 else n_folds - 1 - position
        blocks.append(Block(index, start, stop, fold))
    return blocks
