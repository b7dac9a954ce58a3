"""The covariance of the mean curve: shrinkage of the between-curve covariance and the
one-curve noise estimate, checked against covariances and noise levels put in."""

import numpy as np
import pytest

from identification.fitting.covariance import (
    LevelCovariance,
    estimate,
    gasser_noise_variance,
    shrunk_covariance,
)

LEVELS, CHANNELS = 8, 2
P = LEVELS * CHANNELS
CHANNEL_OF = np.tile(np.arange(CHANNELS), LEVELS)


def truth_covariance() -> np.ndarray:
    """Assembly offsets: strongly correlated along the levels (AR(1), ρ = 0.9), the two
    channels weakly coupled, heteroscedastic along the levels."""
    levels = np.arange(LEVELS)
    along = 0.9 ** np.abs(levels[:, None] - levels[None, :])
    across = np.array([[1.0, 0.3], [0.3, 1.0]])
    sd = np.concatenate([[1.0 + 0.2 * k, 1e-2 * (1 + 0.1 * k)] for k in levels])
    return np.kron(along, across) * sd[:, None] * sd[None, :]


def draw(covariance, n, batch, seed=0):
    rng = np.random.default_rng(seed)
    return rng.standard_normal((batch, n, P)) @ np.linalg.cholesky(covariance).T


def test_many_curves_recover_the_covariance_with_little_shrinkage():
    truth = truth_covariance()
    estimated, lam_r, lam_v = shrunk_covariance(draw(truth, 2000, 1), CHANNEL_OF, np.zeros(P))
    assert lam_r[0] < 0.05 and lam_v[0] < 0.2
    scale = np.sqrt(np.outer(np.diag(truth), np.diag(truth)))
    assert np.abs(estimated[0] - truth).max() < 0.1 * scale.max()
    assert (np.abs(estimated[0] - truth) / scale).max() < 0.1


def correlations(covariances: np.ndarray) -> np.ndarray:
    sd = np.sqrt(np.einsum("bii->bi", covariances))
    return covariances / sd[:, :, None] / sd[:, None, :]


def test_few_curves_keep_the_correlation_along_the_levels_and_only_that():
    """Five curves (200 campaigns): of independent noise, the estimated correlations stay
    near zero; of assembly offsets (AR(1) ρ = 0.9 along the levels, 0.3 between the
    channels), the estimate keeps the correlation along the levels: lag-1 near 0.9 (the
    stationary target tapers it by (L − 1)/L = 7/8: 0.79; a target of zero correlation
    kept about a third of it); between channels, not pooled, it shrinks toward zero.
    Positive definite."""
    independent = np.diag(np.diag(truth_covariance()))
    estimated, _, _ = shrunk_covariance(draw(independent, 5, 200, seed=1), CHANNEL_OF,
                                        np.zeros(P))  # fmt: skip
    r = correlations(estimated)
    off = ~np.eye(P, dtype=bool)
    assert np.abs(r[:, off].mean()) < 0.03 and np.abs(r[:, off]).mean() < 0.15
    correlated, _, _ = shrunk_covariance(draw(truth_covariance(), 5, 200, seed=1),
                                         CHANNEL_OF, np.zeros(P))  # fmt: skip
    r = correlations(correlated)
    levels = np.arange(LEVELS - 1) * CHANNELS
    lag1 = np.mean([r[:, i + c, i + CHANNELS + c] for i in levels for c in range(CHANNELS)])
    across = np.mean([r[:, i, i + 1] for i in np.arange(LEVELS) * CHANNELS])
    assert 0.7 < lag1 < 0.9, lag1
    assert 0.0 < across < 0.3, across
    for matrix in (*estimated[:5], *correlated[:5]):
        np.linalg.cholesky(matrix)


def test_two_curves_give_a_diagonal_and_floors_hold():
    estimated, lam_r, _ = shrunk_covariance(draw(truth_covariance(), 2, 3), CHANNEL_OF,
                                            np.full(P, 4.0))  # fmt: skip
    np.testing.assert_array_equal(lam_r, 1.0)
    for matrix in estimated:
        np.testing.assert_array_equal(matrix - np.diag(np.diag(matrix)), 0.0)
        assert (np.diag(matrix) >= 4.0).all()


def test_pseudo_residuals_estimate_white_noise_on_a_smooth_curve():
    """Uneven positions, a curved trend, noise σ = 0.01: the mean estimate over many curves is
    σ² to within a few per cent (curvature adds a little, never subtracts)."""
    rng = np.random.default_rng(2)
    x = np.sort(rng.uniform(0, 3, 12))
    trend = np.stack([0.05 * np.sin(x / 2), 0.01 * x**2], axis=1)
    values = trend + 0.01 * rng.standard_normal((4000, 12, 2))
    variance = gasser_noise_variance(values, x).mean(axis=0)
    np.testing.assert_allclose(variance, 1e-4, rtol=0.05)
    assert (variance > 0.98e-4).all()


def test_one_curve_gives_its_own_noise_and_the_mean_covariance_adds_the_floor():
    rng = np.random.default_rng(3)
    x = np.log(np.geomspace(5e-5, 2e-3, LEVELS))
    curve = np.column_stack([101 + 0.5 * x, 0.003 + 0 * x]) + rng.standard_normal(
        (LEVELS, 2)) * [0.01, 1e-5]  # fmt: skip
    per_curve, lam_r, _ = estimate(curve.reshape(1, 1, P), CHANNEL_OF, x, np.zeros(P))
    assert np.isnan(lam_r[0])
    diagonal = np.diag(per_curve[0]).reshape(LEVELS, 2)
    assert np.allclose(diagonal, diagonal[0]) and 1e-5 < diagonal[0, 0] < 1e-3
    covariance = LevelCovariance(per_curve[0], np.full(P, 1e-6), 1, np.nan, np.nan, "within-curve")
    np.testing.assert_allclose(np.diag(covariance.mean), np.diag(per_curve[0]) + 1e-6)
    z = covariance.whiten(np.ones(P))
    assert z @ z == pytest.approx(np.ones(P) @ np.linalg.solve(covariance.mean, np.ones(P)))
