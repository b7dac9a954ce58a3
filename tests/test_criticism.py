"""Model criticism: the calibrated decision, locating failures, ranking missing effects,
adequacy and admissibility, groups, the add loop, reports, posterior bands, and the
hidden-effect studies on the virtual rig."""

import dataclasses
import json
from functools import lru_cache

import numpy as np
import pytest
import xarray as xr
from oscillators import measured_curve
from scipy.special import i1

from identification.analytical.harmonic import backbone as harmonic_backbone
from identification.criticism.adequacy import NEARBY_MODE, onset_only
from identification.criticism.config import SEPARATION
from identification.criticism.criticism import Step, criticize, run_rounds
from identification.criticism.directions import base_jacobian
from identification.criticism.plots import plot_history
from identification.effects import jenkins_path
from identification.fitting.prediction import predict_channels
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from identification.rig import (
    HIDDEN_EFFECT_SCENARIOS,
    LAB_HIDDEN_SCENARIOS,
    LAB_NULL_SCENARIOS,
    LAB_OUT_OF_CATALOGUE_SCENARIOS,
)
from pm_joint.analysis.posterior import criticize as criticize_posterior
from studies import KEY_CHANNEL, StudyResult, criticism_study, simulated_campaign
from studies.term_groups import design_chi2

W0 = 2 * np.pi * 101.0
K0 = W0**2
C0 = 2 * 0.003 * W0
AMPS = 1e-3 * np.geomspace(0.05, 2.0, 10)
SCENARIOS = HIDDEN_EFFECT_SCENARIOS


def linear(**extra) -> JointModel:
    return JointModel({"linear_stiffness": K0, "viscous_damping": C0, **extra})


def population(truth: JointModel, n=3, k_spread=0.005, noise_hz=0.003, noise_zeta=1e-6, seed=0):
    """Measured curves: assemblies with a lognormal stiffness spread, single-harmonic
    backbones of the truth (exact for the odd terms used here) plus measurement noise."""
    rng = np.random.default_rng(seed)
    curves = []
    for i in range(n):
        model = truth.replace(linear_stiffness=K0 * np.exp(k_spread * rng.standard_normal()))
        hb = harmonic_backbone(model, AMPS)
        curves.append(measured_curve(hb, rng, noise_hz, noise_zeta, f"assembly{i}"))
    return BackboneSet(curves)


@pytest.fixture(scope="module")
def duffing_data():
    return population(linear(cubic_stiffness=1.4e10))


@pytest.fixture(scope="module")
def linear_criticised(duffing_data):
    return criticize(linear(), duffing_data)


def test_where_locates_the_missing_hardening(linear_criticised):
    """A refitted linear model has one frequency at every level; the measured mean follows
    the cubic shift √(k + ¾k₃a²)/2π, so the residual, less its value at the first level,
    is that closed-form shift less its own; the top levels are under-predicted beyond the
    calibrated bound."""
    crit = linear_criticised
    levels = crit.data.levels_m
    shift = (np.sqrt(K0 + 0.75 * 1.4e10 * levels**2) - W0) / (2 * np.pi)
    residual, se = crit.residual("frequency_hz")
    np.testing.assert_allclose(residual - residual[0], shift - shift[0], rtol=0.01, atol=0.01)
    failures = [f for f in crit.where() if f.channel == "frequency_hz"]
    top = failures[-1]
    assert top.direction == "under-predicted"
    assert top.to_mm == pytest.approx(1e3 * levels[-1])
    assert top.max_residual == pytest.approx(residual[-1], rel=1e-9)
    assert top.max_z > crit.calibration.where_bound
    # every level beyond the bound is in a reported range, and no other
    z = np.abs(residual) / se
    assert z[-1] > crit.calibration.where_bound
    assert top.text.startswith("frequency is under-predicted by up to")


def test_missing_hardening_is_ranked_first_and_the_loop_closes(linear_criticised, duffing_data):
    crit = linear_criticised
    assert crit.significant and crit.verdict == "explained"
    best = crit.missing()[0]
    assert best.effect == "cubic_stiffness" and best.status == "explained"
    assert best.fit.model.coefficient("cubic_stiffness") == pytest.approx(1.4e10, rel=0.02)
    assert best.error_reduction["frequency_hz"] > 0.95
    assert best.gain > crit.threshold and best.delta_chi2 > 100 * crit.threshold
    assert best.share > 0.95 and best.adequate and not best.problems
    assert "hardening" in best.reading and "consistent with" in best.reading
    # the signature of the right effect follows the refitted model's residual
    residual = crit.data.mean_residual(best.base.predicted)
    np.testing.assert_allclose(best.signature["frequency_hz"], residual[:, 0], atol=0.03)
    after = crit.add("cubic_stiffness")
    assert [s.action for s in after.history] == ["start", "+ cubic_stiffness"]
    assert after.history[1].frequency_rmse_hz < 0.05 * after.history[0].frequency_rmse_hz
    assert not after.significant and after.where() == [] and after.verdict == "nothing missing"
    assert "missing: nothing proposed" in after.summary()
    assert [r["verdict"] for r in after.rounds] == ["explained", "nothing missing"]
    assert after.rounds[0]["ranking"][0]["effect"] == "cubic_stiffness"
    # the history carries over to a criticism started by hand
    again = criticize(after.model.replace(cubic_stiffness=1.3e10), duffing_data,
                      history=after.history)  # fmt: skip
    assert [s.action for s in again.history] == ["start", "+ cubic_stiffness", "criticize"]


