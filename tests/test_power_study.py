"""The oracle test and the power study (issue 25, scope 3).

The fast tests draw campaigns from :func:`studies.campaigns.simulated_campaign` (a harmonic
balance with noise: seconds per campaign); the lab-rig campaign is slow. Expectations are
independent of the code: an obvious effect is found by both tests; under the null the
oracle fires with probability ``α`` (two-sided binomial bounds over fixed seeds); the
80 %-size rule on curves whose crossing is known by hand.
"""

import math

import numpy as np
import pytest

from identification.criticism.criticism import criticize
from identification.criticism.oracle import oracle
from identification.effects import LINEAR_STIFFNESS
from identification.effects.cubic_damping import EFFECT as _CUBIC_DAMPING
from identification.effects.cubic_stiffness import EFFECT as _CUBIC_STIFFNESS
from identification.rig import RIG_PRESETS
from identification.rig.presets import lab_hidden_scenario
from studies import binomial_bounds, simulated_campaign
from studies.power import (
    expected_ratio,
    power_campaign,
    scaled_truth,
    size_at_power,
    wrong_upper,
)

CUBIC_DAMPING, CUBIC_STIFFNESS = _CUBIC_DAMPING.name, _CUBIC_STIFFNESS.name


def _campaign(effect: str, size: float, seed: int, n_curves: int = 3):
    truth, base = scaled_truth(effect, size)
    measured = simulated_campaign(truth, n_curves, seed, levels=8)
    return criticize(base, measured, n_bootstrap=1000, seed=seed)


def test_obvious_effect_is_found_by_search_and_oracle():
    crit = _campaign(CUBIC_STIFFNESS, 0.3, seed=11)
    test = oracle(crit.decision, CUBIC_STIFFNESS)
    assert test.detects and test.p_value < 0.01
    assert crit.missing() and crit.missing()[0].effect == CUBIC_STIFFNESS
    # the oracle's statistic is the search's own gain on the effect's columns
    assert math.isclose(test.gain, crit.decision.effect_gains[CUBIC_STIFFNESS][0], rel_tol=1e-9)
    # testing one effect costs less than searching all: a lower threshold
    assert test.threshold < crit.decision.calibration.catalogue_threshold


def test_a_fired_test_names_the_independent_simulators_effect():
    # Data from the independent simulator (its own forces and balance, no library kernel)
    # hiding a weak cubic stiffness, 0.1× the hidden scenario's (tuning seed 1): before the
    # one calibrated rule this campaign fired (gain above threshold, p ≤ 0.001) and was
    # answered "nothing missing". Where the test fires, the truth must be what is named and
    # the verdict must not be one its test contradicts.
    row = power_campaign("independent", CUBIC_STIFFNESS, 0.1, seed=1)
    assert row.fires and row.oracle_detects
    assert not row.contradicts and row.verdict not in ("nothing missing", "drift")
    assert row.outcome == "named" and CUBIC_STIFFNESS in row.group


def test_oracle_refuses_an_effect_the_model_holds():
    crit = _campaign(CUBIC_STIFFNESS, 0.3, seed=11)
    with pytest.raises(ValueError, match="not a candidate"):
        oracle(crit.decision, LINEAR_STIFFNESS)


def test_size_at_power_interpolates_in_log_size():
    sizes = [1.0, 2.0, 4.0, 8.0]
    # 0.8 lies halfway between 0.6 at 2 and 1.0 at 4: the geometric mid-point √8
    assert math.isclose(size_at_power(sizes, [0.0, 0.6, 1.0, 1.0]), math.sqrt(8.0))
    assert size_at_power(sizes, [0.9, 1.0, 1.0, 1.0]) == 0.0
    assert size_at_power(sizes, [0.0, 0.1, 0.2, 0.5]) == math.inf


def test_wrong_upper_bound_needs_59_campaigns():
    # 0 wrong in n: the one-sided 95 % bound is 1 − 0.05^(1/n); ≤ 5 % from n = 59 (issue 25)
    assert wrong_upper(0, 58) > 0.05 >= wrong_upper(0, 59)
    assert math.isclose(wrong_upper(0, 20), 1 - 0.05 ** (1 / 20))


def test_expected_ratio_of_bonferroni_thresholds():
    # χ²₁ thresholds at α = 1 % and at α/50: the sizes at 80 % power (z_{α/2} + z_0.8 on
    # the score scale, to within the far tail's share) differ by about 1.30
    from scipy import stats

    t_one, t_many = (stats.chi2.isf(a, 1) for a in (0.01, 0.01 / 50))
    z80 = stats.norm.isf(0.2)
    approx = (math.sqrt(t_many) + z80) / (math.sqrt(t_one) + z80)
    assert math.isclose(expected_ratio(t_many, t_one), approx, rel_tol=0.01)


@pytest.mark.slow
def test_oracle_is_calibrated_under_the_null():
    # the base model is the truth's structure: the oracle's test of cubic damping fires
    # with probability α = 0.1 (two-sided 95 % binomial bounds over 40 fixed seeds)
    n, alpha = 40, 0.1
    preset = RIG_PRESETS[lab_hidden_scenario(CUBIC_DAMPING)]
    fired = 0
    for seed in range(n):
        measured = simulated_campaign(preset.base_model, 3, 500 + seed, levels=8)
        crit = criticize(preset.base_model, measured, alpha=alpha, n_bootstrap=500, seed=seed)
        fired += oracle(crit.decision, CUBIC_DAMPING).detects
    low, high = binomial_bounds(n, alpha)
    assert low <= fired <= high


@pytest.mark.slow
def test_lab_campaign_at_an_obvious_size():
    row = power_campaign("lab", CUBIC_STIFFNESS, 0.3, seed=3)
    assert row.outcome == "named" and row.oracle_detects
    assert np.isfinite(row.oracle_threshold) and row.oracle_threshold < row.catalogue_threshold
