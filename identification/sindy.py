"""SINDy identification of a joint model from phase-resonance records.

The model is ``ẍ + Σ c_i φ_i(x, ẋ) = −a_base`` (:class:`~identification.model.JointModel`)
with ``x`` the centre displacement relative to the base. Everything the
regression needs is in the absolute acceleration ``y = ẍ + a_base = −Σ c_i φ_i``,
so the identification is one sparse regression of ``y`` on the library columns
``φ_i(x, ẋ)`` (catalogue effects, :mod:`identification.effects`).

Why it is built this way:

* **pysindy's optimisers, not** ``ps.SINDy``. Fitting ``SINDy`` on the state
  ``(x, ẋ)`` with ``u = a_base`` would also identify the kinematic row
  ``ẋ = v`` and a free gain on ``u``, while the model fixes that gain to one; and
  the Jenkins (``microslip``) feature needs the whole displacement path, which a
  ``CustomLibrary`` only sees sample by sample when simulating. So the library
  matrix is built here from the catalogue and the sparse regression is
  ``pysindy.STLSQ`` (and ``pysindy.EnsembleOptimizer`` for bagging).
* **One filter on both sides.** ``y`` is band-limited (first three harmonics),
  so every library column passes the same zero-phase band-pass before the
  regression. A column's harmonics above the band would otherwise have nothing
  to match (Coulomb's square wave keeps only 90 % of its energy in harmonics 1
  and 3, which would bias its coefficient by about 10 %), and its slow mean
  (x², ẋ²) nothing to balance.
* **Mean-offset reconstruction.** An asymmetric stiffness shifts the mean of the
  relative displacement with the amplitude; velocity data cannot show that
  offset, and without it the cubic term leaks into the quadratic one (a
  relative bias of about ``−1.5 c₃ a² / k`` on the quadratic coefficient, with
  ``c₃`` the cubic one and ``k`` the linear stiffness: −11 % for a 3 % cubic
  frequency shift). After each fit the slow offset implied by the model's
  quasi-static balance is added back to the displacement and the fit repeated
  with the same support (``offset_iterations``); the iterate with the lowest
  cross-validated error is kept and its support chosen again.
* **Data.** Whole records, ramps and PLL transients included: the equation of
  motion holds at every instant, not only in steady state, so no sample needs
  to be thrown away; only ``edge_periods`` periods at each end, where the
  zero-phase filters ring, are left out. As in the paper, the acceleration
  comes from the velocity channel by central differences and the
  displacement by the trapezoidal rule (:func:`~identification.measurements.signals.kinematics`);
  both are zero-phase, so their small gain errors (``(ωh)²/6`` and
  ``(ωh)²/12``, 7e-4 and 3e-4 at 100 Hz and 10 kHz) act on the stiffness and
  never leak into the damping. Several records (assemblies, runs) are fitted
  jointly: the model is then their population model.
* **Two groups, two thresholds.** Columns are divided by their maxima (the
  paper's scaling, applied per column so that non-polynomial features scale
  too) and then measured against their group's force: conservative columns
  (even in ``ẋ``; the Jenkins element, a stiffness with hysteresis) against
  the restoring force, dissipative columns (odd in ``ẋ``) against the
  dissipative force (:data:`GROUPS`). The normalised coefficient
  ``ξ_i = c_i max|φ_i| / max|f_group|`` is the term's share of its group's
  force and each group has its own STLSQ threshold. A single share of the
  total force cannot work for resonance data: at phase resonance the
  dissipative force balances the excitation, ``2ζ`` of the restoring force
  (0.5–2 %), so viscous damping, structurally essential, ranks with the
  spurious terms and is dropped, while dissipative terms that are spurious
  can carry more of their group than true stiffness terms carry of theirs.
* **Candidates.** Each group's threshold is raised from ``min_threshold``
  (default 1e-3 of the group's force) to just above its weakest kept term,
  STLSQ restarting from the previous support, until the group is empty; the
  candidates are all combinations of the two groups' supports. Backward
  elimination (drop the term whose removal scores best) from the selected and
  from the best candidate adds the supports that thresholds cannot reach,
  where nearly collinear columns have their shares in the wrong order.
* **Selection.** ``"cv"`` (default): K-fold cross-validation of each
  candidate support, refitted on the training folds. Folds are dealt blocks of
  :data:`CV_BLOCK_PERIODS` periods from every record in turn, so each fold
  spans every excitation level; contiguous fifths of a stepped-level record
  would hold out whole levels, and the held-out error would measure
  extrapolation to amplitudes no training block has seen (on the trc-like rig
  records this made the two-term, undamped model "best"). The model is the
  candidate with the fewest terms within one standard error of the best
  (the one-standard-error rule). ``"bic"``: Bayesian information criterion
  with the effective number of independent samples ``2 · bandwidth ·
  duration`` (consecutive samples of a band-limited residual are not
  independent); it takes the residual for noise, so on noise-free simulations
  it keeps small terms that fit preprocessing error.
* **Admissibility.** A resonance test measures positive damping at every
  level (the shaker feeds power in). Only candidates whose single-harmonic
  backbone exists with positive damping over the tested amplitudes
  (:func:`admissible`) compete; a model without damping, or one whose damping
  turns negative at small amplitudes, cannot be run under a phase-locked loop
  however small its regression error.
* **Fast.** Regressions on any subset of columns only need the Gram matrix, so
  every time block is reduced once to the Gram matrix of its ``[Θ | y]``, and
  the threshold paths and cross-validation run on those small matrices.

Terms that data of this kind cannot tell apart are reported, not hidden:
``x²`` and ``ẋ²`` act only through the second harmonic, with a ratio ``−ω²``
that barely changes over a resonance test (|r| ≈ 0.99–0.9996 in the tests);
``x·|x|``, ``x³`` and ``x`` (or ``ẋ·|ẋ|``, ``ẋ³``, ``ẋ``, Coulomb) are separated
only by their harmonics and by how they scale with amplitude (|r| ≈ 0.96–0.97
between x·|x| and x³, and between ẋ·|ẋ| and ẋ³); ``tanh(x/x_s)`` and
``exp(x/x_s) − 1`` with ``x_s`` above the amplitudes are nearly polynomials
(|r| ≈ 0.98–0.99 with ``x``). :attr:`Identification.correlation` and
:attr:`Identification.condition_number` say how well, and a
:class:`CollinearityWarning` names pairs beyond ``|r| > 0.99``.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pysindy as ps
from numpy.typing import ArrayLike

from identification.analytical import harmonic, pll
from identification.effects import CATALOGUE, get_effect
from identification.measurements.signals import (
    Kinematics,
    amplitude_envelope,
    bandpass,
    kinematics,
    lowpass,
    unscale_coefficients,
)
from identification.model import JointModel, Term

__all__ = [
    "EQ3_SYMBOLS",
    "GROUPS",
    "PAPER_LIBRARY",
    "POLYNOMIAL_LIBRARY",
    "CollinearityWarning",
    "ErrorStatistics",
    "Identification",
    "LibraryTerm",
    "RankDeficientLibraryError",
    "ThresholdPath",
    "Validation",
    "admissible",
    "backbone_error",
    "comparison_table",
    "design_matrix",
    "identify",
    "identify_arrays",
    "mean_offset",
    "plot_validation",
    "record_kinematics",
    "validate",
]

#: The paper's library: polynomials up to cubic in (x, ẋ) and its joint terms
#: (every catalogue effect but the hysteretic ``microslip``).
PAPER_LIBRARY: tuple[str, ...] = tuple(name for name in CATALOGUE if name != "microslip")

#: Every monomial of degree 1 to 3 in (x, ẋ).
POLYNOMIAL_LIBRARY: tuple[str, ...] = (
    "linear_stiffness", "viscous_damping", "quadratic_stiffness", "stiffness_damping_coupling",
    "velocity_squared", "cubic_stiffness", "van_der_pol", "displacement_velocity_squared",
    "cubic_damping",
)  # fmt: skip

#: How each catalogue coefficient of the ``pandey2025`` preset reads in the paper's Eq. 3.
EQ3_SYMBOLS: dict[str, str] = {
    "linear_stiffness": "k1",
    "viscous_damping": "k2 + k11",
    "quadratic_stiffness": "−k3",
    "stiffness_damping_coupling": "−k4",
    "velocity_squared": "k5",
    "cubic_stiffness": "−k6",
    "displacement_velocity_squared": "−k7",
    "cubic_damping": "−k8",
    "abs_stiffness": "−k9",
    "quadratic_damping": "k10",
    "van_der_pol": "−k11·k12",
}

#: |r| between two library columns above which a :class:`CollinearityWarning` is given.
COLLINEARITY_WARNING = 0.99
#: The two groups of library columns, each thresholded against its own force.
GROUPS = ("conservative", "dissipative")
#: Length of the cross-validation blocks, in periods of the band's lower edge.
CV_BLOCK_PERIODS = 20
#: Smallest group force (fraction of max|y|) a group share is measured against.
GROUP_FLOOR = 1e-3
#: Condition number of the scaled library above which it counts as rank-deficient (the
#: Gram matrix resolves condition numbers up to about 1e8 in double precision).
RANK_DEFICIENT = 1e7


class CollinearityWarning(UserWarning):
    """Two library columns are so alike on the data that only their combination is identified."""


class RankDeficientLibraryError(ValueError):
    """Some library columns are linearly dependent on the data (the message names them)."""


# --------------------------------------------------------------------------- library


@dataclass(frozen=True)
class LibraryTerm:
    """One library column: a catalogue effect with fixed shape parameters."""

    effect: str
    shape: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        effect = get_effect(self.effect)
        values = effect.shape_values(**self.shape)  # validates names and values
        object.__setattr__(self, "shape", dict(zip(effect.shape, values, strict=False)))

    def feature(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """The column ``φ(x, v)`` along a path (the Jenkins force needs the whole path)."""
        return CATALOGUE[self.effect].feature(x, v, **self.shape)


def _library_grid(
    effects: Sequence[str], shapes: Mapping[str, Mapping[str, Any]] | None
) -> list[tuple[LibraryTerm, ...]]:
    """Every library of the shape-parameter grid (a scalar shape value is fixed)."""
    if isinstance(effects, str) or len(effects) == 0:
        raise ValueError(f"effects must be a non-empty list of catalogue names, got {effects!r}")
    for name in effects:
        get_effect(name)
    duplicates = sorted({n for n in effects if list(effects).count(n) > 1})
    if duplicates:
        raise ValueError(f"effect(s) {duplicates} appear more than once in the library")
    shapes = dict(shapes or {})
    stray = sorted(set(shapes) - set(effects))
    if stray:
        raise ValueError(f"shapes given for effect(s) {stray} that are not in the library")
    axes = []  # (effect, parameter, values)
    for name, params in shapes.items():
        for param, values in params.items():
            values = np.atleast_1d(np.asarray(values, dtype=float))
            if values.ndim != 1 or values.size == 0:
                raise ValueError(f"shape {name}.{param} must be a number or a 1-D list of numbers")
            axes.append((name, param, values))
    grid = []
    for combination in itertools.product(*(values for _, _, values in axes)):
        chosen: dict[str, dict[str, float]] = {}
        for (name, param, _), value in zip(axes, combination, strict=True):
            chosen.setdefault(name, {})[param] = float(value)
        grid.append(tuple(LibraryTerm(name, chosen.get(name, {})) for name in effects))
    return grid


def design_matrix(
    kin: Kinematics, terms: Sequence[LibraryTerm], offset: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Library columns and target of one record, band-passed like the data.

    Parameters
    ----------
    kin
        Band-limited kinematics of the record
        (:func:`~identification.measurements.signals.kinematics`).
    terms
        Library columns.
    offset
        Slow mean of the displacement to add back (:func:`mean_offset`), or None.

    Returns
    -------
    theta, y
        ``(n_valid, n_terms)`` columns and ``(n_valid,)`` absolute acceleration
        ``ẍ + a_base`` (m/s²) over the valid samples.
    """
    rows = _design_rows(kin, terms, offset)
    return rows[:-1].T, rows[-1]