def test_the_well_specified_model_lacks_nothing(duffing_data):
    crit = criticize(linear(cubic_stiffness=1.4e10), duffing_data)
    assert not crit.significant and crit.missing() == [] and crit.verdict == "nothing missing"
    assert all(c.gain <= crit.threshold for c in crit.candidates)
    assert len(crit.candidates) == 13  # every other catalogue effect was tried
    assert crit.explained_share is None and not crit.unexplained
    text = crit.summary()
    assert f"α = {crit.alpha:g}" in text and f"{crit.n_bootstrap} bootstrap" in text


@pytest.mark.parametrize(
    ("effect", "coefficient", "words"),
    [
        ("coulomb_friction", 0.2, "damping falling with amplitude"),
        ("quadratic_damping", 5.0, "damping rising with amplitude"),
    ],
)
def test_damping_effects_are_found_and_read(effect, coefficient, words):
    data = population(linear(**{effect: coefficient}), noise_zeta=2e-6, seed=1)
    crit = criticize(linear(), data, candidates=["coulomb_friction", "quadratic_damping",
                                                 "cubic_damping", "cubic_stiffness"])  # fmt: skip
    best = crit.missing()[0]
    assert best.effect == effect
    assert words in best.reading
    assert best.error_reduction["damping_ratio"] > 0.9 and best.status == "explained"
    assert any(f.channel == "damping_ratio" for f in crit.where())
    if effect == "coulomb_friction":
        # Stribeck's law fitted to Coulomb data must let its decay velocity grow past
        # every velocity of the test (a start value given by shape)
        stribeck = crit.add("stribeck_friction", v_s=0.3)
        peak_velocity = AMPS.max() * W0
        assert stribeck.model["stribeck_friction"].shape["v_s"] > 3 * peak_velocity
        assert stribeck.fit.damping_rmse < 0.1 * crit.base.damping_rmse
        with pytest.raises(ValueError, match="no shape parameter"):
            crit.add("stribeck_friction", x_s=1.0)


def test_stribeck_friction_is_probed_where_it_acts():
    """Stribeck friction that vanishes within the test (v_s = 0.1 m/s: Coulomb-like at
    0.05 mm, gone above 0.3 mm), on backbones that carry their 2nd and 3rd harmonics (so
    every direction goes through the multi-harmonic balance). A probe sized at the
    effect's default decay velocity and the largest amplitude is 1e11 times too strong
    where the term acts, the balance has no solution there and the effect would have no
    direction at all; each shape's probe is sized where that shape acts, and Stribeck's
    law is found first, beyond Coulomb's."""
    truth = linear(stribeck_friction={"coefficient": 0.3, "v_s": 0.1})
    rng = np.random.default_rng(3)
    curves = []
    for i in range(3):
        model = truth.replace(linear_stiffness=K0 * np.exp(0.005 * rng.standard_normal()))
        hb = harmonic_backbone(model, AMPS, method="multi", harmonics=5)
        ratios = (hb.harmonics_cos_m[:, 2:4] - 1j * hb.harmonics_sin_m[:, 2:4]) / AMPS[:, None]
        noise = 1e-5 * (rng.standard_normal(ratios.shape) + 1j * rng.standard_normal(ratios.shape))
        curve = measured_curve(hb, rng, 0.003, 2e-6, f"assembly{i}")
        curves.append(
            dataclasses.replace(
                curve, harmonics=ratios + noise, harmonic_standard_error=np.full(ratios.shape, 1e-5)
            )
        )
    candidates = ["coulomb_friction", "stribeck_friction", "quadratic_damping"]
    crit = criticize(linear(), BackboneSet(curves), n_bootstrap=500, candidates=candidates)
    assert crit.base.method == "multi"
    stribeck = next(c for c in crit.candidates if c.effect == "stribeck_friction")
    assert stribeck.significant and stribeck.gain > crit.effect_gains["coulomb_friction"][0]
    assert crit.missing()[0].effect == "stribeck_friction", crit.summary()


