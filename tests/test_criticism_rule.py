"""The criticism's rule: the calibrated decision alone says whether something is missing;
``where()`` says where, and a finding no single level shows reads "small".

The campaigns are built here, by hand, from the closed form of a linear joint's backbone
(constant frequency and damping ratio) plus a stated bias, so that what the statistics
must give is known analytically rather than taken from the code under test.
"""

import json

import numpy as np

from identification.criticism.config import VERDICTS, Verdict
from identification.criticism.criticism import criticize
from identification.criticism.words import SMALL
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from studies import binomial_bounds

W0 = 2 * np.pi * 101.0
LINEAR = JointModel({"linear_stiffness": W0**2, "viscous_damping": 2 * 0.003 * W0})
CUBIC = "cubic_stiffness"
#: Twenty levels over one octave: a cubic stiffness's frequency shift (∝ a²) spread over
#: every level, with no level far ahead of the others once the linear stiffness is refitted.
LEVELS_M = 1e-3 * np.geomspace(1.0, 2.0, 20)
FREQUENCY_SD_HZ, DAMPING_SD = 0.003, 3e-5
#: Systematic floors switched off: the bootstrap alone calibrates the rule.
NO_FLOOR = {"frequency_hz": 1e-6, "damping_ratio": 1e-9, "harmonics": 1e-7}


def _designed_noise(n_curves: int, n_columns: int, seed: int) -> np.ndarray:
    """``(n_curves, n_columns)`` deviations whose sample mean is exactly 0, sample standard
    deviation exactly 1 and sample correlations exactly 0 (orthonormal columns orthogonal to
    the ones-vector): the estimated covariance of the mean is then exactly diagonal."""
    rng = np.random.default_rng(seed)
    basis, _ = np.linalg.qr(
        np.column_stack([np.ones(n_curves), rng.standard_normal((n_curves, n_columns))])
    )
    return basis[:, 1:] * np.sqrt(n_curves - 1)


def _shape() -> np.ndarray:
    """The bias's shape after the linear stiffness is refitted (a², its mean removed)."""
    a2 = LEVELS_M**2
    return a2 - a2.mean()


def small_trend_campaign(gain: float, n_curves: int = 41, seed: int = 0) -> BackboneSet:
    """Curves of a linear joint whose population mean carries a cubic stiffness's frequency
    shift (∝ a²) sized so that, with the constant a linear stiffness absorbs removed, its
    ``χ²`` is ``gain``: ``|b⊥|² / SE² = gain`` with ``SE = σ/√n`` (the deviations are
    designed, so the mean curve is exactly the bias and the covariance exactly σ²/n)."""
    se = FREQUENCY_SD_HZ / np.sqrt(n_curves)
    bias = np.sqrt(gain) * se * LEVELS_M**2 / np.linalg.norm(_shape())
    noise = _designed_noise(n_curves, 2 * LEVELS_M.size, seed)
    f = 101.0 + bias + FREQUENCY_SD_HZ * noise[:, : LEVELS_M.size]
    z = 0.003 + DAMPING_SD * noise[:, LEVELS_M.size :]
    return BackboneSet([Backbone(LEVELS_M, f[i], z[i], label=f"c{i}") for i in range(n_curves)])


def test_a_small_trend_over_many_levels_is_missing_though_no_level_shows_it():
    """A bias of about one standard error at each of 20 levels: the cubic column's gain is
    the trend's whole χ², 20 (it is the column's own shape), far beyond the one-column
    threshold (≈ χ²₁'s 1 % quantile, 6.6), while the largest standardised residual is
    max|b⊥|/|b⊥|·√20 ≈ 2, within the where-bound of 40 entries (above 3.66). The
    decision fires, ``where()`` is empty, and the verdict says something is missing, small."""
    gain = 20.0
    crit = criticize(
        LINEAR, small_trend_campaign(gain), candidates=[CUBIC], noise_floor=NO_FLOOR,
        n_bootstrap=1000,
    )  # fmt: skip
    shape = _shape()
    assert 0.9 * gain < crit.observed.catalogue[0] <= 1.01 * gain, crit.summary()
    peak = np.sqrt(gain) * np.abs(shape).max() / np.linalg.norm(shape)
    assert np.nanmax(np.abs(crit.decision.standardised)) < 1.1 * peak < 3.0, crit.summary()
    # one column: about χ²₁'s 1 % quantile; 40 entries: above the 99 % quantile of the
    # largest of 40 independent |N(0, 1)|, 3.66 (a re-estimated covariance widens both)
    assert crit.calibration.catalogue_threshold < gain / 2
    assert crit.calibration.where_bound > 3.3
    assert crit.fires["catalogue"] and crit.significant and crit.where() == [], crit.summary()
    assert crit.small and crit.verdict != Verdict.NOTHING_MISSING
    assert crit.verdict == Verdict.EXPLAINED and crit.missing()[0].effect == CUBIC
    assert crit.verdict_text.endswith(SMALL) and "small" in crit.verdict_text
    assert "fails: at no single level beyond the scatter" in crit.summary()
    report = json.loads(crit.to_json())
    assert report["small"] is True and report["significant"] is True
    assert report["verdict"] == "explained" and type(report["verdict"]) is str


