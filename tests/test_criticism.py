"""Model criticism: locating failures, ranking missing effects, the add loop, reports,
posterior bands, and the hidden-effect studies on the virtual rig."""

import json
from functools import cache

import numpy as np
import pytest
import xarray as xr

from identification.analytical.harmonic import backbone as harmonic_backbone
from identification.criticism.criticism import criticize
from identification.criticism.plots import plot_history
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from identification.rig import HIDDEN_EFFECT_SCENARIOS
from pm_joint.analysis.posterior import criticize as criticize_posterior
from pm_joint.studies import KEY_CHANNEL, hidden_effect_study

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
        curves.append(
            Backbone(
                hb.amplitude_m,
                hb.frequency_hz + noise_hz * rng.standard_normal(AMPS.size),
                hb.damping_ratio + noise_zeta * rng.standard_normal(AMPS.size),
                label=f"assembly{i}",
            )
        )
    return BackboneSet(curves)


@pytest.fixture(scope="module")
def duffing_data():
    return population(linear(cubic_stiffness=1.4e10))


@pytest.fixture(scope="module")
def linear_criticised(duffing_data):
    return criticize(linear(), duffing_data)


def test_where_locates_the_missing_hardening(linear_criticised):
    """A linear model at the truth's small-amplitude stiffness misses the cubic shift
    √(k + ¾k₃a²)/2π − √k/2π, under-predicting the frequency at large amplitude."""
    crit = linear_criticised
    levels = crit.data.levels_m
    shift = (np.sqrt(K0 + 0.75 * 1.4e10 * levels**2) - W0) / (2 * np.pi)
    residual, se = crit.residual("frequency_hz")
    # plus the mean assembly offset (which scales a little with the stiffness drawn)
    np.testing.assert_allclose(residual, shift + residual[0], rtol=0.01, atol=0.01)
    failures = {f.channel: f for f in crit.where()}
    failure = failures["frequency_hz"]
    assert failure.direction == "under-predicted"
    # ζ = c/(2ω) falls as the frequency rises: a damping failure, if any, is over-predicted
    assert failures.get("damping_ratio", failure).direction in ("over-predicted", failure.direction)
    assert len(failures) == len(crit.where())  # one range per channel
    assert failure.to_mm == pytest.approx(1e3 * levels[-1])
    assert failure.max_residual == pytest.approx(shift[-1] + residual[0], rel=0.01)
    clearly = 1e3 * levels[shift > 4 * se + abs(residual[0])]
    assert failure.from_mm <= clearly.min()
    assert failure.text.startswith("frequency is under-predicted by up to")
    assert "between" in failure.text and "mm" in failure.text


def test_missing_hardening_is_ranked_first_and_the_loop_closes(linear_criticised, duffing_data):
    crit = linear_criticised
    assert crit.significant
    best = crit.missing()[0]
    assert best.effect == "cubic_stiffness"
    assert best.fit.model.coefficient("cubic_stiffness") == pytest.approx(1.4e10, rel=0.02)
    assert best.error_reduction["frequency_hz"] > 0.95
    assert best.delta_ic < -100 and "hardening" in best.reading
    # the signature of the right effect follows the refitted model's residual
    residual, _ = best.base.level_residual()
    np.testing.assert_allclose(best.signature["frequency_hz"], residual[:, 0], atol=0.03)
    after = crit.add("cubic_stiffness")
    assert [s.action for s in after.history] == ["start", "+ cubic_stiffness"]
    assert after.history[1].frequency_rmse_hz < 0.05 * after.history[0].frequency_rmse_hz
    assert not after.significant and after.where() == []
    assert "missing: nothing significant" in after.summary()
    # the history carries over to a criticism started by hand
    again = criticize(after.model.replace(cubic_stiffness=1.3e10), duffing_data,
                      history=after.history)  # fmt: skip
    assert [s.action for s in again.history] == ["start", "+ cubic_stiffness", "criticize"]