def test_effects_the_data_cannot_separate_form_a_group():
    """Stribeck's law with its decay velocity far above every velocity of the test is
    Coulomb's: both explain Coulomb data equally, so they form a group (a ranking inside
    it is not a finding) and the report says that nothing near this test separates them;
    ẋ² is not in it (it cancels the viscous term: inadmissible)."""
    data = population(linear(coulomb_friction=0.2), noise_zeta=2e-6, seed=1)
    candidates = ["coulomb_friction", "stribeck_friction", "quadratic_damping"]
    crit = criticize(linear(), data, n_bootstrap=500, candidates=candidates)
    assert crit.verdict == "explained"
    (group,) = crit.groups
    assert set(group.effects) == {"coulomb_friction", "stribeck_friction"}
    assert max(group.separation.values()) < 6.63  # χ²₁ at 1 %: no evidence between them
    assert group.separated_by.startswith("nothing near this test")
    assert "a ranking among them is not a finding" in crit.summary()
    assert "1 ambiguity group" in crit.summary()
    quadratic = next(c for c in crit.candidates if c.effect == "quadratic_damping")
    assert not quadratic.proposed and quadratic.problems
    assert "terms cancel in the equivalent damping" in quadratic.problems[0]


def test_add_refuses_what_it_cannot_add(duffing_data):
    crit = criticize(linear(), duffing_data, candidates=["cubic_stiffness"])
    with pytest.raises(ValueError, match="'viscous_damping' is already in the model"):
        crit.add("viscous_damping")
    with pytest.raises(ValueError, match="unknown effect 'membrane'"):
        crit.add("membrane")
    with pytest.raises(ValueError, match="candidate 'viscous_damping' is already"):
        criticize(linear(), duffing_data, candidates=["viscous_damping"])
    sparse = BackboneSet([Backbone(AMPS[:2], [101.0, 101.1], [0.003, 0.003], label="two")])
    with pytest.raises(ValueError, match="at least 3 are needed"):
        criticize(linear(), sparse)


def test_the_engine_takes_a_model_and_draws_only(duffing_data):
    """The engine imports no PyMC: a posterior comes in through pm_joint's adapter;
    draws come as (names, draws) of the model's parameters; backbones carry the
    harmonics, so records only serve when no backbones are given."""
    tree = xr.DataTree.from_dict({"posterior": xr.Dataset({"cubic_stiffness": (("chain", "draw"),
                                                            np.ones((1, 4)))})})  # fmt: skip
    with pytest.raises(ValueError, match="pm_joint's criticize"):
        criticize(tree, duffing_data)
    with pytest.raises(ValueError, match=r"names \['membrane'\] are not parameters"):
        criticize(linear(), duffing_data, posterior=(["membrane"], np.ones((4, 1))))
    with pytest.raises(ValueError, match=r"must be \(n_draws, 2\)"):
        criticize(linear(), duffing_data, posterior=(["linear_stiffness", "viscous_damping"],
                                                     np.ones((4, 1))))  # fmt: skip
    with pytest.raises(ValueError, match="not both"):
        criticize(linear(), duffing_data, records=[object()])
    with pytest.raises(ValueError, match="give the measured backbones or the records"):
        criticize(linear())
    for module in ("pymc", "arviz", "xarray"):
        assert module not in criticism_engine_imports(), module