def _design_rows(kin: Kinematics, terms: Sequence[LibraryTerm], offset: np.ndarray | None):
    """``(n_terms + 1, n_valid)``: the columns of :func:`design_matrix` as rows, then y."""
    x = kin.displacement if offset is None else kin.displacement + offset
    rows = np.empty((len(terms) + 1, x.size))
    for i, term in enumerate(terms):
        rows[i] = term.feature(x, kin.velocity)
    # Rows are contiguous in memory, so filtering along the last axis is the fast way.
    rows[:-1] = bandpass(rows[:-1], kin.sampling_rate_hz, kin.band_hz, axis=-1)
    rows[-1] = kin.absolute_acceleration
    return rows[:, kin.valid]


def mean_offset(model: JointModel, kin: Kinematics, iterations: int = 3) -> np.ndarray:
    """Slow mean of the displacement implied by the model's quasi-static balance.

    The band-limited displacement ``x'`` has no slow part, but the true one is
    ``x' + m(t)`` with ``m`` such that the slow part of the restoring force
    vanishes: ``slow(f(x' + m, ẋ)) = 0``. Solved by the fixed point
    ``m ← m − slow(f(x' + m, ẋ)) / k_lin``, with "slow" a low-pass at a quarter
    of the band's lower edge (far below the fundamental).
    """
    k = model.linear_stiffness
    if k <= 0:
        raise ValueError(f"model has no positive linear stiffness (k = {k}); no offset defined")
    cutoff = kin.band_hz[0] / 4
    offset = np.zeros_like(kin.displacement)
    for _ in range(iterations):
        force = model.restoring_force(kin.displacement + offset, kin.velocity)
        offset = offset - lowpass(force, kin.sampling_rate_hz, cutoff) / k
    return offset


# --------------------------------------------------------------------------- regression
#
# Any least-squares fit on a subset of the columns of [Θ | y] needs only the Gram
# matrix G = [Θ | y]ᵀ[Θ | y] (size n_terms + 1): a square R with RᵀR = G gives
# the same solutions and residuals as the rows themselves. Every time block is
# reduced to its Gram once (one BLAS product), and the threshold paths, the
# cross-validation and STLSQ run on these small matrices.


@dataclass(frozen=True, eq=False)
class ThresholdPath:
    """Candidate models along the two STLSQ threshold paths, and their scores.

    Conservative and dissipative columns each have their own threshold
    (:data:`GROUPS`, shares of the group's force); the candidates are the
    combinations of the distinct supports found along both paths.

    Attributes
    ----------
    thresholds
        ``(n, 2)`` conservative and dissipative threshold of each candidate
        (NaN for a group the library lacks).
    n_terms
        Terms each candidate keeps.
    score
        Held-out mean squared error (``"cv"``, scaled units) or BIC (``"bic"``).
    score_se
        Standard error of the held-out error across folds (``"cv"``), else None.
    criterion
        ``"cv"`` or ``"bic"``.
    admissible
        Whether the candidate has a backbone with positive damping over the
        tested amplitudes (:func:`admissible`).
    chosen
        Index of the selected candidate.
    pruned
        Terms of the selected candidate that the model does not keep: backward
        elimination (from it and from the best-scoring candidate) removed them
        within the same score limit.
    """

    thresholds: np.ndarray
    n_terms: np.ndarray
    score: np.ndarray
    score_se: np.ndarray | None
    criterion: str
    admissible: np.ndarray
    chosen: int
    pruned: tuple[str, ...]