def test_the_well_specified_model_lacks_nothing(duffing_data):
    crit = criticize(linear(cubic_stiffness=1.4e10), duffing_data)
    assert not crit.significant and crit.missing() == []
    assert all(c.delta_ic > crit.threshold for c in crit.candidates)
    assert len(crit.candidates) == 13  # every other catalogue effect was tried


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
    assert best.error_reduction["damping_ratio"] > 0.9
    assert any(f.channel == "damping_ratio" for f in crit.where())
    if effect == "coulomb_friction":
        # Stribeck's law fitted to Coulomb data must let its decay velocity grow past
        # every velocity of the test (a start value given by shape)
        stribeck = crit.add("stribeck_friction", v_s=0.3)
        peak_velocity = AMPS.max() * W0
        assert stribeck.model["stribeck_friction"].shape["v_s"] > 3 * peak_velocity
        assert stribeck.fit.damping_rmse < 0.1 * crit.fit.damping_rmse
        with pytest.raises(ValueError, match="no shape parameter"):
            crit.add("stribeck_friction", x_s=1.0)


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
                "history", "candidates", "comparison"):  # fmt: skip
        assert key in report, key
    top = report["ranking"][0]
    assert top["effect"] == "cubic_stiffness"
    assert set(top) >= {"effect", "error_reduction", "delta_information_criterion", "reading"}
    assert report["significant"] is True and report["fails_at"][0]["channel"] == "frequency_hz"
    for name in ("comparison", "signatures", "history"):
        assert paths[name].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    second = crit.write(tmp_path / "after")
    assert len(json.loads(second["json"].read_text())["history"]) == 2
    from matplotlib.figure import Figure

    ax = Figure().subplots()
    plot_history(report["history"] + [s.to_dict() for s in crit.history[1:]], ax)
    assert len(ax.get_xticklabels()) == 2


def test_posterior_band_covers_its_population():
    """Curves drawn from the posterior's own population fall inside its 95 % band;
    a posterior without the hardening does not cover the large amplitudes."""
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


@cache
def study(scenario: str, seed: int = 0):
    return hidden_effect_study(scenario, seed, assemblies=3, levels=8)


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
    assert steps[-1].information_criterion < steps[0].information_criterion - 100


def test_microslip_reading_is_specific():
    best = study("hidden-microslip").criticisms[0].missing()[0]
    assert best.effect == "microslip"
    assert "frequency softening" in best.reading
    assert "damping rising" in best.reading and "partial slip" in best.reading


def test_quadratic_stiffness_needs_the_records():
    """Backbones alone: the refitted cubic absorbs x² (nothing significant is left).
    The records' second harmonic, which the extracted backbones keep, reveals it,
    ranked above ẋ², which makes the same harmonic but with the wrong amplitude
    dependence."""
    result = study("hidden-quadratic")
    blind = criticize(result.start, result.measured.without_harmonics())
    assert not blind.significant
    with_records = result.criticisms[0]
    ranked = [c.effect for c in with_records.missing()]
    assert ranked[0] == "quadratic_stiffness"
    assert ranked.index("velocity_squared") > 0
    (failure,) = [f for f in with_records.where() if f.channel == "harmonic2"]
    assert failure.direction == "under-predicted" and failure.max_residual > 0.02


