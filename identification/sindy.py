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
  (``offset_iterations``); the iterate with the lowest cross-validated error is
  kept.
* **Scaling.** Columns and target are divided by their maxima (the paper's
  scaling, applied per column so that non-polynomial features scale too). A
  normalised coefficient ``ξ_i = c_i max|φ_i| / max|y|`` is then the peak share
  of term ``i`` in the force, and the STLSQ threshold is a peak share as well.
* **Threshold.** ``"cv"`` (default): K-fold cross-validation over contiguous
  time blocks (one block of every record per fold), and the sparsest threshold
  whose held-out error is within one standard error of the best (the
  one-standard-error rule). ``"bic"``: Bayesian information criterion along the
  threshold path with the effective number of independent samples
  ``2 · bandwidth · duration`` (consecutive samples of a band-limited residual
  are not independent). Thresholds below ``min_threshold`` (default 1e-3, the
  accuracy of the band-pass and of the differentiation) are not tried: terms
  below that share cannot be told from preprocessing error.
* **Fast.** Regressions on any subset of columns only need the Gram matrix, so
  every time block is reduced once to the Gram matrix of its ``[Θ | y]``, and
  the threshold path and cross-validation run on those small matrices.

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
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pysindy as ps
from numpy.typing import ArrayLike

from identification import harmonic, pll
from identification.effects import CATALOGUE, get_effect
from identification.model import JointModel, Term
from identification.signals import (
    Kinematics,
    bandpass,
    kinematics,
    lowpass,
    scale_by_maximum,
    unscale_coefficients,
)