def _factor(gram: np.ndarray) -> np.ndarray:
    """Square ``R`` with ``RᵀR = gram`` (Cholesky; eigen-decomposition if semi-definite)."""
    try:
        return np.linalg.cholesky(gram).T
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(gram)
        return np.sqrt(np.clip(values, 0.0, None))[:, None] * vectors.T


def _rss(gram: np.ndarray, xi: np.ndarray) -> float:
    """Residual sum of squares of ``y − Θ ξ`` from the augmented Gram."""
    z = np.append(-xi, 1.0)
    return float(z @ gram @ z)


def _least_squares(factor: np.ndarray, support: np.ndarray | None = None) -> np.ndarray:
    """Least-squares coefficients on the columns in ``support`` (all by default), 0 elsewhere."""
    xi = np.zeros(factor.shape[1] - 1)
    columns = np.arange(xi.size) if support is None else np.flatnonzero(support)
    if columns.size:
        xi[columns] = np.linalg.lstsq(factor[:, columns], factor[:, -1], rcond=None)[0]
    return xi


def _stlsq_optimizer(a: np.ndarray, thresholds: np.ndarray) -> tuple[ps.STLSQ, np.ndarray]:
    """pysindy's STLSQ for one threshold per column, and the column factors it needs.

    STLSQ takes one threshold: columns multiplied by ``ratio`` (their threshold
    over the largest) have coefficients divided by it, so the largest
    threshold on the scaled coefficients is each column's own threshold.
    """
    top = float(np.max(thresholds))
    ratio = thresholds / top if top > 0 else np.ones_like(thresholds)
    scaled = a * ratio
    # Negligible ridge; pysindy's unbias step refits the support without it.
    return ps.STLSQ(threshold=top, alpha=1e-12 * np.sum(scaled * scaled), max_iter=50), ratio


@contextmanager
def _quiet_stlsq() -> Iterator[None]:
    with warnings.catch_warnings():
        # All terms below the threshold is a legitimate end of a path.
        warnings.filterwarnings("ignore", message="Sparsity parameter is too big")
        yield


def _stlsq(
    factor: np.ndarray, thresholds: np.ndarray, columns: np.ndarray | None = None
) -> np.ndarray:
    """Sequentially thresholded least squares (pysindy) on a Gram factor.

    ``thresholds`` has one entry per column; only ``columns`` (a mask, all by
    default) take part, the others get 0.
    """
    columns = np.ones(factor.shape[1] - 1, dtype=bool) if columns is None else columns
    a, b = factor[:, :-1][:, columns], factor[:, -1]
    optimizer, ratio = _stlsq_optimizer(a, thresholds[columns])
    with _quiet_stlsq():
        optimizer.fit(a * ratio, b)
    xi = np.zeros(columns.size)
    xi[columns] = optimizer.coef_[0] * ratio
    return xi


def _group_paths(
    factor: np.ndarray, dissipative: np.ndarray, min_threshold: float
) -> list[list[tuple[float, np.ndarray]]]:
    """Per group (:data:`GROUPS`), the nested supports along its STLSQ threshold path.

    The group's threshold starts at ``min_threshold`` and is raised each time
    to just above the smallest coefficient the group keeps, until it keeps
    none, while the other group's stays at ``min_threshold``. Each STLSQ
    starts from the previous support, so every step drops the weakest term
    (and any that fall below the threshold with it): sequential thresholding
    itself, one fit per support. Restarting from the whole library instead,
    or sweeping a fixed grid, steps over supports whose coefficients lie
    close together. Returns ``(threshold, support within the group)`` pairs
    with the threshold the geometric mean of the range giving that support,
    ascending; a group the library lacks gives one pair ``(nan, no column)``.
    """
    paths = []
    for members in (~dissipative, dissipative):
        if not members.any():
            paths.append([(math.nan, members)])
            continue
        steps: list[tuple[float, np.ndarray]] = []
        lam, active = min_threshold, np.ones_like(members)
        while True:
            xi = _stlsq(factor, np.where(members, lam, min_threshold), active)
            support = (xi != 0) & members
            if steps and np.array_equal(support, steps[-1][1]):
                # STLSQ's unbiased refit can leave a kept coefficient just below the
                # threshold; step on geometrically then.
                lam *= 1.05
                continue
            steps.append((lam, support))
            if not support.any():
                break
            active = support | ~members
            lam = max(lam, float(np.abs(xi[support]).min())) * (1 + 1e-6)
        bounds = [lam for lam, _ in steps[1:]] + [steps[-1][0]]
        paths.append([(math.sqrt(low * high), support)
                      for (low, support), high in zip(steps, bounds, strict=True)])  # fmt: skip
    return paths