def criticism_engine_imports() -> set[str]:
    """Top-level packages the criticism and fitting modules import (from their source)."""
    import ast
    from pathlib import Path

    import identification

    root = Path(identification.__file__).parent
    found = set()
    for path in [*(root / "criticism").glob("*.py"), *(root / "fitting").glob("*.py")]:
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found |= {a.name.split(".")[0] for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                found.add(node.module.split(".")[0])
    return found


def test_report_json_and_figures(linear_criticised, tmp_path):
    first = linear_criticised
    crit = first.add("cubic_stiffness")
    paths = first.write(tmp_path / "report")
    report = json.loads(paths["json"].read_text())
    for key in ("ranking", "significant", "fails_at", "frequency_rmse_hz", "damping_rmse",
                "history", "candidates", "comparison", "groups", "explained_share",
                "unexplained", "threshold", "alpha", "n_bootstrap", "verdict", "rounds",
                "reference"):  # fmt: skip
        assert key in report, key
    top = report["ranking"][0]
    assert top["effect"] == "cubic_stiffness"
    assert set(top) >= {"effect", "error_reduction", "delta_information_criterion", "reading"}
    assert report["significant"] is True and report["fails_at"][0]["channel"] == "frequency_hz"
    assert report["verdict"] == "explained" and report["unexplained"] is False
    assert report["alpha"] == 0.01 and report["n_bootstrap"] == 2000
    assert report["threshold"] == pytest.approx(first.threshold)
    assert len(report["reference"]["k_eq_reference"]) == len(report["amplitude_mm"])
    for name in ("comparison", "signatures", "freeform", "history"):
        assert paths[name].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    second = json.loads(crit.write(tmp_path / "after")["json"].read_text())
    assert len(second["history"]) == 2
    assert [r["verdict"] for r in second["rounds"]] == ["explained", "nothing missing"]
    from matplotlib.figure import Figure

    ax = Figure().subplots()
    plot_history(report["history"] + [s.to_dict() for s in crit.history[1:]], ax)
    assert len(ax.get_xticklabels()) == 2


def test_level_wise_predictions_are_driven_by_the_measured_excitation():
    """lab-distorted (2nd/3rd harmonic of 4 %/3 % in the base acceleration, the lab rig's
    time-domain engine): the truth's structure, refitted, predicts the mean harmonics at
    the comparison levels within two hold-fit standard errors when the level-wise
    prediction is driven by the excitation measured there, as the points' predictions
    are; a pure sine leaves the response's 2nd harmonic more than four standard errors
    unexplained. The linearised directions are driven the same way (the viscous damping
    moves the forced harmonics), and nothing is missing."""
    from identification.fitting.data import HARMONIC_CHANNELS
    from identification.measurements.extraction import extract_backbones
    from identification.rig import RIG_PRESETS, rig_for_preset

    rig = rig_for_preset("lab-distorted", levels=5, noise_m_s=1e-5)
    measured = extract_backbones(record for record, _ in rig.campaign(assemblies=3, seed=0))
    crit = criticize(RIG_PRESETS["lab-distorted"].base_model, measured)
    data = crit.data
    levels = data.levels_m
    forced = crit.predict_at(crit.base.model, levels)
    pure = predict_channels(crit.base.model, levels, data.channels, method="multi")
    # the standard error of the mean harmonics from the hold fits (not the likelihood's floor)
    hold_se = np.sqrt(np.nanmean(data.at_levels(data.standard_error**2), axis=0) / data.n_curves)
    columns = [data.column(c) for c in HARMONIC_CHANNELS]
    mean = np.column_stack([crit.comparison[c]["measured_mean"] for c in HARMONIC_CHANNELS])
    z_forced = (mean - forced[:, columns]) / hold_se[:, columns]
    z_pure = (mean - pure[:, columns]) / hold_se[:, columns]
    assert np.abs(z_forced).max() < 2, z_forced
    assert np.abs(z_pure[:, HARMONIC_CHANNELS.index("harmonic2_sin")]).max() > 4, z_pure
    free = list(crit.base.free)
    driven = base_jacobian(crit.base.model, free, data, "multi", crit.metric)
    unforced = dataclasses.replace(data, excitation_harmonics=None)
    sine = base_jacobian(crit.base.model, free, unforced, "multi", crit.metric)
    harmonic_rows = np.isin(
        np.flatnonzero(crit.metric.keep) % len(data.channels), columns
    )  # the entries of the harmonic channels
    damping = free.index("viscous_damping")
    assert not sine[harmonic_rows, damping].any()
    assert np.abs(driven[harmonic_rows, damping]).max() > 0
    assert crit.verdict == "nothing missing" and not crit.where(), crit.summary()


def test_posterior_band_covers_its_population():
    """Curves drawn from the posterior's own population fall inside its 95 % band;
    a posterior without the hardening does not cover the large amplitudes. The
    covariance is widened by the uncertainty of the population-mean curve (the draws'
    spread over the number of curves), not by the predictive spread."""
    truth = linear(cubic_stiffness=1.4e10)
    data = population(truth, n=8, k_spread=0.003, noise_hz=0.0, seed=5)
    rng = np.random.default_rng(6)
    draws = np.column_stack(
        [K0 * np.exp(0.003 * rng.standard_normal(400)), np.full(400, C0),
         1.4e10 * (1 + 0.01 * rng.standard_normal(400))]
    )  # fmt: skip
    names = ["linear_stiffness", "viscous_damping", "cubic_stiffness"]
    crit = criticize_posterior(truth, data, posterior=(names, draws))
    coverage = crit.comparison["frequency_hz"]["coverage"]
    assert coverage.mean() > 0.8
    assert not any(f.channel == "frequency_hz" for f in crit.where())
    # the widening: the variance of the posterior's mean prediction over the 8 curves
    plain = criticize(truth, data)
    spread = np.var([harmonic_backbone(truth.with_parameters(dict(zip(names, d, strict=True))),
                                       crit.data.levels_m).frequency_hz for d in draws[::4]],
                    axis=0, ddof=1)  # fmt: skip
    added = crit.residual("frequency_hz")[1] ** 2 - plain.residual("frequency_hz")[1] ** 2
    np.testing.assert_allclose(added, spread / 8, rtol=0.3)
    assert (added < 0.2 * spread).all()  # not the predictive spread
    # the same posterior as a DataTree from pm.sample, passed as the model
    posterior = xr.Dataset({n: (("chain", "draw"), d.reshape(2, 200)) for n, d in
                            zip(names, draws.T, strict=True)})  # fmt: skip
    tree = xr.DataTree.from_dict({"posterior": posterior})
    from_tree = criticize_posterior(tree, data)
    assert from_tree.model.effects == truth.effects
    assert from_tree.model.coefficient("cubic_stiffness") == pytest.approx(1.4e10, rel=0.01)
    wrong = criticize_posterior(linear(), data, posterior=(names[:2], draws[:, :2]))
    assert wrong.comparison["frequency_hz"]["coverage"][-1] == 0.0
    assert any(f.channel == "frequency_hz" and f.direction == "under-predicted"
               for f in wrong.where())  # fmt: skip


# --------------------------------------------------------------------------
# Hidden-effect studies on the virtual rig (PLL records, extraction, criticism)


# Bounded: a study keeps its records (about 200 MB), and the 140 slow rows of one run held in
# an unbounded cache took the 24 GB machine out of memory; neighbouring tests still share.
@lru_cache(maxsize=8)
def study(scenario: str, seed: int = 0, start: str = "base"):
    return criticism_study(scenario, seed, start=start, assemblies=3, levels=8)


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_hidden_effect_is_found_first(scenario):
    result = study(scenario)
    row = result.row()
    if not result.hidden:
        assert result.first is None and not result.criticisms[0].significant, row
        return
    assert result.first == result.hidden[0] or result.first in result.hidden, row
    assert sorted(result.added) == sorted(result.hidden), row
    assert result.reduction(KEY_CHANNEL[scenario]) >= 0.8, row
    assert not result.criticisms[-1].significant, row
    steps = result.history
    assert len(steps) == 1 + len(result.hidden)
    assert all(c.verdict in ("explained", "partly explained") for c in result.criticisms[:-1])


def test_microslip_reading_is_specific():
    best = study("hidden-microslip").criticisms[0].missing()[0]
    assert best.effect == "microslip"
    assert "frequency softening" in best.reading
    assert "damping rising" in best.reading and "consistent with partial slip" in best.reading
    # slip from 0.2 mm, tested to 2 mm: the damping's peak and fall are in the data, so a
    # nearby mode is not offered as an alternative (that would be a false ambiguity)
    assert not best.alternative and "nearby mode" not in best.reading, best.reading


def test_quadratic_stiffness_needs_the_records():
    """Backbones alone cannot name x²: its frequency shift is second order in k₂ and ∝ a²
    to leading order, a cubic's (ω² ≈ k + ¾k₃a² − (5/6)k₂²a²/k), so the refitted cubic
    takes most of it. What is left is the design's λ: the start's structure refitted to
    the noise-free truth's backbones (independent of the campaign's noise) misses by
    less than 2 × SEPARATION, while with the records' harmonics it misses by hundreds.
    The recalibrated test may see that rest (issue #25: on this campaign p = 0.0015,
    catalogue gain 6.8 against a threshold of 3.8; before the recalibration the
    threshold was 24.1 for the same gain, p = 0.26, and the test claimed "not
    significant" — a claim about the old draw, not the physics), but it cannot attribute
    it: where it fires, the first proposal is in a group of springs the backbones cannot
    separate, x² among them — never x² named alone, never an effect outside that group.
    The records' second harmonic, which the extracted backbones keep, reveals x²,
    proposed alone and ranked above ẋ², which makes the same harmonic but with the wrong
    amplitude dependence. Seen over seeds of this campaign's recipe: tuning 0 fires (a
    group of four springs holding x²), tuning 1 does not; held-out 1_000_000 and
    1_000_001 do not (p 0.29, 0.37); with the records x² is first and ungrouped on all
    four."""
    result = study("hidden-quadratic")
    blind_data = result.measured.without_harmonics()
    blind = criticize(result.start, blind_data)
    assert design_chi2(blind, result.truth, result.start) < 2 * SEPARATION
    if blind.significant:
        first = blind.missing()[0].effect
        (group,) = [g.effects for g in blind.groups if first in g.effects]
        assert "quadratic_stiffness" in group and len(group) >= 2, blind.summary()
    with_records = result.criticisms[0]
    ranked = [c.effect for c in with_records.candidates]
    assert ranked[0] == "quadratic_stiffness" == with_records.missing()[0].effect
    assert ranked.index("velocity_squared") > 0
    (failure,) = [f for f in with_records.where() if f.channel == "harmonic2"]
    assert failure.direction == "under-predicted" and failure.max_residual > 0.02
    assert not any("quadratic_stiffness" in g.effects for g in with_records.groups)
    assert design_chi2(with_records, result.truth, result.start) > 100 * SEPARATION


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_hidden_effect_study_over_seeds(scenario, seed):
    result = study(scenario, seed)
    assert result.passed, result.row()


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("start", ["linear", "sindy"])
@pytest.mark.parametrize("scenario", LAB_HIDDEN_SCENARIOS)
def test_lab_hidden_effect_from_what_users_start_from(scenario, start, seed):
    """The issue's acceptance: each catalogue effect hidden in a lab-like campaign (3
    assemblies, 8 levels, distortion, ripple, drift, dropouts) is found from a bare
    linear-viscous start and from SINDy's polynomial model: ranked first, or in a
    flagged group that holds it, with only the truth's effects added before, and the
    key channel's error down by 80 % once it is added (or already in the start, and
    then nothing significant is left). A start that lacks it by name but is adequate
    without it passes when a model-term group of the start holds it and the effect in
    place of that term takes the key error down 80 % from the bare linear model's (an
    in-group hit); otherwise it is not judged. Either way the rig's truth must be within
    the where-bound of the refitted start at every level."""
    result = study(scenario, seed, start)
    if result.start_adequate:
        assert result.truth_gap < result.criticisms[0].calibration.where_bound, result.row()
    if result.passed is None:  # start adequate or start term group: not judged
        assert result.truth_gap < result.criticisms[0].calibration.where_bound, result.row()
        return
    assert result.passed, result.row()


# --------------------------------------------------------------------------
# Lab scenarios (identification.rig.rig_for_preset): artefacts are not physics


def test_lab_drift_is_drift_not_physics():
    """Natural frequency +0.2 % within each run, linear in time, levels stepped up then
    down: the branches differ by time, so the verdict is drift, with its rate near the
    preset's 0.2 %·f₀ over a record's duration (the holds carry their times, so the rate
    is per hour), and nothing is proposed as physics."""
    result = study("lab-drift")
    crit = result.criticisms[0]
    assert crit.verdict == "drift" and not crit.missing(), crit.summary()
    (frequency,) = [d for d in crit.drift if d.channel == "frequency_hz" and d.significant]
    f0 = np.sqrt(result.truth.coefficient("linear_stiffness")) / (2 * np.pi)
    record_hours = np.mean([r.time_s[-1] - r.time_s[0] for r in result.records]) / 3600
    assert frequency.time_unit == "hour"
    assert frequency.rate == pytest.approx(0.002 * f0 / record_hours, rel=0.2)
    assert "drift, not joint physics" in crit.summary()


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("scenario", LAB_NULL_SCENARIOS)
def test_lab_null_scenarios_find_nothing(scenario, seed):
    result = study(scenario, seed)
    assert result.passed and not result.false_discovery, result.row()


@pytest.mark.slow
@pytest.mark.parametrize("start", ["base", "sindy"])
@pytest.mark.parametrize("scenario", LAB_OUT_OF_CATALOGUE_SCENARIOS)
def test_out_of_catalogue_physics_is_not_explained_as_physics(scenario, start):
    """From the truth's catalogue part and from SINDy's polynomial model: "not explained by
    the catalogue" or "partly explained", and no inadmissible fit proposed."""
    result = study(scenario, 0, start)
    crit = result.criticisms[0]
    assert crit.verdict in ("not explained by the catalogue", "partly explained"), crit.summary()
    assert all(not c.problems for c in crit.missing())


# --------------------------------------------------------------------------
# What one sensor cannot tell apart, and a start that already reproduces the effect


def test_a_slip_fit_is_identified_only_past_its_damping_peak():
    """The premise of ``onset_only``, from the element's own hysteresis loop (time domain,
    not the catalogue's describing function): a Jenkins element's dissipated energy per
    cycle over a², i.e. its added damping ratio, peaks at twice the slip amplitude
    (4 F_s (a − a_s)/a² is largest at 2 a_s). The rule fires exactly when the test stops
    below that peak."""
    k_t, slip = 3e3, 1e-3
    amplitudes = slip * np.linspace(1.05, 4.0, 60)
    theta = np.linspace(0, 4 * np.pi, 8001)
    loss = []
    for a in amplitudes:
        x = a * np.sin(theta)
        force = jenkins_path(x, k_t, k_t * slip)
        half = theta.size // 2  # the second cycle: the loop is closed
        loss.append(np.trapezoid(force[half:], x[half:]) / a**2)
    peak = amplitudes[int(np.argmax(loss))]
    assert peak == pytest.approx(2 * slip, rel=0.03)
    model = linear(microslip={"coefficient": 1.0, "k_t": k_t, "F_s": k_t * slip})
    below = onset_only(model, 1e-3 * np.geomspace(0.05, 1.5, 8))
    assert below is not None and "onset of slip" in below and "2 mm" in below
    assert onset_only(model, 1e-3 * np.geomspace(0.05, 2.5, 8)) is None
    assert onset_only(linear(cubic_stiffness=1.4e10), AMPS) is None


def test_a_second_mode_is_not_explained_as_microslip():
    """The rig's ground truth: cubic hardening and a second mode 5 % above the first, no
    slip. The catalogue's Jenkins element fits the damping that rises at the top of the
    range (slip from about 0.9 mm, tested to 1.4 mm), which is only its onset, so the
    verdict is not "explained": microslip and a nearby mode form a group, and the reading
    says what would separate them; the mode's routes fitted together beat microslip, so
    the verdict names the mode (#27). (Seed 1 was "explained by microslip" before.)"""
    result = study("lab-second-mode", 1)
    assert "microslip" not in result.truth
    crit = result.criticisms[0]
    assert crit.verdict == "explained by a second mode" and crit.unexplained, crit.summary()
    best = crit.missing()[0]
    assert best.effect == "microslip" and best.status == "partly explained"
    assert "nearby mode" in best.reading and "second response point" in best.alternative
    assert any(set(g.effects) == {"microslip", NEARBY_MODE} for g in crit.groups)
    report = crit.to_dict()
    assert report["ranking"][0]["alternative"] == best.alternative
    assert "a second mode" in report["verdict_text"]


def _exponential_campaign():
    """An exponential spring c(e^{x/x_s} − 1) with x_s = 5 mm hidden in a linear joint
    (its stiffness at rest taken out of the linear one, as the rig's presets do), and
    the describing function's expansion 2 I₁(z)/a = (1 + z²/8 + z⁴/192 + …)/x_s."""
    x_s, share = 5e-3, 0.2
    c = share * K0 * x_s
    truth = linear(linear_stiffness=K0 - c / x_s, exponential={"coefficient": c, "x_s": x_s})
    z = AMPS / x_s
    k_eq = K0 - c / x_s + c * 2 * i1(z) / AMPS
    cubic = K0 + c / x_s * z**2 / 8  # what x³ gives: ¾ k₃ a² with k₃ = c/(6 x_s³)
    hz = lambda k: np.sqrt(k) / (2 * np.pi)  # noqa: E731
    return truth, population(truth, seed=4), hz(k_eq) - hz(cubic), hz(cubic) - hz(K0)


def test_a_start_that_reproduces_the_hidden_effect_is_start_adequate():
    """Ground truth: beyond x³ the exponential's describing function moves the frequency
    by ≤ 0.003 Hz over the test (the measurement noise), while x³ itself moves it by
    0.2 Hz. A start with x² and x³ (SINDy's polynomial) is adequate by the criticism's
    own test; its x³ is grouped with the exponential (a model-term group: the data need
    the term and cannot tell it from the exponential), so the study counts the row apart
    ("start term group": not a hit, not judged); a bare linear start is not adequate."""
    truth, measured, beyond_cubic, cubic_shift = _exponential_campaign()
    assert np.abs(beyond_cubic).max() < 0.003 < 0.1 < cubic_shift.max()
    polynomial = linear(quadratic_stiffness=0.0, cubic_stiffness=1e9)
    crit = criticize(polynomial, measured)
    assert crit.adequate and crit.beyond_scatter == (), crit.summary()
    assert crit.to_dict()["adequate"] is True and crit.missing() == []
    (group,) = crit.term_groups
    assert group.term == "cubic_stiffness" and "exponential" in group.alternatives
    assert abs(group.separation["exponential"]) < 6.63  # χ²₁ at 1 %: they cannot be told apart
    assert crit.swap_term() is None  # nothing to prefer: the loop keeps the start's x³
    row = StudyResult("lab-hidden-exponential", 0, "sindy", truth, ("exponential",), measured,
                      [], polynomial, [crit])  # fmt: skip
    assert not row.in_start and row.start_adequate
    assert row.term_group == {"exponential": "cubic_stiffness"}
    assert row.term_reduction("frequency_hz") >= 0.8 and row.passed is None
    assert row.outcome == "start term group" == row.row()["outcome"]
    bare = criticize(linear(), measured)
    assert not bare.adequate and "frequency_hz" in bare.beyond_scatter, bare.summary()
    assert not StudyResult("lab-hidden-exponential", 0, "linear", truth, ("exponential",),
                           measured, [], linear(), [bare]).start_adequate  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(3))