#: The proposed ranking (effect, ΔBIC) of every round of each scenario's study (seed 0,
#: 3 assemblies, 8 levels) as main computed it before the backbones kept their harmonics
#: (commit 49ef863, harmonics re-fitted from the records by fit._hold_harmonics).
RANKINGS_BEFORE = {
    "hidden-none": [
        [],
    ],
    "hidden-cubic": [
        [
            ("cubic_stiffness", -3199.0983345317827),
            ("tanh_saturation", -3194.1193629446025),
            ("abs_stiffness", -2827.823626497068),
            ("displacement_velocity_squared", -2361.426858939386),
            ("exponential", -1703.0470405266428),
        ],
        [],
    ],
    "hidden-quadratic": [
        [
            ("quadratic_stiffness", -5893.958457374626),
            ("exponential", -5888.251625048552),
            ("velocity_squared", -5793.188859853253),
            ("displacement_velocity_squared", -17.3324879338561),
        ],
        [],
    ],
    "hidden-quadratic-damping": [
        [
            ("quadratic_damping", -3546.31396597158),
            ("cubic_damping", -3313.3717848960296),
            ("van_der_pol", -3308.2855457555443),
            ("microslip", -3142.2275945149368),
            ("stribeck_friction", -1462.2125133753116),
            ("coulomb_friction", -1425.1187042530046),
        ],
        [],
    ],
    "hidden-coulomb": [
        [
            ("coulomb_friction", -4476.635053158853),
            ("stribeck_friction", -4471.665238409574),
            ("microslip", -4471.331932630643),
            ("quadratic_damping", -1734.7899224494013),
            ("cubic_damping", -985.9465253252547),
            ("van_der_pol", -984.822728010251),
        ],
        [],
    ],
    "hidden-microslip": [
        [
            ("microslip", -17926.982494594922),
            ("stribeck_friction", -8870.861008328484),
            ("coulomb_friction", -8134.78420034784),
            ("tanh_saturation", -2115.527139340722),
            ("abs_stiffness", -2012.6361448063726),
            ("quadratic_damping", -639.4310971378618),
            ("exponential", -190.0873191965875),
            ("displacement_velocity_squared", -19.48896162737765),
        ],
        [],
    ],
    "hidden-two": [
        [
            ("microslip", -18072.163645508528),
            ("stribeck_friction", -10374.541961785793),
            ("coulomb_friction", -9305.750003213445),
            ("cubic_stiffness", -4268.560728420685),
            ("tanh_saturation", -4258.755209593619),
            ("displacement_velocity_squared", -2287.6735917525184),
            ("exponential", -2269.515676264142),
            ("abs_stiffness", -1965.5316226551222),
            ("quadratic_damping", -308.95173498238364),
            ("cubic_damping", -100.24701870915669),
            ("van_der_pol", -100.24184780085488),
        ],
        [
            ("cubic_stiffness", -9472.29907304757),
            ("tanh_saturation", -9467.280606523955),
            ("abs_stiffness", -8137.065422223094),
            ("displacement_velocity_squared", -5640.607246147686),
            ("exponential", -3751.5327295922525),
            ("van_der_pol", -233.21539123925868),
            ("cubic_damping", -232.4068399518028),
            ("quadratic_damping", -126.94512990209114),
            ("coulomb_friction", -52.21467204689634),
        ],
        [],
    ],
}


@pytest.mark.parametrize("scenario", SCENARIOS)
def test_ranking_and_delta_bic_are_unchanged_by_the_harmonics_moving_into_the_backbones(scenario):
    """The backbones now carry the harmonics the criticism used to re-fit from the
    records: same ranking, same ΔBIC (1e-6 relative) in every round. Some candidate fits
    (Stribeck in hidden-two) move by up to 20 in ΔBIC when the data move by one
    rounding, so a change that only rounds differently can fail here too: judge it. (The
    effects' describing functions summed in another order moved hidden-microslip's Stribeck
    fit by 4e-6 relative: 1e-4 holds rounding, not a changed statistic.)"""
    got = [[(c.effect, c.delta_ic) for c in crit.missing()] for crit in study(scenario).criticisms]
    expected = RANKINGS_BEFORE[scenario]
    assert [[e for e, _ in r] for r in got] == [[e for e, _ in r] for r in expected]
    for round_got, round_expected in zip(got, expected, strict=True):
        np.testing.assert_allclose([d for _, d in round_got], [d for _, d in round_expected],
                                   rtol=1e-4)  # fmt: skip


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("scenario", SCENARIOS)
def test_hidden_effect_study_over_seeds(scenario, seed):
    result = study(scenario, seed)
    assert result.passed, result.row()
