"""Model selection: which support of the library the data support, and at which thresholds.

**Candidates.** Each group's threshold is raised from ``min_threshold``
(default 1e-3 of the group's force) to just above its weakest kept term, STLSQ
restarting from the previous support, until the group is empty
(:func:`.regression.group_paths`); the candidates are all combinations of the two
groups' supports. The same paths are walked on the library's polynomial columns
alone, so that every support the polynomial library would reach competes too:
a non-polynomial column that imitates ``x + x² + x³`` with the wrong ratios
changes the shares along the paths, and the polynomial support could otherwise
be stepped over. Backward elimination by held-out error from the whole library
(:func:`backward_path`), and after the selection from the selected and from the
best candidate within the score limit, adds the supports that thresholds cannot
reach, where nearly collinear columns have their shares in the wrong order.

**Scores.** ``"cv"`` (default): K-fold cross-validation of each candidate
support, refitted on the training folds (the weighted folds of :mod:`.design`:
the held-out mean square is about 1 for a model as good as the reference fit,
at every amplitude). The model is the candidate with the fewest terms within
one standard error of the best (the one-standard-error rule). ``"bic"``:
Bayesian information criterion with the effective number of independent
samples ``2 · bandwidth · duration`` (consecutive samples of a band-limited
residual are not independent), times Kish's effective fraction of the weighted
rows; it takes the residual for noise, so on noise-free simulations it keeps
small terms that fit preprocessing error. Only admissible
candidates (:mod:`.admissibility`) compete while there is one; they
are checked lazily, in the order the rule needs them.

**A clearly better support.** :func:`better_support` looks, after the
selection, for a support with a clearly lower held-out error than the model's
(:data:`BETTER_SUPPORT_RATIO`, :data:`BETTER_SUPPORT_SE`) among the candidates
and the model's support with one term added; the identification names it in a
warning.
"""

from __future__ import annotations

import itertools
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from identification.effects import CATALOGUE
from identification.sindy.admissibility import Admissibility
from identification.sindy.design import Design
from identification.sindy.library import LibraryTerm, check_rank, library_model
from identification.sindy.regression import (
    gram_factor,
    group_paths,
    least_squares,
    residual_sum_of_squares,
    stlsq,
)

#: Held-out mean square of the model over that of another support above which, together
#: with :data:`BETTER_SUPPORT_SE`, the other support is clearly better (RMS 12 % larger).
BETTER_SUPPORT_RATIO = 1.25
#: Standard errors of the fold-by-fold difference the other support must also be better by.
BETTER_SUPPORT_SE = 2.0


@dataclass(frozen=True, eq=False)
class ThresholdPath:
    """Candidate models along the two STLSQ threshold paths, and their scores.

    Conservative and dissipative columns each have their own threshold
    (:data:`.library.GROUPS`, shares of the group's force); the candidates are the
    combinations of the distinct supports found along both paths, on the whole
    library and on its polynomial columns.

    Attributes
    ----------
    thresholds
        ``(n, 2)`` conservative and dissipative threshold of each candidate
        (NaN for a group the library lacks).
    supports
        Which library columns each candidate keeps.
    n_terms
        Fitted parameters of each candidate: its terms and their fitted shape
        parameters (:func:`parameter_counts`).
    score
        Held-out mean square (``"cv"``, weighted and scaled: about 1 for a model
        as good as the reference fit) or BIC (``"bic"``).
    score_se
        Standard error of the held-out error across folds (``"cv"``), else None.
    criterion
        ``"cv"`` or ``"bic"``.
    admissible
        Whether the candidate is admissible (:class:`.admissibility.Admissibility`);
        False also where it was not checked (see ``checked``).
    checked
        Whether the selection needed to check the candidate's admissibility.
    chosen
        Index of the selected candidate.
    pruned
        Terms of the selected candidate that the model does not keep: backward
        elimination (from it and from the best-scoring candidate) removed them
        within the same score limit.
    """

    thresholds: np.ndarray
    supports: list[np.ndarray]
    n_terms: np.ndarray
    score: np.ndarray
    score_se: np.ndarray | None
    criterion: str
    admissible: np.ndarray
    checked: np.ndarray
    chosen: int
    pruned: tuple[str, ...]