def test_lab_exponential_from_sindy_is_start_adequate(seed):
    """The lab study's rows: SINDy's x³ and ẋ² reproduce the hidden exponential on
    these campaigns (and the criticism groups one of them with it), checked against the
    rig's truth: the shape of the start's backbone
    and of the truth's (multi-harmonic balance, no rig; each less its value at the lowest level,
    as assemblies differ in their offset) differ by less than two standard errors of the
    measured mean at every level."""
    result = study("lab-hidden-exponential", seed, "sindy")
    assert result.start_adequate, result.row()
    # one of the start's terms is grouped with the exponential: counted apart, not a hit
    assert result.outcome == "start term group", result.row()
    crit = result.criticisms[0]
    levels = crit.data.levels_m
    # harmonics 0..5: the exponential's even part moves the frequency through the mean and
    # the 2nd harmonic, which a single-harmonic balance leaves out (0.4 Hz at 1.9 mm)
    truth = harmonic_backbone(result.truth, levels, method="multi").frequency_hz
    start = harmonic_backbone(crit.base.model, levels, method="multi").frequency_hz
    _, se = crit.residual("frequency_hz")
    shape = (truth - truth[0]) - (start - start[0])
    assert np.all(np.abs(shape) < 2 * se), (shape, se)
    assert result.truth_gap < 2, result.row()  # every channel, the study's own figure