def _cross_validation(
    fold_grams: Sequence[np.ndarray], sizes: Sequence[int], supports: Sequence[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error of the held-out mean squared error of each support.

    Each candidate support is refitted by least squares on the training folds
    (STLSQ's own last step) and scored on the held-out one.
    """
    errors = np.empty((len(supports), len(fold_grams)))
    for k, (held_out, size) in enumerate(zip(fold_grams, sizes, strict=True)):
        train = _factor(sum(g for j, g in enumerate(fold_grams) if j != k))
        for i, support in enumerate(supports):
            errors[i, k] = _rss(held_out, _least_squares(train, support)) / size
    return errors.mean(axis=1), errors.std(axis=1, ddof=1) / math.sqrt(len(fold_grams))


@dataclass(frozen=True, eq=False)
class _Design:
    """Scaled Gram matrices of one design, one per cross-validation fold (internal)."""

    fold_grams: list[np.ndarray]  # augmented [Θ | y], columns divided by `scale`
    sizes: np.ndarray  # rows per fold
    scale: np.ndarray  # per column, max|φ_i| · max|y| / max|group force|; then max|y|
    dissipative: np.ndarray  # per column, whether it is in the dissipative group
    tss: float  # total sum of squares of y (SI)
    rows: Sequence[np.ndarray]  # per record, unscaled, for bagging

    @property
    def gram(self) -> np.ndarray:
        return sum(self.fold_grams)

    @property
    def n_rows(self) -> int:
        return int(self.sizes.sum())

    def thresholds(self, pair: np.ndarray) -> np.ndarray:
        """Per-column thresholds from a (conservative, dissipative) pair."""
        return np.where(self.dissipative, pair[1], pair[0])


def _design(
    kins: Sequence[Kinematics],
    terms: Sequence[LibraryTerm],
    offsets: Sequence[np.ndarray | None],
    n_folds: int,
) -> _Design:
    """Band-passed library of every record, reduced to per-fold Gram matrices.

    Every record is cut into blocks of :data:`CV_BLOCK_PERIODS` periods of its
    band's lower edge, dealt to the folds in turn, so that every fold spans the
    whole test (all excitation levels) and the held-out error measures
    interpolation, not extrapolation to levels no training block has seen.
    Columns are scaled to group shares (:func:`_group_force`).
    """
    rows = [_design_rows(k, terms, o) for k, o in zip(kins, offsets, strict=True)]
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
    dissipative = np.array([_is_dissipative(t) for t in terms])
    scale = peak.copy()
    scale[:-1] /= _group_force(sum(fold_grams) / np.outer(peak, peak), rows, peak, dissipative)
    y_sum = sum(float(np.sum(r[-1])) for r in rows)
    y_squares = sum(float(r[-1] @ r[-1]) for r in rows)
    return _Design(
        fold_grams=[g / np.outer(scale, scale) for g in fold_grams],
        sizes=sizes,
        scale=scale,
        dissipative=dissipative,
        tss=y_squares - y_sum**2 / sizes.sum(),
        rows=rows,
    )


def _is_dissipative(term: LibraryTerm) -> bool:
    """Whether a column is odd in the velocity, ``φ(x, −ẋ) = −φ(x, ẋ)`` (damping-like).

    Such terms reverse with the motion and take energy out; the others (even
    in ``ẋ``, and the Jenkins element: a stiffness with hysteresis, whose
    force follows the displacement path) store it. Checked numerically at
    points covering every sign combination of ``x`` and ``ẋ``.
    """
    x = np.linspace(-1e-3, 1e-3, 41)
    v = 0.2 * np.cos(np.linspace(0.0, 9.0, 41))
    return bool(np.allclose(term.feature(x, -v), -term.feature(x, v), rtol=1e-9, atol=0))


def _group_force(
    gram: np.ndarray, rows: Sequence[np.ndarray], peak: np.ndarray, dissipative: np.ndarray
) -> np.ndarray:
    """Per column, the peak force of its group over the peak of ``y``.

    The group forces are those of a least-squares fit on the whole library
    (``gram`` of the columns divided by ``peak``). Conservative and
    dissipative forces are nearly orthogonal on a resonance record (even and
    odd under time reversal), so each group's sum is well determined even
    where single coefficients are not. At phase resonance the dissipative
    force balances the excitation, one or two percent of the restoring
    force; measured against its own group, a damping term's share is of
    order one. A group weaker than :data:`GROUP_FLOOR` of ``max|y|`` is
    measured against that floor.
    """
    xi = _least_squares(_factor(gram))
    force = np.empty(dissipative.size)
    for members in (~dissipative, dissipative):
        if members.any():
            weights = xi[members] / peak[:-1][members]
            top = max(float(np.max(np.abs(weights @ r[:-1][members]))) for r in rows)
            force[members] = max(top, GROUP_FLOOR)
    return force


@dataclass(frozen=True, eq=False)
class _Fit:
    """One regression of a design (internal)."""

    design: _Design
    xi: np.ndarray  # normalised coefficients (group shares) of y on Θ
    threshold: np.ndarray  # (conservative, dissipative)
    path: ThresholdPath | None
    held_out: float  # cross-validated mean squared error of the support (scaled units)
    rss: float  # SI, (m/s²)²

    @property
    def coefficients(self) -> np.ndarray:
        """SI coefficients in the model convention (``c_i = −w_i``)."""
        return _unscaled(self.xi, self.design)

    @property
    def support(self) -> np.ndarray:
        return self.xi != 0


def _unscaled(xi: np.ndarray, design: _Design) -> np.ndarray:
    """SI coefficients in the model convention (``c_i = −w_i``) of normalised ones."""
    return -unscale_coefficients(xi, design.scale[:-1], design.scale[-1])


def _regress(
    design: _Design,
    terms: Sequence[LibraryTerm],
    threshold: float | Sequence[float] | str | None,
    n_effective: float,
    min_threshold: float,
    amplitudes_m: np.ndarray,
) -> _Fit:
    """STLSQ with the thresholds chosen as asked."""
    gram = design.gram
    _check_rank(gram, [t.effect for t in terms])
    factor = _factor(gram)
    path = None
    if threshold is None:
        pair = np.zeros(2)
        xi = _least_squares(factor)
    elif isinstance(threshold, str):
        if threshold not in ("cv", "bic"):
            raise ValueError(
                "threshold must be a number, a (conservative, dissipative) pair, 'cv', 'bic' or "
                f"None, got {threshold!r}"
            )
        paths = _group_paths(factor, design.dissipative, min_threshold)
        candidates = [(np.array([tc, td]), sc | sd)
                      for (tc, sc), (td, sd) in itertools.product(*paths)]  # fmt: skip
        pairs = np.array([pair for pair, _ in candidates])
        supports = [support for _, support in candidates]
        score, se, fits = _scores(design, supports, threshold, n_effective)
        n_terms = np.array([np.count_nonzero(support) for support in supports])
        admissible_ = np.array([admissible(_model(terms, _unscaled(xi, design)), amplitudes_m)
                                for xi in fits])  # fmt: skip
        chosen, best, limit = _select(score, se, n_terms, admissible_)

        def acceptable(xi: np.ndarray) -> bool:
            model = _model(terms, _unscaled(xi, design))
            return not admissible_.any() or admissible(model, amplitudes_m)

        # Backward elimination from the selected and from the best candidate; the
        # sparser end (then the better scoring) is the model.
        ends = [_prune(design, fits[i], score[i], limit, threshold, n_effective, acceptable)
                for i in dict.fromkeys((chosen, best))]  # fmt: skip
        xi = min(ends, key=lambda end: (np.count_nonzero(end[0]), end[1]))[0]
        pruned = tuple(t.effect for t, a, b in zip(terms, fits[chosen], xi, strict=True)
                       if a and not b)  # fmt: skip
        path = ThresholdPath(pairs, n_terms, score, se if threshold == "cv" else None,
                             threshold, admissible_, chosen, pruned)  # fmt: skip
        pair = pairs[chosen]
    else:
        pair = _threshold_pair(threshold)
        xi = _stlsq(factor, design.thresholds(pair)) if pair.any() else _least_squares(factor)
    return _fit(design, xi, pair, path)


def _threshold_pair(threshold: float | Sequence[float]) -> np.ndarray:
    """A fixed threshold as a (conservative, dissipative) pair; ValueError if invalid."""
    try:
        pair = np.broadcast_to(np.asarray(threshold, dtype=float), (2,)).copy()
    except (TypeError, ValueError):
        raise ValueError(
            "threshold must be a number, a (conservative, dissipative) pair, 'cv', 'bic' or "
            f"None, got {threshold!r}"
        ) from None
    if not (np.all(np.isfinite(pair)) and (np.all(pair > 0) or np.all(pair == 0))):
        raise ValueError(f"fixed thresholds must be finite and > 0 (or both 0), got {threshold}")
    return pair


def _fit(design: _Design, xi: np.ndarray, pair: np.ndarray, path: ThresholdPath | None) -> _Fit:
    """A :class:`_Fit` with the cross-validated error of its support."""
    held_out = float(_cross_validation(design.fold_grams, design.sizes, [xi != 0])[0][0])
    return _Fit(design, xi, pair, path, held_out, _rss(design.gram, xi) * design.scale[-1] ** 2)


def _refit(design: _Design, fit: _Fit) -> _Fit:
    """Least squares on a new design with the support (and thresholds) of an earlier fit."""
    return _fit(design, _least_squares(_factor(design.gram), fit.support), fit.threshold, None)


def _scores(
    design: _Design, supports: Sequence[np.ndarray], criterion: str, n_effective: float
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Score, its standard error (0 for BIC) and least-squares fit of each candidate support."""
    factor = _factor(design.gram)
    fits = [_least_squares(factor, support) for support in supports]
    if criterion == "cv":
        score, se = _cross_validation(design.fold_grams, design.sizes, supports)
        return score, se, fits
    rss = np.array([_rss(design.gram, xi) for xi in fits])
    n_terms = np.array([np.count_nonzero(support) for support in supports])
    score = n_effective * np.log(rss / design.n_rows) + n_terms * np.log(n_effective)
    return score, np.zeros_like(score), fits


def _select(
    score: np.ndarray, se: np.ndarray, n_terms: np.ndarray, admissible_: np.ndarray
) -> tuple[int, int, float]:
    """The one-standard-error rule among the admissible candidates.

    Returns the candidate with the fewest terms scoring within one standard
    error of the best admissible one (ties go to the lower score), that best
    one, and the limit on the score. Without any admissible candidate the
    rule runs on all of them, with a warning.
    """
    if not admissible_.any():
        warnings.warn(
            "no candidate model has positive damping over the tested amplitudes; the selected "
            "model is not physically admissible (is the library missing a damping term?)",
            stacklevel=6,
        )
    candidates = np.flatnonzero(admissible_) if admissible_.any() else np.arange(score.size)
    best = int(candidates[np.argmin(score[candidates])])
    limit = float(score[best] + se[best] + 1e-12 * abs(score[best]))
    qualified = candidates[score[candidates] <= limit]
    return int(min(qualified, key=lambda i: (n_terms[i], score[i]))), best, limit


def _prune(
    design: _Design,
    xi: np.ndarray,
    score: float,
    limit: float,
    criterion: str,
    n_effective: float,
    acceptable: Callable[[np.ndarray], bool],
) -> tuple[np.ndarray, float]:
    """Backward elimination: drop terms one at a time while the score stays within ``limit``.

    Thresholds order terms by their share, which misorders nearly collinear
    columns: on ``pandey2025`` records ``exp(x/x_s) − 1`` (spurious, a mix of
    x, x², x³ and higher powers) carries 0.78 % of the conservative force and
    the true x³ 0.77 %, so no threshold drops the one and keeps the other.
    Each step tries the removal of every term and makes the best-scoring
    one, if it stays within the limit and the model stays ``acceptable``.
    Returns the last model and its score.
    """
    while np.count_nonzero(xi) > 1:
        trials = [(xi != 0) & (np.arange(xi.size) != i) for i in np.flatnonzero(xi)]
        scores, _, fits = _scores(design, trials, criterion, n_effective)
        accepted = next((j for j in np.argsort(scores)
                         if scores[j] <= limit and acceptable(fits[j])), None)  # fmt: skip
        if accepted is None:
            break
        xi, score = fits[accepted], float(scores[accepted])
    return xi, score


def admissible(model: JointModel, amplitudes_m: ArrayLike) -> bool:
    """Whether ``model`` has a phase-resonant backbone with positive damping at every amplitude.

    A resonance test measures positive damping at every level (the shaker
    feeds power in), so a model without damping, or whose damping turns
    negative inside the tested range, contradicts the data, however small its
    regression error, and a phase-locked loop cannot run it there.
    Single-harmonic balance (:func:`identification.analytical.harmonic.backbone`).
    """
    if not model.terms:
        return False
    result = harmonic.backbone(model, amplitudes_m)
    return bool(np.all(result.converged) and np.all(result.damping_ratio > 0))


def _check_rank(gram: np.ndarray, names: Sequence[str]) -> None:
    """ValueError naming the columns when the library is numerically rank-deficient."""
    values, vectors = np.linalg.eigh(_unit_columns(gram))
    singular = np.sqrt(np.clip(values, 0.0, None))  # ascending
    if singular[0] > singular[-1] / RANK_DEFICIENT:
        return
    null = np.abs(vectors[:, 0])
    involved = [names[i] for i in np.flatnonzero(null > 0.1 * null.max())]
    condition = singular[-1] / singular[0] if singular[0] > 0 else math.inf
    raise RankDeficientLibraryError(
        f"the library is rank-deficient on these records: columns {involved} are linearly "
        f"dependent (condition number {condition:.3g}); drop all but one of them"
    )


def _unit_columns(gram: np.ndarray) -> np.ndarray:
    """Gram of the library columns scaled to unit norm: their correlation matrix.

    The columns are band-passed, hence zero-mean, so the cosine of the angle
    between two columns is their Pearson correlation. Unit columns make the
    condition number independent of how the columns were scaled for the thresholds.
    """
    g = gram[:-1, :-1]
    norms = np.sqrt(np.diag(g))
    return g / np.outer(norms, norms)


def _correlation(gram: np.ndarray) -> tuple[np.ndarray, float]:
    """Column correlations and condition number of the library (unit columns)."""
    correlation = _unit_columns(gram)
    values = np.clip(np.linalg.eigvalsh(correlation), 0.0, None)
    return correlation, float(np.sqrt(values[-1] / values[0]))


# --------------------------------------------------------------------------- report


@dataclass(frozen=True, eq=False)
class Identification:
    """Result of :func:`identify`: the model and how it was found.

    Attributes
    ----------
    model
        Identified :class:`~identification.model.JointModel` (SI units).
    library
        The library columns, with the shape parameters chosen.
    coefficients
        SI coefficient of every library term in the model convention
        (``ẍ + Σ c_i φ_i = −a_base``), 0 where the term was dropped.
    normalised_coefficients
        Group share ``c_i max|φ_i| / max|f_group|`` (signed): the term's peak
        over the peak force of its group (``groups``), the scale the threshold
        applies to.
    groups
        ``"conservative"`` or ``"dissipative"`` per library term (:data:`GROUPS`).
    threshold
        The STLSQ thresholds used, (conservative, dissipative) group shares
        (NaN for a group the library lacks).
    threshold_method
        ``"cv"``, ``"bic"``, ``"fixed"`` or ``"none"`` (plain least squares).
    path
        Candidates along the threshold paths and their scores (``"cv"``,
        ``"bic"``), else None.
    r2
        Coefficient of determination of ``ẍ + a_base`` over the regression samples.
    residual_rms
        RMS of the regression residual (m/s²).
    held_out_rms
        RMS of the cross-validated (held-out time blocks) residual (m/s²).
    condition_number
        Of the scaled library matrix.
    correlation
        ``(n_terms, n_terms)`` correlations between the library columns.
    peak_contribution
        Per kept term, ``max|c_i φ_i| / max|Σ c_j φ_j|`` over the data.
    inclusion_probability, ensemble_coefficients
        With ``ensemble=True``: share of bagged models that keep each term,
        and their median coefficients (SI); else None.
    offset_iterations
        Mean-offset reconstructions of the kept fit (0: none).
    band_hz
        Pass band of each record.
    n_samples
        Regression rows (all records).
    """

    model: JointModel
    library: tuple[LibraryTerm, ...]
    coefficients: dict[str, float]
    normalised_coefficients: dict[str, float]
    groups: dict[str, str]
    threshold: tuple[float, float]
    threshold_method: str
    path: ThresholdPath | None
    r2: float
    residual_rms: float
    held_out_rms: float
    condition_number: float
    correlation: np.ndarray
    peak_contribution: dict[str, float]
    inclusion_probability: dict[str, float] | None
    ensemble_coefficients: dict[str, float] | None
    offset_iterations: int
    band_hz: tuple[tuple[float, float], ...]
    n_samples: int

    @property
    def effects(self) -> list[str]:
        """Library effect names in library order."""
        return [term.effect for term in self.library]

    def collinear_pairs(self, limit: float = 0.95) -> list[tuple[str, str, float]]:
        """Pairs of library columns with ``|r| > limit``, most collinear first."""
        names = self.effects
        pairs = [(names[i], names[j], float(self.correlation[i, j]))
                 for i, j in itertools.combinations(range(len(names)), 2)
                 if abs(self.correlation[i, j]) > limit]  # fmt: skip
        return sorted(pairs, key=lambda p: -abs(p[2]))

    def summary(self) -> str:
        """Plain-text report: coefficients, shares, inclusion, fit quality, collinearity."""
        lines = [
            f"SINDy identification: {self.n_samples} samples, thresholds "
            f"{self.threshold[0]:.3g} (conservative) / {self.threshold[1]:.3g} (dissipative) "
            f"({self.threshold_method}), R² = {self.r2:.6f}, residual RMS "
            f"{self.residual_rms:.4g} m/s² (held out {self.held_out_rms:.4g}), condition number "
            f"{self.condition_number:.3g}",
            f"{'effect':<30}{'group':>13}{'coefficient':>13}{'ξ':>11}{'peak share':>12}"
            f"{'P(incl.)':>10}",
        ]
        for name in self.effects:
            share = self.peak_contribution.get(name)
            incl = None if self.inclusion_probability is None else self.inclusion_probability[name]
            lines.append(
                f"{name:<30}{self.groups[name]:>13}{self.coefficients[name]:>13.4g}"
                f"{self.normalised_coefficients[name]:>11.2e}"
                f"{'' if share is None else f'{share:.2%}':>12}"
                f"{'' if incl is None else f'{incl:.2f}':>10}"
            )
        pairs = self.collinear_pairs()
        if pairs:
            lines.append("nearly collinear columns (|r| > 0.95): " + ", ".join(
                f"{a} ~ {b} (r = {r:+.4f})" for a, b, r in pairs))  # fmt: skip
        lines.append(self.model.equation())
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.summary()


def comparison_table(
    identification: Identification,
    reference: JointModel,
    labels: Mapping[str, str] | None = None,
) -> str:
    """Identified coefficients beside a reference model's (e.g. the paper's Eq. 3).

    One row per effect of the library or the reference: its label (``labels``,
    e.g. :data:`EQ3_SYMBOLS`), reference and identified coefficients (model
    convention, SI) and the relative error ("spurious" for a term the
    reference does not have).
    """
    labels = labels or {}
    names = list(dict.fromkeys([*identification.effects, *reference.effects]))
    lines = [f"{'effect':<30}{'symbol':>10}{'reference':>13}{'identified':>13}{'error':>9}"]
    for name in names:
        ref = reference.coefficient(name)
        got = identification.coefficients.get(name, 0.0)
        error = f"{got / ref - 1:+.1%}" if ref else ("" if got == 0 else "spurious")
        lines.append(f"{name:<30}{labels.get(name, ''):>10}{ref:>13.4g}{got:>13.4g}{error:>9}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- entry points


def record_kinematics(record: Any, **options: Any) -> Kinematics:
    """Band-limited kinematics of a :class:`~identification.measurements.records.Record`."""
    return kinematics(record.time_s, record.response_velocity, record.excitation_velocity,
                      record.frequency_hz, record.sampling_rate_hz, **options)  # fmt: skip


def identify(records: Any, effects: Sequence[str], **options: Any) -> Identification:
    """Identify a joint model from test records (:class:`~.measurements.records.Record`).

    ``records`` is one record or a sequence of them, fitted jointly; all must
    share one sampling rate. ``options`` are those of :func:`identify_arrays`.
    """
    records = [records] if hasattr(records, "response_velocity") else list(records)
    if not records:
        raise ValueError("no records given")
    return identify_arrays(
        [r.time_s for r in records],
        [r.response_velocity for r in records],
        [r.excitation_velocity for r in records],
        [r.frequency_hz for r in records],
        effects,
        labels=[str(r.path or r.name) for r in records],
        **options,
    )


def identify_arrays(
    t: ArrayLike | Sequence[ArrayLike],
    response_velocity: ArrayLike | Sequence[ArrayLike],
    base_velocity: ArrayLike | Sequence[ArrayLike],
    frequency_hz: ArrayLike | Sequence[ArrayLike],
    effects: Sequence[str],
    *,
    shapes: Mapping[str, Mapping[str, float | Sequence[float]]] | None = None,
    threshold: float | Sequence[float] | str | None = "cv",
    ensemble: bool = False,
    n_models: int = 20,
    seed: int = 0,
    n_folds: int = 5,
    min_threshold: float = 1e-3,
    offset_iterations: int = 3,
    n_harmonics: int = 3,
    edge_periods: float = 20.0,
    labels: Sequence[str] | None = None,
) -> Identification:
    """Identify a joint model from velocity arrays of one or several records.

    Each data argument is one 1-D array, or a list with one array per record
    (as in pysindy's multiple trajectories); records are fitted jointly.

    Parameters
    ----------
    t
        Sample times (s), uniformly sampled, one rate for all records.
    response_velocity
        Response-point velocity relative to the base (m/s).
    base_velocity
        Base (excitation) velocity (m/s).
    frequency_hz
        Instantaneous excitation frequency (Hz); sets the pass band.
    effects
        Catalogue names of the library columns (e.g. :data:`PAPER_LIBRARY`).
    shapes
        Shape parameters per effect, ``{"tanh_saturation": {"x_s": 5e-4}}``; a
        list of values is scanned and the best-scoring combination kept
        (``{"microslip": {"k_t": [...], "F_s": [...]}}`` scans a grid).
    threshold
        ``"cv"``, ``"bic"`` (see the module notes), a fixed group-share
        threshold (one for both groups, or a ``(conservative, dissipative)``
        pair), or None for plain least squares on the whole library.
    ensemble
        Also bag ``n_models`` STLSQ fits (``pysindy.EnsembleOptimizer``, time
        samples drawn with replacement, ``seed``) at the chosen thresholds and
        report per-term inclusion probabilities. Consecutive samples are
        correlated, so these probabilities are optimistic; the backward
        elimination after the threshold paths is not repeated per bag.
    n_folds
        Cross-validation folds; each takes every ``n_folds``-th block of
        :data:`CV_BLOCK_PERIODS` periods of every record.
    min_threshold
        Lowest threshold tried (a group share).
    offset_iterations
        Mean-offset reconstructions (:func:`mean_offset`) after the first fit; 0 disables.
    n_harmonics, edge_periods
        Preprocessing (:func:`~identification.measurements.signals.kinematics`).
    labels
        Names of the records for error messages (file paths).

    Returns
    -------
    Identification

    Raises
    ------
    ValueError
        Unknown effect or shape, records with different sampling rates or
        non-uniform sampling, records too short, or a rank-deficient library
        (naming the dependent columns).
    """
    channels = [_as_list(c) for c in (t, response_velocity, base_velocity, frequency_hz)]
    n_records = len(channels[0])
    if any(len(c) != n_records for c in channels):
        raise ValueError(
            "t, response_velocity, base_velocity and frequency_hz must hold the same number "
            f"of records, got {[len(c) for c in channels]}"
        )
    labels = list(labels) if labels is not None else [f"record {i}" for i in range(n_records)]
    grid = _library_grid(effects, shapes)
    if n_folds < 2:
        raise ValueError(f"n_folds must be >= 2, got {n_folds}")
    if not (math.isfinite(min_threshold) and 0 < min_threshold < 1):
        raise ValueError(f"min_threshold must be in (0, 1), got {min_threshold}")
    rates = [_sampling_rate(np.asarray(ti, dtype=float), label)
             for ti, label in zip(channels[0], labels, strict=True)]  # fmt: skip
    if max(rates) - min(rates) > 1e-6 * max(rates):
        listing = ", ".join(
            f"{label}: {rate:.6g} Hz" for label, rate in zip(labels, rates, strict=True)
        )
        raise ValueError(f"records have different sampling rates ({listing}); resample first")
    kins = []
    for (ti, vi, bi, fi), rate, label in zip(zip(*channels, strict=True), rates, labels,
                                             strict=True):  # fmt: skip
        try:
            kins.append(kinematics(ti, vi, bi, fi, rate, n_harmonics=n_harmonics,
                                   edge_periods=edge_periods))  # fmt: skip
        except ValueError as exc:
            raise ValueError(f"{label}: {exc}") from None
    n_effective = sum(2 * (k.band_hz[1] - k.band_hz[0]) * (k.valid.stop - k.valid.start)
                      / k.sampling_rate_hz for k in kins)  # fmt: skip
    amplitudes_m = _tested_amplitudes(kins)
    selection = dict(threshold=threshold, n_effective=n_effective, min_threshold=min_threshold,
                     amplitudes_m=amplitudes_m)  # fmt: skip
    best, refused = None, []
    for terms in grid:
        try:
            candidate = _fit_with_offsets(kins, terms, selection, n_folds, offset_iterations)
        except RankDeficientLibraryError as exc:
            if len(grid) == 1:
                raise
            refused.append(f"{_shape_text(terms)} ({exc})")
            continue
        # An admissible model beats any inadmissible one, then the held-out error decides.
        rank = (not admissible(_model(terms, candidate[1].coefficients), amplitudes_m),
                candidate[1].held_out)  # fmt: skip
        if best is None or rank < best[0]:
            best = (rank, candidate)
    if best is None:
        raise RankDeficientLibraryError("every shape of the grid gives a rank-deficient library: "
                                        + "; ".join(refused))  # fmt: skip
    if refused:
        warnings.warn("shape grid points skipped: " + "; ".join(refused), stacklevel=2)
    terms, fit, offsets, iterations = best[1]
    return _report(kins, terms, fit, offsets, iterations, threshold, ensemble, n_models, seed)


def _tested_amplitudes(kins: Sequence[Kinematics], n: int = 16) -> np.ndarray:
    """Amplitudes (m) spanning the records: 2nd percentile to largest of the envelope.

    The low percentile leaves out the start-up from rest, where no level is held.
    """
    envelope = np.concatenate(
        [amplitude_envelope(k.displacement, k.sampling_rate_hz, k.band_hz[0] / 4)[k.valid]
         for k in kins]
    )  # fmt: skip
    return np.geomspace(np.percentile(envelope, 2), envelope.max(), n)


def _shape_text(terms: Sequence[LibraryTerm]) -> str:
    return ", ".join(f"{t.effect}.{k}={v:g}" for t in terms for k, v in t.shape.items()
                     if k != "v_reg") or "default shapes"  # fmt: skip


def _as_list(values: Any) -> list[np.ndarray]:
    if isinstance(values, np.ndarray) and values.ndim == 1:
        return [values]
    values = list(values)
    if values and np.ndim(values[0]) == 0:  # one record given as a plain list of numbers
        return [np.asarray(values, dtype=float)]
    return [np.asarray(v, dtype=float) for v in values]


def _sampling_rate(t: np.ndarray, label: str) -> float:
    if t.ndim != 1 or t.size < 3:
        raise ValueError(f"{label}: t must be 1-D with at least 3 samples")
    steps = np.diff(t)
    rate = (t.size - 1) / (t[-1] - t[0])
    if not np.all(np.isfinite(steps)) or np.any(np.abs(steps * rate - 1) > 1e-3):
        raise ValueError(f"{label}: t is not uniformly sampled (steps {steps.min():.6g} to "
                         f"{steps.max():.6g} s)")  # fmt: skip
    return float(rate)


def _fit_with_offsets(
    kins: Sequence[Kinematics],
    terms: tuple[LibraryTerm, ...],
    selection: dict[str, Any],
    n_folds: int,
    offset_iterations: int,
) -> tuple[tuple[LibraryTerm, ...], _Fit, list[np.ndarray | None], int]:
    """Fit, then refit with the mean offset each fit implies; keep the best iterate.

    The support is chosen on the first fit and held while the offset is
    iterated, and chosen again on the kept design. Iterates are compared by
    their cross-validated error: the in-sample residual would favour spurious
    terms that mimic the missing offset. The iteration stops early when the
    model has no even term (nothing shifts the mean) or its coefficients settle.
    """
    offsets: list[np.ndarray | None] = [None] * len(kins)
    fit = first = _regress(_design(kins, terms, offsets, n_folds), terms, **selection)
    best = (fit, offsets, 0)
    for iteration in range(1, offset_iterations + 1):
        model = _model(terms, fit.coefficients)
        if model.linear_stiffness <= 0 or all(CATALOGUE[e].parity == "odd" for e in model.effects):
            break
        offsets = [mean_offset(model, k) for k in kins]
        previous, fit = fit, _refit(_design(kins, terms, offsets, n_folds), first)
        if fit.held_out < best[0].held_out:
            best = (fit, offsets, iteration)
        if np.allclose(fit.coefficients, previous.coefficients, rtol=1e-3, atol=0):
            break
    fit, offsets, iteration = best
    if iteration:
        fit = _regress(fit.design, terms, **selection)
    return terms, fit, offsets, iteration


def _model(terms: Sequence[LibraryTerm], coefficients: np.ndarray) -> JointModel:
    return JointModel(
        [Term(t.effect, float(c), t.shape) for t, c in zip(terms, coefficients, strict=True) if c],
        name="sindy",
    )


def _report(kins, terms, fit, offsets, iterations, threshold, ensemble, n_models, seed):
    names = [t.effect for t in terms]
    correlation, condition = _correlation(fit.design.gram)
    for i, j in itertools.combinations(range(len(names)), 2):
        if abs(correlation[i, j]) > COLLINEARITY_WARNING:
            warnings.warn(
                f"library columns {names[i]!r} and {names[j]!r} are nearly collinear on these "
                f"records (r = {correlation[i, j]:+.5f}): only their combination is identified",
                CollinearityWarning,
                stacklevel=3,
            )
    model = _model(terms, fit.coefficients)
    inclusion = ensemble_coefficients = None
    if ensemble:
        rows = np.hstack(fit.design.rows) / fit.design.scale[:, None]
        bagged = _bagged_coefficients(rows[:-1].T, rows[-1], fit.design.thresholds(fit.threshold),
                                      n_models, seed)  # fmt: skip
        inclusion = dict(zip(names, np.mean(bagged != 0, axis=0).tolist(), strict=True))
        median = _unscaled(np.median(bagged, axis=0), fit.design)
        ensemble_coefficients = dict(zip(names, median.tolist(), strict=True))
    method = "none" if threshold is None else threshold if isinstance(threshold, str) else "fixed"
    return Identification(
        model=model,
        library=tuple(terms),
        coefficients=dict(zip(names, fit.coefficients.tolist(), strict=True)),
        normalised_coefficients=dict(zip(names, (-fit.xi).tolist(), strict=True)),
        groups={n: GROUPS[d] for n, d in zip(names, fit.design.dissipative.tolist(), strict=True)},
        threshold=(float(fit.threshold[0]), float(fit.threshold[1])),
        threshold_method=method,
        path=fit.path,
        r2=1.0 - fit.rss / fit.design.tss,
        residual_rms=math.sqrt(fit.rss / fit.design.n_rows),
        held_out_rms=math.sqrt(fit.held_out) * float(fit.design.scale[-1]),
        condition_number=condition,
        correlation=correlation,
        peak_contribution=_peak_contribution(model, kins, offsets),
        inclusion_probability=inclusion,
        ensemble_coefficients=ensemble_coefficients,
        offset_iterations=iterations,
        band_hz=tuple(k.band_hz for k in kins),
        n_samples=fit.design.n_rows,
    )


def _peak_contribution(model, kins, offsets) -> dict[str, float]:
    peaks = {t.effect: 0.0 for t in model.terms}
    total = 0.0
    for kin, offset in zip(kins, offsets, strict=True):
        x = kin.displacement if offset is None else kin.displacement + offset
        x, v = x[kin.valid], kin.velocity[kin.valid]
        total = max(total, float(np.max(np.abs(model.restoring_force(x, v)))))
        for t in model.terms:
            peaks[t.effect] = max(peaks[t.effect], float(np.max(np.abs(
                t.coefficient * CATALOGUE[t.effect].feature(x, v, **t.shape)))))  # fmt: skip
    return {name: peak / total for name, peak in peaks.items()} if total else peaks


@contextmanager
def _numpy_seed(seed: int) -> Iterator[None]:
    # pysindy's bagging draws from numpy's global generator: seed it, then restore.
    state = np.random.get_state()  # noqa: NPY002
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def _bagged_coefficients(theta_n, y_n, thresholds, n_models, seed) -> np.ndarray:
    """``(n_models, n_terms)`` normalised coefficients of bagged STLSQ fits."""
    inner, ratio = _stlsq_optimizer(theta_n, thresholds)
    optimizer = ps.EnsembleOptimizer(inner, bagging=True, n_models=n_models)
    with _numpy_seed(seed), _quiet_stlsq():
        optimizer.fit(theta_n * ratio, y_n)
    return np.array(optimizer.coef_list)[:, 0, :] * ratio


# --------------------------------------------------------------------------- validation


@dataclass(frozen=True)
class ErrorStatistics:
    """Error of a predicted signal against the measured one (paper section 4.1.3)."""

    mean: float
    max_abs: float
    rmse: float
    relative_rmse: float  # rmse / RMS of the measured signal

    @classmethod
    def of(cls, measured: np.ndarray, predicted: np.ndarray) -> ErrorStatistics:
        error = predicted - measured
        rmse = float(np.sqrt(np.mean(error**2)))
        return cls(float(np.mean(error)), float(np.max(np.abs(error))), rmse,
                   rmse / float(np.sqrt(np.mean(measured**2))))  # fmt: skip


@dataclass(frozen=True, eq=False)
class Validation:
    """Open-loop simulation of a model under the measured base excitation, against the record."""

    t: np.ndarray
    measured_velocity: np.ndarray
    predicted_velocity: np.ndarray
    measured_acceleration: np.ndarray
    predicted_acceleration: np.ndarray
    velocity: ErrorStatistics
    acceleration: ErrorStatistics


def validate(model: JointModel, kin: Kinematics) -> Validation:
    """Simulate ``model`` under the record's base acceleration and compare.

    The simulation (:func:`identification.analytical.pll.simulate_base_excitation`)
    starts from the record's first displacement and velocity; its velocity and
    acceleration pass the record's band-pass, so that both sides are compared
    in the same band, and are compared over the valid samples.
    """
    _, v, a = pll.simulate_base_excitation(
        model, kin.t, kin.base_acceleration, x0=kin.displacement[0], v0=kin.velocity[0]
    )
    if not np.all(np.isfinite(v)):
        raise ValueError("the model's response to the measured base excitation diverges")
    predicted = bandpass(np.column_stack([v, a]), kin.sampling_rate_hz, kin.band_hz)[kin.valid]
    measured_v, measured_a = kin.velocity[kin.valid], kin.acceleration[kin.valid]
    return Validation(
        t=kin.t[kin.valid],
        measured_velocity=measured_v,
        predicted_velocity=predicted[:, 0],
        measured_acceleration=measured_a,
        predicted_acceleration=predicted[:, 1],
        velocity=ErrorStatistics.of(measured_v, predicted[:, 0]),
        acceleration=ErrorStatistics.of(measured_a, predicted[:, 1]),
    )


def plot_validation(
    validation: Validation,
    axes: Sequence[Any],
    *,
    channel: str = "velocity",
    zoom_s: tuple[float, float] | None = None,
) -> None:
    """Draw the paper's Fig. 9 (velocity) or Fig. 10 (acceleration) on three matplotlib axes.

    ``axes``: overall comparison, zoomed comparison (``zoom_s``, default ten
    periods around the largest measured value), error over the whole record.
    """
    if channel not in ("velocity", "acceleration"):
        raise ValueError(f"channel must be 'velocity' or 'acceleration', got {channel!r}")
    if len(axes) != 3:
        raise ValueError(f"need 3 axes (overall, zoom, error), got {len(axes)}")
    t = validation.t
    measured = getattr(validation, f"measured_{channel}")
    predicted = getattr(validation, f"predicted_{channel}")
    unit = "m/s" if channel == "velocity" else "m/s²"
    if zoom_s is None:
        peak = t[np.argmax(np.abs(measured))]
        period = 10 * _dominant_period(t, measured)
        zoom_s = (peak - period / 2, peak + period / 2)
    window = (t >= zoom_s[0]) & (t <= zoom_s[1])
    for ax, mask in ((axes[0], slice(None)), (axes[1], window)):
        ax.plot(t[mask], measured[mask], label="measured")
        ax.plot(t[mask], predicted[mask], "--", label="SINDy model")
        ax.set_ylabel(f"{channel} ({unit})")
        ax.legend(loc="upper right")
    stats = getattr(validation, channel)
    axes[2].plot(t, predicted - measured)
    axes[2].set_ylabel(f"error ({unit})")
    axes[2].set_xlabel("time (s)")
    axes[2].set_title(f"mean {stats.mean:.3g}, max {stats.max_abs:.3g}, RMSE {stats.rmse:.3g} "
                      f"{unit}", fontsize="small")  # fmt: skip


def _dominant_period(t: np.ndarray, values: np.ndarray) -> float:
    spectrum = np.abs(np.fft.rfft(values))
    frequencies = np.fft.rfftfreq(values.size, t[1] - t[0])
    return 1.0 / frequencies[1 + np.argmax(spectrum[1:])]


def backbone_error(
    model: JointModel,
    amplitude_m: ArrayLike,
    frequency_hz: ArrayLike,
    *,
    method: str = "single",
) -> np.ndarray:
    """Relative frequency error of the model's harmonic-balance backbone at measured points.

    ``harmonic.backbone(model, amplitude_m).frequency_hz / frequency_hz − 1``
    (NaN where the harmonic balance found no phase-resonant solution).
    """
    amplitude_m = np.asarray(amplitude_m, dtype=float)
    frequency_hz = np.asarray(frequency_hz, dtype=float)
    if amplitude_m.shape != frequency_hz.shape:
        raise ValueError(f"amplitude_m {amplitude_m.shape} and frequency_hz "
                         f"{frequency_hz.shape} must have the same shape")  # fmt: skip
    predicted = harmonic.backbone(model, amplitude_m, method=method).frequency_hz
    return predicted / frequency_hz - 1.0