@dataclass(frozen=True, eq=False)
class Fit:
    """One regression of a design: its coefficients, thresholds and errors."""

    design: Design
    xi: np.ndarray  # normalised coefficients (group shares) of y on Θ
    threshold: np.ndarray  # (conservative, dissipative)
    path: ThresholdPath | None
    held_out: float  # cross-validated mean square of the support (weighted, scaled)
    rss: float  # SI, (m/s²)², unweighted

    @property
    def coefficients(self) -> np.ndarray:
        """SI coefficients in the model convention (``c_i = −w_i``)."""
        return self.design.model_coefficients(self.xi)

    @property
    def support(self) -> np.ndarray:
        """Which columns the fit keeps."""
        return self.xi != 0


def sparse_fit(
    design: Design,
    terms: Sequence[LibraryTerm],
    threshold: float | Sequence[float] | str | None,
    n_effective: float,
    min_threshold: float,
    admissibility: Admissibility,
    fitted_shapes: Sequence[int] | None = None,
) -> Fit:
    """STLSQ with the thresholds chosen as asked.

    Parameters
    ----------
    design
        The weighted, scaled per-fold Gram matrices of the library.
    terms
        Library columns (names for messages, models for admissibility).
    threshold
        ``"cv"`` or ``"bic"`` (candidates along the threshold paths, scored,
        then backward elimination), a fixed group share (one for both groups
        or a (conservative, dissipative) pair), or None (least squares on every column).
    n_effective
        Effective number of independent samples (for BIC).
    min_threshold
        Lowest threshold of the paths (a group share).
    admissibility
        The checks a candidate must pass to compete.
    fitted_shapes
        Per library column, how many shape parameters were fitted to the data
        (scanned, :mod:`.shapes`); each counts as a parameter of the supports that keep
        the column (:func:`parameter_counts`). None: none.

    Raises
    ------
    ValueError
        An invalid ``threshold``, or a rank-deficient library
        (:class:`.library.RankDeficientLibraryError`).
    """
    gram = design.gram
    check_rank(gram, [t.effect for t in terms])
    factor = gram_factor(gram)
    path = None
    if threshold is None:
        pair = np.zeros(2)
        xi = least_squares(factor)
    elif isinstance(threshold, str):
        if threshold not in ("cv", "bic"):
            raise ValueError(
                "threshold must be a number, a (conservative, dissipative) pair, 'cv', 'bic' or "
                f"None, got {threshold!r}"
            )
        pairs, supports = _candidates(design, terms, factor, min_threshold)
        score, se, fits = _scores(design, supports, threshold, n_effective)
        n_terms = parameter_counts(supports, fitted_shapes)
        verdicts: dict[int, bool] = {}

        def candidate_admissible(i: int) -> bool:
            if i not in verdicts:
                verdicts[i] = admissibility(
                    library_model(terms, design.model_coefficients(fits[i]))
                )
            return verdicts[i]

        chosen, best, limit = _select(score, se, n_terms, candidate_admissible)
        any_admissible = any(verdicts.values())

        def acceptable(xi: np.ndarray) -> bool:
            model = library_model(terms, design.model_coefficients(xi))
            return not any_admissible or admissibility(model)

        # Backward elimination from the selected and from the best candidate; the
        # sparser end (then the better scoring) is the model.
        ends = [_prune(design, fits[i], score[i], limit, threshold, n_effective, acceptable)
                for i in dict.fromkeys((chosen, best))]  # fmt: skip
        xi = min(ends, key=lambda end: (parameter_counts([end[0] != 0], fitted_shapes)[0],
                                        end[1]))[0]  # fmt: skip
        pruned = tuple(t.effect for t, a, b in zip(terms, fits[chosen], xi, strict=True)
                       if a and not b)  # fmt: skip
        checked = np.zeros(len(supports), dtype=bool)
        checked[list(verdicts)] = True
        admissible_ = np.zeros(len(supports), dtype=bool)
        admissible_[[i for i, ok in verdicts.items() if ok]] = True
        path = ThresholdPath(pairs, supports, n_terms, score, se if threshold == "cv" else None,
                             threshold, admissible_, checked, chosen, pruned)  # fmt: skip
        pair = pairs[chosen]
    else:
        pair = _threshold_pair(threshold)
        xi = stlsq(factor, design.thresholds(pair)) if pair.any() else least_squares(factor)
    return _fit(design, xi, pair, path)


def parameter_counts(
    supports: Sequence[np.ndarray], fitted_shapes: Sequence[int] | None
) -> np.ndarray:
    """Fitted parameters of each support: its terms, plus the shape parameters fitted to the
    data of the terms it keeps (a ``tanh(x/x_s)`` with a scanned ``x_s`` has two).

    A column whose shape was chosen to fit the data can imitate a polynomial over the
    records' range (``tanh(x/x_s)`` with ``x_s`` above the amplitudes is ``x − x³/(3x_s²)``
    there); counted as one parameter it ties with the polynomial it imitates, and the
    one-standard-error rule could take the imitation.
    """
    extra = np.zeros(len(supports[0])) if fitted_shapes is None else np.asarray(fitted_shapes)
    return np.array([int(np.count_nonzero(s) + extra[np.asarray(s, dtype=bool)].sum())
                     for s in supports])  # fmt: skip