@pytest.mark.parametrize(("onset_mm", "identified"), [(0.2, True), (0.9, False)])
def test_true_slip_is_identified_only_when_the_test_passes_its_damping_peak(onset_mm, identified):
    """The trade-off of the onset rule, on true slip (harmonic-balance campaigns of cubic
    hardening plus a Jenkins element carrying 3 % of the stiffness, tested to 1.5 mm):
    slip from 0.2 mm peaks in damping at 0.4 mm, inside the test, and is explained; slip
    from 0.9 mm peaks at 1.8 mm, beyond it, and is grouped with a nearby mode although it
    is slip — the data hold only its onset."""
    k_t = 0.03 * K0
    slip = {"coefficient": 1.0, "k_t": k_t, "F_s": k_t * 1e-3 * onset_mm}
    truth = linear(linear_stiffness=K0 - k_t, cubic_stiffness=1.4e10, microslip=slip)
    measured = simulated_campaign(truth, 3, seed=1, levels=8, amplitude_range_mm=(0.05, 1.5))
    crit = criticize(linear(cubic_stiffness=1.4e10), measured)
    assert crit.missing()[0].effect == "microslip", crit.summary()
    nearby = any(NEARBY_MODE in g.effects for g in crit.groups)
    assert (crit.verdict == "explained") == identified and nearby != identified, crit.summary()


