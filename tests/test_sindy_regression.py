"""The regression under SINDy: least squares on Gram matrices, per-group thresholds, folds.

Checked against plain ``numpy.linalg.lstsq`` on the rows themselves and against
coefficients planted in synthetic columns; the identification as a whole is
tested in ``test_sindy.py``.
"""

import numpy as np
import pytest

from identification.effects import CATALOGUE
from identification.measurements.signals import kinematics
from identification.sindy import GROUPS, LibraryTerm, design_matrix
from identification.sindy.design import build_design
from identification.sindy.library import is_dissipative
from identification.sindy.regression import (
    gram_factor,
    group_paths,
    least_squares,
    residual_sum_of_squares,
    stlsq,
)


def augmented_gram(theta, y):
    rows = np.column_stack([theta, y])
    return rows.T @ rows


@pytest.fixture(scope="module")
def planted():
    """Four unit-RMS columns and y = 1·a + 0.05·b + 0.3·c + 0.02·d (no noise)."""
    rng = np.random.default_rng(3)
    theta = rng.standard_normal((2000, 4))
    coefficients = np.array([1.0, 0.05, 0.3, 0.02])
    return theta, theta @ coefficients, coefficients


def test_gram_least_squares_equals_least_squares_on_the_rows():
    rng = np.random.default_rng(0)
    theta = rng.standard_normal((500, 4)) * [1.0, 1e-2, 3.0, 1e2]
    y = theta @ [0.5, -2.0, 1.0, 1e-3] + 0.1 * rng.standard_normal(500)
    gram = augmented_gram(theta, y)
    factor = gram_factor(gram)
    np.testing.assert_allclose(factor.T @ factor, gram, rtol=1e-12, atol=1e-9 * np.abs(gram).max())
    direct = np.linalg.lstsq(theta, y, rcond=None)[0]
    np.testing.assert_allclose(least_squares(factor), direct, rtol=1e-9)
    support = np.array([True, False, True, False])
    on_support = np.linalg.lstsq(theta[:, support], y, rcond=None)[0]
    xi = least_squares(factor, support)
    np.testing.assert_allclose(xi[support], on_support, rtol=1e-9)
    assert np.all(xi[~support] == 0)
    assert residual_sum_of_squares(gram, xi) == pytest.approx(np.sum((y - theta @ xi) ** 2))


def test_semi_definite_gram_still_gives_the_least_squares_fit():
    # A repeated column makes the Gram singular; the factor must still reproduce it.
    rng = np.random.default_rng(1)
    theta = rng.standard_normal((300, 3))
    theta[:, 2] = theta[:, 1]
    y = theta[:, :2] @ [2.0, -1.0]
    gram = augmented_gram(theta, y)
    factor = gram_factor(gram)
    np.testing.assert_allclose(factor.T @ factor, gram, atol=1e-9 * np.abs(gram).max())
    xi = least_squares(factor, np.array([True, True, False]))
    np.testing.assert_allclose(xi, [2.0, -1.0, 0.0], atol=1e-9)


def test_stlsq_thresholds_each_column_on_its_own(planted):
    theta, y, coefficients = planted
    theta, y = theta[:, :2], y - theta[:, 2:] @ coefficients[2:]  # y = 1·a + 0.05·b
    factor = gram_factor(augmented_gram(theta, y))
    on_a_alone = np.linalg.lstsq(theta[:, :1], y, rcond=None)[0][0]
    np.testing.assert_allclose(stlsq(factor, np.array([0.01, 0.01])), [1.0, 0.05], rtol=1e-9)
    # b (0.05) is dropped by its own threshold of 0.1 and kept under 0.01 while a's is 0.1;
    # one shared threshold of 0.1 would drop it in both cases.
    np.testing.assert_allclose(stlsq(factor, np.array([0.01, 0.1])), [on_a_alone, 0.0])
    np.testing.assert_allclose(stlsq(factor, np.array([0.1, 0.01])), [1.0, 0.05], rtol=1e-9)
    # Columns left out take no part.
    only_a = stlsq(factor, np.array([0.01, 0.01]), np.array([True, False]))
    np.testing.assert_allclose(only_a, [on_a_alone, 0.0])


def test_group_paths_drop_the_weakest_term_of_each_group_in_turn(planted):
    theta, y, _ = planted
    dissipative = np.array([False, False, True, True])
    conservative_path, dissipative_path = group_paths(
        gram_factor(augmented_gram(theta, y)), dissipative, 1e-3
    )
    for path, (strong, weak), (weak_value, strong_value) in (
        (conservative_path, (0, 1), (0.05, 1.0)),
        (dissipative_path, (2, 3), (0.02, 0.3)),
    ):
        supports = [set(np.flatnonzero(support)) for _, support in path]
        assert supports == [{strong, weak}, {strong}, set()]
        thresholds = [threshold for threshold, _ in path]
        # Each support holds for thresholds between its weakest kept coefficient and the next.
        assert 1e-3 < thresholds[0] < weak_value < thresholds[1] < strong_value
        assert thresholds == sorted(thresholds)


def test_library_groups_follow_the_parity_in_velocity():
    odd_in_velocity = {
        "viscous_damping", "quadratic_damping", "cubic_damping", "stiffness_damping_coupling",
        "van_der_pol", "coulomb_friction", "stribeck_friction",
    }  # fmt: skip
    for name in CATALOGUE:
        expected = name in odd_in_velocity
        assert is_dissipative(LibraryTerm(name)) == expected, name
    assert GROUPS == ("conservative", "dissipative")


def test_folds_span_every_level_of_a_growing_record():
    # One record whose amplitude grows tenfold: contiguous folds would differ in mean
    # square by two orders of magnitude; folds dealt block by block must not.
    fs, f_hz = 2000.0, 50.0
    t = np.arange(0.0, 40.0, 1 / fs)
    envelope = 1e-3 * (1 + 9 * t / t[-1])
    velocity = envelope * np.cos(2 * np.pi * f_hz * t)
    kin = kinematics(t, velocity, 0.01 * velocity, np.full_like(t, f_hz), fs)
    terms = [LibraryTerm("linear_stiffness"), LibraryTerm("viscous_damping")]
    design = build_design([kin], terms, [None], n_folds=5)
    assert design.n_rows == kin.valid.stop - kin.valid.start
    # Every row lands in exactly one fold.
    rows = np.column_stack(design_matrix(kin, terms))
    np.testing.assert_allclose(
        design.gram * np.outer(design.scale, design.scale), rows.T @ rows, rtol=1e-9
    )
    mean_square = np.array([g[-1, -1] for g in design.fold_grams]) / design.sizes
    assert mean_square.max() / mean_square.min() < 1.2
    assert design.dissipative.tolist() == [False, True]
