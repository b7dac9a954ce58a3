"""Thresholded least squares of the scaled library, on Gram matrices.

**pysindy's optimisers, not** ``ps.SINDy``. Fitting ``SINDy`` on the state
``(x, ẋ)`` with ``u = a_base`` would also identify the kinematic row ``ẋ = v``
and a free gain on ``u``, while the model fixes that gain to one; and the
Jenkins (``microslip``) feature needs the whole displacement path, which a
``CustomLibrary`` only sees sample by sample when simulating. So the library
matrix is built from the catalogue (:mod:`.library`) and the sparse regression
is ``pysindy.STLSQ`` (:func:`stlsq`, :func:`group_paths`), with
``pysindy.EnsembleOptimizer`` for bagging (:func:`bagged_coefficients`).

**Gram matrices.** Any least-squares fit on a subset of the columns of
``[Θ | y]`` needs only the Gram matrix ``G = [Θ | y]ᵀ[Θ | y]`` (size
``n_terms + 1``): a square ``R`` with ``RᵀR = G`` (:func:`gram_factor`) gives the
same solutions and residuals as the rows themselves. Every time block is reduced
to its Gram once (one BLAS product, :mod:`.design`), and the threshold paths,
the cross-validation and STLSQ run on these small matrices.

**Two groups, two thresholds.** Conservative and dissipative columns
(:data:`.library.GROUPS`) are each thresholded against their own group's force
(:func:`group_force`), so every function here takes one threshold per column.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager

import numpy as np
import pysindy as ps

#: Smallest group force (fraction of max|y|) a group share is measured against.
GROUP_FLOOR = 1e-3


def gram_factor(gram: np.ndarray) -> np.ndarray:
    """Square ``R`` with ``RᵀR = gram`` (Cholesky; eigen-decomposition if semi-definite)."""
    try:
        return np.linalg.cholesky(gram).T
    except np.linalg.LinAlgError:
        values, vectors = np.linalg.eigh(gram)
        return np.sqrt(np.clip(values, 0.0, None))[:, None] * vectors.T


def residual_sum_of_squares(gram: np.ndarray, xi: np.ndarray) -> float:
    """Residual sum of squares of ``y − Θ ξ`` from the augmented Gram."""
    z = np.append(-xi, 1.0)
    return float(z @ gram @ z)


def least_squares(factor: np.ndarray, support: np.ndarray | None = None) -> np.ndarray:
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


def stlsq(
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


def group_paths(
    factor: np.ndarray, dissipative: np.ndarray, min_threshold: float
) -> list[list[tuple[float, np.ndarray]]]:
    """Per group (:data:`.library.GROUPS`), the nested supports along its STLSQ threshold path.

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
            xi = stlsq(factor, np.where(members, lam, min_threshold), active)
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


def group_force(
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
    xi = least_squares(gram_factor(gram))
    force = np.empty(dissipative.size)
    for members in (~dissipative, dissipative):
        if members.any():
            weights = xi[members] / peak[:-1][members]
            top = max(float(np.max(np.abs(weights @ r[:-1][members]))) for r in rows)
            force[members] = max(top, GROUP_FLOOR)
    return force


@contextmanager
def _numpy_seed(seed: int) -> Iterator[None]:
    # pysindy's bagging draws from numpy's global generator: seed it, then restore.
    state = np.random.get_state()  # noqa: NPY002
    np.random.seed(seed)  # noqa: NPY002
    try:
        yield
    finally:
        np.random.set_state(state)  # noqa: NPY002


def bagged_coefficients(
    theta_n: np.ndarray, y_n: np.ndarray, thresholds: np.ndarray, n_models: int, seed: int
) -> np.ndarray:
    """``(n_models, n_terms)`` normalised coefficients of bagged STLSQ fits.

    ``theta_n`` and ``y_n`` are the scaled columns and target (samples in rows);
    ``thresholds`` has one entry per column.
    """
    inner, ratio = _stlsq_optimizer(theta_n, thresholds)
    optimizer = ps.EnsembleOptimizer(inner, bagging=True, n_models=n_models)
    with _numpy_seed(seed), _quiet_stlsq():
        optimizer.fit(theta_n * ratio, y_n)
    return np.array(optimizer.coef_list)[:, 0, :] * ratio
