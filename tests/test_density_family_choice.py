"""The density's family choice for few curves: the normal unless another family is clearly better.

The margin is calibrated (``bench/family_choice.py``) so that at most 5 % of normal samples
get another family; these tests draw their own samples (seeds of held-out block 3, never
used by the bench) and check the rate against the stated 5 %, two-sided.
"""

import numpy as np
import pytest
from scipy import stats

from pm_joint.distributions import (
    UNBOUNDED_CANDIDATES,
    BackboneDensity,
    choose_family,
    fit_best,
    normal_margin_aicc,
)
from pm_joint.distributions.family_choice import (
    FALSE_CHOICE_RATE,
    MARGIN_BY_N,
    TWO_PARAMETER_UP_TO,
    chosen_fit,
    competitors,
    normal_gap_aicc,
)
from studies.seeds import held_out_block

SEED = held_out_block(3)
#: The candidates that compete with the normal on few samples (the t's fit, a generic
#: optimiser over three parameters, costs a hundred times the others').
FEW = competitors(UNBOUNDED_CANDIDATES, TWO_PARAMETER_UP_TO)


@pytest.mark.parametrize("n", [4, 5, 8, 20])
def test_normal_samples_get_another_family_at_the_stated_rate(n):
    draws = 1000
    rng = np.random.default_rng([SEED, n])
    chosen = [choose_family(rng.standard_normal(n)).family for _ in range(draws)]
    wrong = sum(family != "norm" for family in chosen)
    # Two-sided 99 % binomial bounds of the stated rate: neither more nor far fewer.
    low, high = stats.binom.ppf([0.005, 0.995], draws, FALSE_CHOICE_RATE)
    assert low <= wrong <= high, (n, wrong, low, high)
    # Plain AICc among the same candidates, the choice before the rule, gets another
    # family for most of them.
    plain = sum(
        fit_best(rng.standard_normal(n), FEW, "aicc")[0].family != "norm" for _ in range(100)
    )
    assert plain > 30


def test_only_location_scale_families_compete_up_to_thirty_samples():
    assert "t" not in FEW and {"norm", "logistic", "gumbel_r", "gumbel_l"} <= set(FEW)
    assert competitors(UNBOUNDED_CANDIDATES, TWO_PARAMETER_UP_TO + 1) == UNBOUNDED_CANDIDATES


def test_a_clearly_skewed_large_sample_gets_a_skewed_family():
    x = np.random.default_rng(SEED).gumbel(size=200)
    assert choose_family(x).family == "gumbel_r"
    assert choose_family(-x).family == "gumbel_l"


def test_the_margin_is_a_table_up_to_thirty_samples_and_its_last_entry_beyond():
    assert len(MARGIN_BY_N) == TWO_PARAMETER_UP_TO - 3 and min(MARGIN_BY_N) > 0
    assert normal_margin_aicc(TWO_PARAMETER_UP_TO) == MARGIN_BY_N[-1]
    assert normal_margin_aicc(1000) == MARGIN_BY_N[-1]
    assert normal_margin_aicc(4) == MARGIN_BY_N[0]
    assert normal_margin_aicc(3) == np.inf


def test_three_samples_get_the_normal():
    assert choose_family([1.0, 2.0, 4.5]).family == "norm"


def test_without_a_normal_candidate_the_best_is_taken():
    x = np.random.default_rng(SEED + 1).standard_normal(6)
    ranked = fit_best(x, ("gumbel_r", "gumbel_l"), "aicc")
    assert choose_family(x, ("gumbel_r", "gumbel_l")) == ranked[0]
    with pytest.raises(ValueError, match="no normal fit"):
        chosen_fit(ranked, x.size)


def _columns_a_gumbel_fits_best(n_columns: int, n: int) -> np.ndarray:
    """Normal columns on which plain AICc prefers a Gumbel, by less than 1."""
    rng = np.random.default_rng(SEED + 2)
    columns = []
    while len(columns) < n_columns:
        x = rng.standard_normal(n)
        ranked = fit_best(x, FEW, "aicc")
        if ranked[0].family.startswith("gumbel") and normal_gap_aicc(ranked) < 1.0:
            columns.append(x)
    return np.column_stack(columns)


def test_the_density_records_which_family_each_marginal_got():
    n = 5
    assert normal_margin_aicc(n) > 1.0
    values = 230.0 + _columns_a_gumbel_fits_best(3, n)
    levels = np.array([1e-4, 2e-4, 3e-4])
    ruled = BackboneDensity.fit(values, levels, candidates=FEW)
    plain = BackboneDensity.fit(values, levels, candidates=FEW, prefer_normal=False)
    assert [m.family for m in ruled.marginals] == ["norm"] * 3
    assert all(m.family.startswith("gumbel") for m in plain.marginals)
    assert [m["family"] for m in ruled.to_dict()["marginals"]] == ["norm"] * 3
    # The normal marginals are the columns' maximum-likelihood normals.
    for m, column in zip(ruled.marginals, values.T, strict=True):
        np.testing.assert_allclose(m.params, [column.mean(), column.std()], rtol=1e-12)