def refit(design: Design, fit: Fit) -> Fit:
    """Least squares on a new design with the support (and thresholds) of an earlier fit."""
    return _fit(design, least_squares(gram_factor(design.gram), fit.support), fit.threshold, None)


def better_support(
    fit: Fit, terms: Sequence[LibraryTerm], admissibility: Admissibility
) -> tuple[np.ndarray, float] | None:
    """An admissible support with a clearly lower held-out error than the fit's, or None.

    Looked for among the threshold-path candidates and the fit's support with
    one more library term. Clearly lower: the fit's held-out mean square exceeds
    the other's by :data:`BETTER_SUPPORT_RATIO` and the fold-by-fold difference
    is :data:`BETTER_SUPPORT_SE` standard errors above zero. Returns the best
    such support (lowest held-out mean square) and its held-out mean square.
    """
    design = fit.design
    others = [] if fit.path is None else list(fit.path.supports)
    others += [fit.support | (np.arange(fit.xi.size) == i) for i in np.flatnonzero(~fit.support)]
    errors = fold_errors(design.fold_grams, design.sizes, [fit.support, *others])
    mine, theirs = errors[0], errors[1:]
    difference = mine[None, :] - theirs
    n = difference.shape[1]
    se = difference.std(axis=1, ddof=1) / math.sqrt(n)
    clear = (mine.mean() > BETTER_SUPPORT_RATIO * theirs.mean(axis=1)) & (
        difference.mean(axis=1) > BETTER_SUPPORT_SE * se)  # fmt: skip
    factor = gram_factor(design.gram)
    for i in np.argsort(theirs.mean(axis=1)):
        if not clear[i]:
            continue
        model = library_model(terms, design.model_coefficients(least_squares(factor, others[i])))
        if admissibility(model):
            return others[i], float(theirs[i].mean())
    return None


