"""The regression's data: every record's library, scaled to group shares, one Gram per fold.

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
of their group than true stiffness terms carry of theirs.

**Folds.** Every record is cut into blocks of :data:`CV_BLOCK_PERIODS` periods
of its band's lower edge, dealt to the cross-validation folds in turn, so each
fold spans every excitation level; contiguous fifths of a stepped-level record
would hold out whole levels, and the held-out error would measure extrapolation
to amplitudes no training block has seen (on the trc-like rig records this made
the two-term, undamped model "best"). Each fold is reduced to the Gram matrix
of its rows (:mod:`.regression`).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from identification.measurements.signals import Kinematics, unscale_coefficients
from identification.sindy.library import LibraryTerm, design_rows, is_dissipative
from identification.sindy.regression import group_force

#: Length of the cross-validation blocks, in periods of the band's lower edge.
CV_BLOCK_PERIODS = 20


@dataclass(frozen=True, eq=False)
class Design:
    """Scaled Gram matrices of one library on a set of records, one per cross-validation fold."""

    fold_grams: list[np.ndarray]  # augmented [Θ | y], columns divided by `scale`
    sizes: np.ndarray  # rows per fold
    scale: np.ndarray  # per column, max|φ_i| · max|y| / max|group force|; then max|y|
    dissipative: np.ndarray  # per column, whether it is in the dissipative group
    tss: float  # total sum of squares of y (SI)
    rows: Sequence[np.ndarray]  # per record, unscaled, for bagging

    @property
    def gram(self) -> np.ndarray:
        """Gram matrix of all rows (scaled)."""
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


def build_design(
    kins: Sequence[Kinematics],
    terms: Sequence[LibraryTerm],
    offsets: Sequence[np.ndarray | None],
    n_folds: int,
) -> Design:
    """Band-passed library of every record, reduced to per-fold Gram matrices.

    Parameters
    ----------
    kins
        Band-limited kinematics of each record.
    terms
        Library columns.
    offsets
        Per record, the slow mean of the displacement to add back
        (:func:`.library.mean_offset`), or None.
    n_folds
        Cross-validation folds the blocks are dealt to.

    Raises
    ------
    ValueError
        A library column is zero on every record.
    """
    rows = [design_rows(k, terms, o) for k, o in zip(kins, offsets, strict=True)]
    peak = np.max([np.max(np.abs(r), axis=1) for r in rows], axis=0)
    zero = np.flatnonzero(peak[:-1] == 0)
    if zero.size:
        raise ValueError(
            f"library column(s) {[terms[i].effect for i in zero]} are zero on these records"
        )
    fold_grams = [np.zeros((peak.size, peak.size)) for _ in range(n_folds)]
    sizes = np.zeros(n_folds, dtype=int)
    # Short records get shorter blocks, so that every fold gets at least one.
    longest = sum(r.shape[1] for r in rows) // n_folds
    dealt = 0
    for kin, r in zip(kins, rows, strict=True):
        block = min(math.ceil(CV_BLOCK_PERIODS * kin.sampling_rate_hz / kin.band_hz[0]), longest)
        bounds = np.linspace(0, r.shape[1], max(1, r.shape[1] // block) + 1).astype(int)
        for start, stop in itertools.pairwise(bounds):
            fold_grams[dealt % n_folds] += r[:, start:stop] @ r[:, start:stop].T
            sizes[dealt % n_folds] += stop - start
            dealt += 1
    dissipative = np.array([is_dissipative(t) for t in terms])
    scale = peak.copy()
    scale[:-1] /= group_force(sum(fold_grams) / np.outer(peak, peak), rows, peak, dissipative)
    y_sum = sum(float(np.sum(r[-1])) for r in rows)
    y_squares = sum(float(r[-1] @ r[-1]) for r in rows)
    return Design(
        fold_grams=[g / np.outer(scale, scale) for g in fold_grams],
        sizes=sizes,
        scale=scale,
        dissipative=dissipative,
        tss=y_squares - y_sum**2 / sizes.sum(),
        rows=rows,
    )