def test_without_the_trend_the_same_campaign_has_nothing_missing():
    crit = criticize(
        LINEAR, small_trend_campaign(0.0), candidates=[CUBIC], noise_floor=NO_FLOOR,
        n_bootstrap=1000,
    )  # fmt: skip
    assert crit.observed.catalogue[0] < 1e-3 and not crit.significant, crit.summary()
    assert crit.verdict == Verdict.NOTHING_MISSING and not crit.small
    assert crit.verdict_text == "nothing missing beyond the scatter"


def test_null_campaigns_answer_nothing_missing_at_the_calibrated_rate():
    """No bias, random scatter (8 curves, the whole catalogue, floors off so the bootstrap
    alone calibrates): "nothing missing" unless the calibrated decision fires, which at
    α = 0.01 it does on at most 2 of 40 campaigns unless the rule is anti-conservative
    (Binomial(40, 0.01)'s 99 % quantile; P(X ≥ 3) = 0.8 %). The verdict is never "nothing
    missing" where the decision fires."""
    fired = 0
    for seed in range(40):
        rng = np.random.default_rng(seed)
        curves = [
            Backbone(
                LEVELS_M,
                101.0 + FREQUENCY_SD_HZ * rng.standard_normal(LEVELS_M.size),
                0.003 + DAMPING_SD * rng.standard_normal(LEVELS_M.size),
                label=f"c{i}",
            )
            for i in range(8)
        ]
        crit = criticize(LINEAR, BackboneSet(curves), noise_floor=NO_FLOOR, n_bootstrap=500,
                         seed=seed)  # fmt: skip
        quiet = crit.verdict in (Verdict.NOTHING_MISSING, Verdict.DRIFT)
        assert quiet == (not crit.significant), crit.summary()
        fired += crit.significant
    assert fired <= binomial_bounds(40, 0.01, level=0.98)[1] == 2


def test_the_verdicts_are_one_list_written_as_plain_strings():
    assert [str(v) for v in VERDICTS] == [
        "nothing missing", "drift", "explained", "partly explained",
        "not explained by the catalogue", "explained by a second mode",
    ]  # fmt: skip
    assert Verdict("partly explained") is Verdict.PARTLY_EXPLAINED
    assert json.dumps(Verdict.NOT_EXPLAINED) == '"not explained by the catalogue"'


def test_the_report_says_a_finding_is_small(tmp_path):
    from pm_joint.html import criticism_section

    summary = "model: m\nfails: at no single level beyond the scatter\nverdict: v"
    round_ = {"action": "start", "verdict": "explained", "summary": summary,
              "verdict_text": f"explained by cubic_stiffness; {SMALL}", "significant": True,
              "small": True, "ranking": []}  # fmt: skip
    record = {"significant": True, "small": True, "equation": "m", "fails_at": [],
              "history": [], "rounds": [round_]}  # fmt: skip
    first, final = criticism_section(record, tmp_path / "c", tmp_path).text.split("\n\n")
    assert first.endswith(f"{SMALL}. Where it fails: at no single level beyond the scatter.")
    assert final == (
        "The final model, m: Something significant is missing. It is small: seen in the trend "
        "over the levels, within the scatter at each. Where it fails: at no single level beyond "
        "the scatter."
    )