__all__ = [
    "EQ3_SYMBOLS",
    "PAPER_LIBRARY",
    "POLYNOMIAL_LIBRARY",
    "CollinearityWarning",
    "ErrorStatistics",
    "Identification",
    "LibraryTerm",
    "RankDeficientLibraryError",
    "ThresholdPath",
    "Validation",
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
        Band-limited kinematics of the record (:func:`~identification.signals.kinematics`).
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
# reduced to its Gram once (one BLAS product), and the threshold path, the
# cross-validation and STLSQ run on these small matrices.


@dataclass(frozen=True, eq=False)
class ThresholdPath:
    """Scores along the STLSQ threshold path (thresholds are peak shares, ascending)."""

    thresholds: np.ndarray
    n_terms: np.ndarray
    score: np.ndarray
    score_se: np.ndarray | None
    criterion: str


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


def _stlsq(factor: np.ndarray, threshold: float) -> np.ndarray:
    """Sequentially thresholded least squares (pysindy) on a Gram factor."""
    a, b = factor[:, :-1], factor[:, -1]
    if threshold == 0:
        return np.linalg.lstsq(a, b, rcond=None)[0]
    # Negligible ridge; pysindy's unbias step refits the support without it.
    optimizer = ps.STLSQ(threshold=threshold, alpha=1e-12 * np.sum(a * a), max_iter=50)
    with warnings.catch_warnings():
        # All terms below the threshold is a legitimate end of the path.
        warnings.filterwarnings("ignore", message="Sparsity parameter is too big")
        optimizer.fit(a, b)
    return optimizer.coef_[0]


def _threshold_path(factor: np.ndarray, min_threshold: float, n_path: int) -> np.ndarray:
    """One threshold per distinct support along a geometric sweep, ascending.

    Thresholds from ``min_threshold`` to the largest least-squares coefficient
    are swept; consecutive ones giving the same support on the whole data are
    merged into their geometric mean, which sits safely inside that support's
    range for the cross-validation folds too.
    """
    top = np.max(np.abs(_stlsq(factor, 0.0)))
    if top <= min_threshold:
        return np.array([min_threshold])
    sweep = np.geomspace(min_threshold, top, n_path)
    supports = [tuple(_stlsq(factor, lam) != 0) for lam in sweep]
    groups = [list(g) for _, g in itertools.groupby(range(n_path), key=lambda i: supports[i])]
    return np.array([math.sqrt(sweep[g[0]] * sweep[g[-1]]) for g in groups])


def _cross_validation(
    fold_grams: Sequence[np.ndarray], sizes: Sequence[int], thresholds: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error of the held-out mean squared error per threshold."""
    errors = np.empty((len(thresholds), len(fold_grams)))
    for k, (held_out, size) in enumerate(zip(fold_grams, sizes, strict=True)):
        train = _factor(sum(g for j, g in enumerate(fold_grams) if j != k))
        for i, threshold in enumerate(thresholds):
            errors[i, k] = _rss(held_out, _stlsq(train, threshold)) / size
    return errors.mean(axis=1), errors.std(axis=1, ddof=1) / math.sqrt(len(fold_grams))


@dataclass(frozen=True, eq=False)
class _Design:
    """Scaled Gram matrices of one design, one per cross-validation fold (internal)."""

    fold_grams: list[np.ndarray]  # augmented [Θ | y], columns divided by `scale`
    sizes: np.ndarray  # rows per fold
    scale: np.ndarray  # maxima of the columns, then of y
    tss: float  # total sum of squares of y (SI)
    rows: Sequence[np.ndarray]  # per record, unscaled, for bagging

    @property
    def gram(self) -> np.ndarray:
        return sum(self.fold_grams)

    @property
    def n_rows(self) -> int:
        return int(self.sizes.sum())


def _design(
    kins: Sequence[Kinematics],
    terms: Sequence[LibraryTerm],
    offsets: Sequence[np.ndarray | None],
    n_folds: int,
) -> _Design:
    """Band-passed library of every record, reduced to per-fold Gram matrices.

    Each fold is one contiguous block of every record.
    """
    rows = [_design_rows(k, terms, o) for k, o in zip(kins, offsets, strict=True)]
    scale = np.max([np.max(np.abs(r), axis=1) for r in rows], axis=0)
    zero = np.flatnonzero(scale[:-1] == 0)
    if zero.size:
        raise ValueError(
            f"library column(s) {[terms[i].effect for i in zero]} are zero on these records"
        )
    fold_grams = [np.zeros((scale.size, scale.size)) for _ in range(n_folds)]
    sizes = np.zeros(n_folds, dtype=int)
    for r in rows:
        bounds = np.linspace(0, r.shape[1], n_folds + 1).astype(int)
        for k, (start, stop) in enumerate(itertools.pairwise(bounds)):
            block = r[:, start:stop]
            fold_grams[k] += block @ block.T
            sizes[k] += stop - start
    normalise = np.outer(1 / scale, 1 / scale)
    y_sum = sum(float(np.sum(r[-1])) for r in rows)
    y_squares = sum(float(r[-1] @ r[-1]) for r in rows)
    return _Design(
        fold_grams=[g * normalise for g in fold_grams],
        sizes=sizes,
        scale=scale,
        tss=y_squares - y_sum**2 / sizes.sum(),
        rows=rows,
    )


@dataclass(frozen=True, eq=False)
class _Fit:
    """One regression of a design (internal)."""

    design: _Design
    xi: np.ndarray  # normalised coefficients of y on Θ
    threshold: float
    path: ThresholdPath | None
    held_out: float  # cross-validated mean squared error at `threshold` (scaled units)
    rss: float  # SI, (m/s²)²

    @property
    def coefficients(self) -> np.ndarray:
        """SI coefficients in the model convention (``c_i = −w_i``)."""
        return -unscale_coefficients(self.xi, self.design.scale[:-1], self.design.scale[-1])


def _regress(
    design: _Design,
    names: Sequence[str],
    threshold: float | str | None,
    n_effective: float,
    min_threshold: float,
    n_path: int,
) -> _Fit:
    """STLSQ with the threshold chosen as asked."""
    gram = design.gram
    _check_rank(gram, names)
    factor = _factor(gram)
    path = None
    if threshold is None:
        chosen = 0.0
    elif isinstance(threshold, str):
        thresholds = _threshold_path(factor, min_threshold, n_path)
        fits = [_stlsq(factor, lam) for lam in thresholds]
        n_terms = np.array([np.count_nonzero(xi) for xi in fits])
        if threshold == "cv":
            score, se = _cross_validation(design.fold_grams, design.sizes, thresholds)
            best = int(np.argmin(score))
            chosen_index = int(np.flatnonzero(score <= score[best] + se[best])[-1])
        elif threshold == "bic":
            rss = np.array([_rss(gram, xi) for xi in fits])
            score = n_effective * np.log(rss / design.n_rows) + n_terms * np.log(n_effective)
            se = None
            chosen_index = int(np.flatnonzero(score <= score.min() + 1e-9 * abs(score.min()))[-1])
        else:
            raise ValueError(f"threshold must be a number, 'cv', 'bic' or None, got {threshold!r}")
        path = ThresholdPath(thresholds, n_terms, score, se, threshold)
        chosen = float(thresholds[chosen_index])
    else:
        chosen = float(threshold)
        if not math.isfinite(chosen) or chosen < 0:
            raise ValueError(f"threshold must be finite and >= 0, got {threshold}")
    xi = _stlsq(factor, chosen)
    if threshold == "cv":
        held_out = float(path.score[chosen_index])
    else:
        mean, _ = _cross_validation(design.fold_grams, design.sizes, np.array([chosen]))
        held_out = float(mean[0])
    return _Fit(design, xi, chosen, path, held_out, _rss(gram, xi) * design.scale[-1] ** 2)


def _check_rank(gram: np.ndarray, names: Sequence[str]) -> None:
    """ValueError naming the columns when the scaled library is numerically rank-deficient."""
    values, vectors = np.linalg.eigh(gram[:-1, :-1])
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


def _correlation(gram: np.ndarray) -> tuple[np.ndarray, float]:
    """Column correlations and condition number of the scaled library.

    The columns are band-passed, hence zero-mean, so the cosine of the angle
    between two columns is their Pearson correlation.
    """
    g = gram[:-1, :-1]
    norms = np.sqrt(np.diag(g))
    values = np.clip(np.linalg.eigvalsh(g), 0.0, None)
    return g / np.outer(norms, norms), float(np.sqrt(values[-1] / values[0]))


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
        Peak share ``c_i max|φ_i| / max|ẍ + a_base|`` (signed), the scale the
        threshold applies to.
    threshold
        The STLSQ threshold used (a peak share).
    threshold_method
        ``"cv"``, ``"bic"``, ``"fixed"`` or ``"none"`` (plain least squares).
    path
        Scores along the threshold path (None for a fixed threshold).
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
    threshold: float
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
            f"SINDy identification: {self.n_samples} samples, threshold {self.threshold:.3g} "
            f"({self.threshold_method}), R² = {self.r2:.6f}, residual RMS "
            f"{self.residual_rms:.4g} m/s² (held out {self.held_out_rms:.4g}), condition number "
            f"{self.condition_number:.3g}",
            f"{'effect':<30}{'coefficient':>14}{'ξ':>11}{'peak share':>12}{'P(incl.)':>10}",
        ]
        for name in self.effects:
            share = self.peak_contribution.get(name)
            incl = None if self.inclusion_probability is None else self.inclusion_probability[name]
            lines.append(
                f"{name:<30}{self.coefficients[name]:>14.4g}"
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
    """Band-limited kinematics of a :class:`~identification.records.Record`."""
    return kinematics(record.time_s, record.response_velocity, record.excitation_velocity,
                      record.frequency_hz, record.sampling_rate_hz, **options)  # fmt: skip


def identify(records: Any, effects: Sequence[str], **options: Any) -> Identification:
    """Identify a joint model from test records (:class:`~identification.records.Record`).

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
    threshold: float | str | None = "cv",
    ensemble: bool = False,
    n_models: int = 20,
    seed: int = 0,
    n_folds: int = 5,
    min_threshold: float = 1e-3,
    n_path: int = 30,
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
        ``"cv"``, ``"bic"`` (see the module notes), a fixed peak-share
        threshold, or None for plain least squares on the whole library.
    ensemble
        Also bag ``n_models`` STLSQ fits (``pysindy.EnsembleOptimizer``, time
        samples drawn with replacement, ``seed``) at the chosen threshold and
        report per-term inclusion probabilities. Consecutive samples are
        correlated, so these probabilities are optimistic.
    n_folds
        Time blocks per record for ``"cv"``.
    min_threshold, n_path
        Lowest threshold tried and number of thresholds on the path.
    offset_iterations
        Mean-offset reconstructions (:func:`mean_offset`) after the first fit; 0 disables.
    n_harmonics, edge_periods
        Preprocessing (:func:`~identification.signals.kinematics`).
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
    selection = dict(threshold=threshold, n_effective=n_effective, min_threshold=min_threshold,
                     n_path=n_path)  # fmt: skip
    best, refused = None, []
    for terms in grid:
        try:
            candidate = _fit_with_offsets(kins, terms, selection, n_folds, offset_iterations)
        except RankDeficientLibraryError as exc:
            if len(grid) == 1:
                raise
            refused.append(f"{_shape_text(terms)} ({exc})")
            continue
        if best is None or candidate[1].held_out < best[1].held_out:
            best = candidate
    if best is None:
        raise RankDeficientLibraryError("every shape of the grid gives a rank-deficient library: "
                                        + "; ".join(refused))  # fmt: skip
    if refused:
        warnings.warn("shape grid points skipped: " + "; ".join(refused), stacklevel=2)
    terms, fit, offsets, iterations = best
    return _report(kins, terms, fit, offsets, iterations, threshold, ensemble, n_models, seed)


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

    The threshold is chosen on the first fit and held while the offset is
    iterated, and chosen again on the kept design. Iterates are compared by
    their cross-validated error: the in-sample residual would favour spurious
    terms that mimic the missing offset. The iteration stops early when the
    model has no even term (nothing shifts the mean) or its coefficients settle.
    """
    names = [t.effect for t in terms]
    offsets: list[np.ndarray | None] = [None] * len(kins)
    fit = first = _regress(_design(kins, terms, offsets, n_folds), names, **selection)
    held = {**selection, "threshold": first.threshold}
    best = (fit, offsets, 0)
    for iteration in range(1, offset_iterations + 1):
        model = _model(terms, fit.coefficients)
        if model.linear_stiffness <= 0 or all(CATALOGUE[e].parity == "odd" for e in model.effects):
            break
        offsets = [mean_offset(model, k) for k in kins]
        previous, fit = fit, _regress(_design(kins, terms, offsets, n_folds), names, **held)
        if fit.held_out < best[0].held_out:
            best = (fit, offsets, iteration)
        if np.allclose(fit.xi, previous.xi, rtol=1e-3, atol=0):
            break
    fit, offsets, iteration = best
    if iteration and isinstance(selection["threshold"], str):
        fit = _regress(fit.design, names, **selection)
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
        rows, _ = scale_by_maximum(np.hstack(fit.design.rows), axis=1)
        bagged = _bagged_coefficients(rows[:-1].T, rows[-1], fit.threshold, n_models, seed)
        inclusion = dict(zip(names, np.mean(bagged != 0, axis=0).tolist(), strict=True))
        median = -unscale_coefficients(np.median(bagged, axis=0), fit.design.scale[:-1],
                                       fit.design.scale[-1])  # fmt: skip
        ensemble_coefficients = dict(zip(names, median.tolist(), strict=True))
    method = "none" if threshold is None else threshold if isinstance(threshold, str) else "fixed"
    return Identification(
        model=model,
        library=tuple(terms),
        coefficients=dict(zip(names, fit.coefficients.tolist(), strict=True)),
        normalised_coefficients=dict(zip(names, (-fit.xi).tolist(), strict=True)),
        threshold=fit.threshold,
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


def _bagged_coefficients(theta_n, y_n, threshold, n_models, seed) -> np.ndarray:
    """``(n_models, n_terms)`` normalised coefficients of bagged STLSQ fits."""
    inner = ps.STLSQ(threshold=threshold, alpha=1e-12 * np.sum(theta_n * theta_n), max_iter=50)
    optimizer = ps.EnsembleOptimizer(inner, bagging=True, n_models=n_models)
    with _numpy_seed(seed), warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Sparsity parameter is too big")
        optimizer.fit(theta_n, y_n)
    return np.array(optimizer.coef_list)[:, 0, :]


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

    The simulation (:func:`identification.pll.simulate_base_excitation`)
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