@pytest.mark.heavy
def test_the_swap_step_replaces_a_stand_in_the_greedy_step_took():
    """Two effects missing from a linear start: van der Pol damping x²ẋ and a softening
    x|x| spring (the truth the curves are simulated from). Alone, a Jenkins slip element
    mimics both (softening and damping rising with amplitude), so the greedy step takes it
    first; once x|x| is in, van der Pol fits the damping far better than the slip element
    does, and the swap step puts it in its place. The last model is the truth's structure
    with its coefficients, and the round's entry records the swap."""
    truth = linear(van_der_pol=7.5e6, abs_stiffness=-4.8e7)
    chain = run_rounds(criticize(linear(), population(truth)), 3)
    assert chain[0].missing()[0].effect == "microslip"  # greedy's first pick: a stand-in
    last = chain[-1]
    assert sorted(last.base.model.effects) == sorted(truth.effects)
    for effect in ("van_der_pol", "abs_stiffness"):
        assert last.base.model.coefficient(effect) == pytest.approx(
            truth.coefficient(effect), rel=0.02
        )
    assert not last.significant and last.verdict == "nothing missing"
    rounds = json.loads(last.to_json())["rounds"]
    assert [r["action"] for r in rounds] == [
        "start", "+ microslip", "+ abs_stiffness; swap − microslip + van_der_pol",
    ]  # fmt: skip
    assert [s.action for s in last.history] == [r["action"] for r in rounds]
    # what each step added and removed, recorded structurally (the study reads it there)
    assert [s.added for s in last.history] == [(), ("microslip",), ("abs_stiffness", "van_der_pol")]
    assert [s.removed for s in last.history] == [(), (), ("microslip",)]
    assert [s["added"] for s in json.loads(last.to_json())["history"]] == [
        [], ["microslip"], ["abs_stiffness", "van_der_pol"],
    ]  # fmt: skip
    row = StudyResult("lab-hidden-van-der-pol", 0, "linear", truth, ("van_der_pol",), None, [],
                      chain[0].model, chain)  # fmt: skip
    assert row.added == ["microslip", "abs_stiffness", "van_der_pol"]
    older = {k: v for k, v in last.history[-1].to_dict().items() if k not in ("added", "removed")}
    assert Step.from_dict(older).added == ()  # a step written before they were recorded
    assert Step.from_dict(last.history[-1].to_dict()) == last.history[-1]
    (kept,) = [s for s in rounds[2]["swaps"] if s["kept"]]
    assert kept["remove"] == "microslip" and kept["add"] == "van_der_pol"
    assert kept["delta_chi2"] > 6.63  # the data tell them apart (χ²₁, 1 %)
    assert all({"significant", "ranking", "groups", "swaps"} <= set(r) for r in rounds)


def test_results_print_as_short_readable_summaries(linear_criticised, capsys):
    """``print(crit.missing())`` prints ranked catalogue effects with ΔBIC and a physical
    reading (the arrays stay behind the attributes); a criticism's repr says its model
    and, once decided, its verdict; a candidate not refitted is one line."""
    crit = linear_criticised
    print(crit.missing())
    out = capsys.readouterr().out
    assert out.startswith("[<Candidate cubic_stiffness: explained, ΔBIC -")
    assert "hardening" in out and "array(" not in out and "FitResult" not in out
    assert len(out.splitlines()) <= 2 * len(crit.missing())
    text = repr(crit)
    assert text.startswith("<Criticism of ẍ") and "explained by cubic_stiffness" in text
    assert "\n" not in text and "array(" not in text
    (quiet,) = [c for c in crit.candidates[-1:] if c.fit is None]
    assert repr(quiet).startswith(f"<Candidate {quiet.effect}: ") and "\n" not in repr(quiet)
    assert str(crit.where()[0]) == crit.where()[0].text