def _candidates(
    design: Design, terms: Sequence[LibraryTerm], factor: np.ndarray, min_threshold: float
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Threshold pairs and distinct supports of the candidates (see module notes).

    Along the threshold paths of the library and of its polynomial columns,
    then along the backward elimination of the whole library (thresholds NaN),
    each of its supports thresholded at ``min_threshold``.
    """
    polynomial = np.array([CATALOGUE[t.effect].polynomial for t in terms])
    libraries = [np.ones(len(terms), dtype=bool)]
    if polynomial.any() and not polynomial.all():
        libraries.append(polynomial)
    seen: dict[bytes, tuple[np.ndarray, np.ndarray]] = {}
    for columns in libraries:
        keep = np.append(columns, True)
        sub = factor if columns.all() else gram_factor(design.gram[np.ix_(keep, keep)])
        paths = group_paths(sub, design.dissipative[columns], min_threshold)
        for (tc, sc), (td, sd) in itertools.product(*paths):
            support = np.zeros(len(terms), dtype=bool)
            support[columns] = sc | sd
            seen.setdefault(support.tobytes(), (np.array([tc, td]), support))
    floor = np.full(len(terms), min_threshold)
    for support in backward_path(design):
        # Below the lowest threshold a term is kept by no path: the elimination's supports
        # are thresholded there too. Kept, such a term competes on a fit of what the noise
        # is not (on noise-free sweeps an x·ẋ² of 0.02 % share fits preprocessing error,
        # and BIC, which takes the whole residual for noise, kept it).
        support = stlsq(factor, floor, support) != 0
        seen.setdefault(support.tobytes(), (np.full(2, np.nan), support))
    pairs = np.array([pair for pair, _ in seen.values()])
    return pairs, [support for _, support in seen.values()]


def backward_path(design: Design) -> list[np.ndarray]:
    """Supports of the backward elimination of the whole library by held-out error.

    From every column, each step drops the column whose removal leaves the
    lowest held-out mean square, down to one column. Thresholds order the
    columns by their shares, and with nearly collinear columns (``x²``, ``ẋ²``
    and ``x·ẋ`` all act through the 2nd harmonic) the true support can lie on
    no threshold path; the elimination reaches it from the data's side.
    """
    support = np.ones(design.fold_grams[0].shape[0] - 1, dtype=bool)
    path = [support]
    while np.count_nonzero(support) > 1:
        trials = [support & (np.arange(support.size) != i) for i in np.flatnonzero(support)]
        errors = cross_validation(design.fold_grams, design.sizes, trials)[0]
        support = trials[int(np.argmin(errors))]
        path.append(support)
    return path


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


def _fit(design: Design, xi: np.ndarray, pair: np.ndarray, path: ThresholdPath | None) -> Fit:
    """A :class:`Fit` with the cross-validated error of its support."""
    held_out = float(cross_validation(design.fold_grams, design.sizes, [xi != 0])[0][0])
    rss = residual_sum_of_squares(design.unweighted_gram, xi) * design.scale[-1] ** 2
    return Fit(design, xi, pair, path, held_out, rss)


def fold_errors(
    fold_grams: Sequence[np.ndarray], sizes: Sequence[int], supports: Sequence[np.ndarray]
) -> np.ndarray:
    """``(n_supports, n_folds)`` held-out mean squares of each support in each fold.

    Each candidate support is refitted by least squares on the training folds
    (STLSQ's own last step) and scored on the held-out one.
    """
    errors = np.empty((len(supports), len(fold_grams)))
    for k, (held_out, size) in enumerate(zip(fold_grams, sizes, strict=True)):
        train = gram_factor(sum(g for j, g in enumerate(fold_grams) if j != k))
        for i, support in enumerate(supports):
            errors[i, k] = residual_sum_of_squares(held_out, least_squares(train, support)) / size
    return errors


def cross_validation(
    fold_grams: Sequence[np.ndarray], sizes: Sequence[int], supports: Sequence[np.ndarray]
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error over the folds of each support's held-out mean square."""
    errors = fold_errors(fold_grams, sizes, supports)
    return errors.mean(axis=1), errors.std(axis=1, ddof=1) / math.sqrt(len(fold_grams))


def _scores(
    design: Design, supports: Sequence[np.ndarray], criterion: str, n_effective: float
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Score, its standard error (0 for BIC) and least-squares fit of each candidate support."""
    factor = gram_factor(design.gram)
    fits = [least_squares(factor, support) for support in supports]
    if criterion == "cv":
        score, se = cross_validation(design.fold_grams, design.sizes, supports)
        return score, se, fits
    rss = np.array([residual_sum_of_squares(design.gram, xi) for xi in fits])
    n_terms = np.array([np.count_nonzero(support) for support in supports])
    # Weighted rows count as fewer samples: Kish's effective size (Σw²)² / Σw⁴ of the rows'
    # weights, relative to their number, scales the band-limited count.
    w2 = np.concatenate([np.square(w) for w in design.weights])
    n_effective = n_effective * float(w2.sum()) ** 2 / (w2.size * float(np.sum(w2**2)))
    score = n_effective * np.log(rss / design.n_rows) + n_terms * np.log(n_effective)
    return score, np.zeros_like(score), fits


def _select(
    score: np.ndarray,
    se: np.ndarray,
    n_terms: np.ndarray,
    admissible: Callable[[int], bool],
) -> tuple[int, int, float]:
    """The one-standard-error rule among the admissible candidates.

    Returns the candidate with the fewest parameters (``n_terms``) scoring within one standard
    error of the best admissible one (ties go to the lower score), that best
    one, and the limit on the score. Candidates are checked in the order the
    rule needs them: by score for the best, then by (terms, score) within the
    limit. Without any admissible candidate the rule runs on all of them, with
    a warning.
    """
    by_score = np.argsort(score, kind="stable")
    best = next((int(i) for i in by_score if admissible(int(i))), None)
    if best is None:
        warnings.warn(
            "no candidate model has positive damping over the tested amplitudes and stays "
            "bounded from the records' own states; the selected model is not physically "
            "admissible (is the library missing a damping term?)",
            # _select ← sparse_fit ← _fit_with_offsets ← identify_kinematics ← identify_arrays
            # ← caller
            stacklevel=6,
        )
        best = int(by_score[0])
        limit = float(score[best] + se[best] + 1e-12 * abs(score[best]))
        qualified = np.flatnonzero(score <= limit)
        return int(min(qualified, key=lambda i: (n_terms[i], score[i]))), best, limit
    limit = float(score[best] + se[best] + 1e-12 * abs(score[best]))
    qualified = sorted(np.flatnonzero(score <= limit), key=lambda i: (n_terms[i], score[i]))
    chosen = next(int(i) for i in qualified if admissible(int(i)))
    return chosen, best, limit


def _prune(
    design: Design,
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
