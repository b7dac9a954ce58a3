"""Stochastic updating: forward-model switch, acceptance on a rig campaign, calibration,
bad input, NaN regions and interrupted runs.

Independent expectations: the PLL simulator and harmonic balance against each
other and against the surrogate's own validation error; the rig's ground truth
(the population it drew the assemblies from); two-sample KS tests against the
measured curves; a standard normal for the draws of an interrupted run.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import warnings

import arviz as az
import numpy as np
import pymc as pm
import pytest
import torch
import zarr
from scipy import stats

from identification.analytical.harmonic import backbone
from identification.analytical.pll import pll_backbones
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.model import JointModel
from identification.rig import Rig, read_ground_truth
from pm_joint.analysis import loo, population_predictive
from pm_joint.analysis.posterior import criticize, posterior_samples
from pm_joint.distributions import BackboneDensity, NanCounter, amplitude_levels, level_marks
from pm_joint.forward import HarmonicBalanceGraph, PLLOp, SurrogateOp
from pm_joint.inference import (
    build_model,
    continue_sampling,
    hierarchical_model,
    load_posterior,
    sample,
    save_posterior,
    stored_density,
)
from pm_joint.inference.traces import read_trace, written_steps
from pm_joint.inference.truncation import (
    TruncationCorrection,
    centred_choice,
    truncation_correction,
)
from studies import binomial_bounds, population_coverage, synthetic_campaign
from surrogates import (
    NetConfig,
    SurrogateRuntime,
    TrainingConfig,
    export_surrogate,
    train_surrogate,
)
from surrogates.dataset import generate_dataset

torch.set_num_threads(1)
# Python-perform Ops (surrogate, PLL) run in numba object mode; pytensor says so on compile.
pytestmark = pytest.mark.filterwarnings("ignore:Numba will use object mode:UserWarning")

W0 = 2 * np.pi * 100.0
DUFFING = JointModel(
    {"linear_stiffness": W0**2, "viscous_damping": 2 * 0.004 * W0, "cubic_stiffness": 1e10}
)
NAMES = ["linear_stiffness", "cubic_stiffness"]
BOUNDS = {"linear_stiffness": (0.97 * W0**2, 1.03 * W0**2), "cubic_stiffness": (5e9, 1.5e10)}
#: Base-acceleration levels of the surrogate (m/s²): about 0.08–1.7 mm on the Duffing panel.
SURROGATE_LEVELS = np.geomspace(0.25, 6.0, 16)


def _duffing_curves(n=6, seed=0):
    """Harmonic-balance backbones of ``n`` Duffing assemblies around the template."""
    rng = np.random.default_rng(seed)
    values = np.column_stack(
        [W0**2 * (1 + 0.005 * rng.standard_normal(n)), 1e10 * (1 + 0.2 * rng.standard_normal(n))]
    )
    amplitudes = 1e-3 * np.geomspace(0.1, 1.5, 12)
    hb = backbone(DUFFING, amplitudes, parameters=values, names=NAMES)
    return BackboneSet(
        Backbone(amplitudes, f, d, label=f"duffing{i}")
        for i, (f, d) in enumerate(zip(hb.frequency_hz, hb.damping_ratio, strict=True))
    )


@pytest.fixture(scope="module")
def duffing_surrogate(tmp_path_factory):
    """A small surrogate of the Duffing panel over BOUNDS (trained in about 10 s)."""
    data = generate_dataset(
        DUFFING, NAMES, 200, bounds=BOUNDS, levels=SURROGATE_LEVELS, progress=False
    )
    net = NetConfig(latent_dim=8, conv_filters=(8, 8), ffnn_width=64, ffnn_depth=2)
    config = TrainingConfig(net=net, max_epochs=150, finetune_epochs=150, progress=False)
    trained = train_surrogate(data.X, data.Y, data.spec, config)
    folder = export_surrogate(trained, tmp_path_factory.mktemp("duffing_surrogate"))
    return trained, SurrogateRuntime.load(folder)


def _predicted_at(pm_model, values):
    """The ``backbone_predicted`` deterministic at a parameter point (physical values)."""
    function = pm_model.compile_fn(
        pm_model["backbone_predicted"], inputs=pm_model.free_RVs, mode="FAST_COMPILE"
    )
    return function(values)


# -- one model, three forward models -----------------------------------------------


def test_forward_models_switch_by_one_argument_and_agree(duffing_surrogate):
    trained, runtime = duffing_surrogate
    measured = _duffing_curves()
    point = {"linear_stiffness": 1.004 * W0**2, "cubic_stiffness": 1.1e10}
    predicted, ops = {}, {}
    for forward in ("harmonic", "pll", "surrogate"):
        pm_model = build_model(
            DUFFING, measured, forward=forward, names=NAMES, bounds=BOUNDS,
            surrogate=runtime, n_grid=10,
        )  # fmt: skip
        ops[forward] = type(pm_model.forward_op)
        predicted[forward] = _predicted_at(pm_model, point)
    assert ops == {"harmonic": HarmonicBalanceGraph, "pll": PLLOp, "surrogate": SurrogateOp}
    assert all(np.isfinite(values).all() for values in predicted.values())
    # The analytical backbones: time-domain PLL against single-harmonic balance.
    gap = np.abs(predicted["pll"] / predicted["harmonic"] - 1).max()
    print(f"PLL against harmonic balance: {100 * gap:.3f} % at most")
    assert gap < 3e-3
    # The surrogate within the error it states for itself (validation curves, worst case).
    stated = trained.metrics["channels"]["frequency_hz"]["max_ape_pct"] / 100
    print(f"surrogate's stated frequency accuracy {100 * stated:.3f} %")
    assert stated < 0.01
    np.testing.assert_allclose(predicted["surrogate"], predicted["harmonic"], rtol=stated)


# -- acceptance on a trc-like campaign ------------------------------------------------

TRC = "trc-like"
#: Test levels and the (population) seed of the campaigns below.
RIG_LEVELS, CAMPAIGN_SEED = 12, 7


def _population(rig):
    """Names the rig varies, their nominal values, lognormal spreads and population means."""
    names = sorted(rig.variability)
    nominal = np.array([rig.model.parameters[n] for n in names])
    spread = np.array([rig.variability[n] for n in names])
    return names, nominal, spread, nominal * np.exp(0.5 * spread**2)


def _campaign_by_pll(rig, assemblies=25, seed=CAMPAIGN_SEED):
    """What the rig measures minus the file round trip: PLL backbones of its drawn assemblies."""
    names, *_ = _population(rig)
    models = [rig.draw(np.random.default_rng([seed, a]))[0] for a in range(1, assemblies + 1)]
    values = np.array([[m.parameters[n] for n in names] for m in models])
    levels = rig.shaker_gain * np.asarray(rig.levels_v)
    result = pll_backbones(rig.model, levels, values, names, progress=False)
    assert result.locked.all()
    return BackboneSet(
        Backbone(a, f, d, label=f"Assemb{i + 1}")
        for i, (a, f, d) in enumerate(
            zip(result.amplitude_m, result.frequency_hz, result.damping_ratio, strict=True)
        )
    )


def _check_posterior_against_the_rig(rig, measured):
    """KS at low/mid/high amplitude and the population means inside the 94 % intervals."""
    names, nominal, spread, population_mean = _population(rig)
    # Priors: five population spreads either side of the nominal value.
    bounds = {
        n: (v * np.exp(-5 * s), v * np.exp(5 * s))
        for n, v, s in zip(names, nominal, spread, strict=True)
    }
    # Damping too, so that the viscous damping the rig varies is informed; the joint density
    # is a multivariate normal over 5 levels × 2 channels, which 25 curves estimate well.
    levels = amplitude_levels(measured, n_levels=5)
    pm_model = build_model(
        rig.model, measured, forward="harmonic", names=names, bounds=bounds, amplitudes_m=levels,
        channels=("frequency_hz", "damping_ratio"), family="mvn",
    )  # fmt: skip
    idata = sample(pm_model, sampler="nuts", draws=1000, tune=500, chains=2, progressbar=False)
    divergences = int(idata.sample_stats["diverging"].sum())
    print(f"NUTS divergences: {divergences}")
    assert divergences <= 10
    predicted = idata.posterior["backbone_predicted"].values.reshape(-1, 2 * levels.size)
    observed = measured.frequency_matrix(levels)
    for mark, j in level_marks(levels).items():
        # Thinned below the effective sample size: KS assumes independent draws.
        result = stats.ks_2samp(predicted[::10, j], observed[:, j])
        print(f"{mark} ({1e3 * levels[j]:.3f} mm): KS distance {result.statistic:.3f}, "
              f"p = {result.pvalue:.3f}")  # fmt: skip
        assert result.pvalue > 0.05, mark
    interval = az.hdi(idata, var_names=names, prob=0.94)
    for name, mean in zip(names, population_mean, strict=True):
        low, high = interval[name].values
        print(f"{name}: population mean {mean:.6g} in 94 % interval [{low:.6g}, {high:.6g}]")
        assert low <= mean <= high, name


def test_posterior_reproduces_a_trc_like_campaign():
    rig = Rig.preset(TRC, levels=RIG_LEVELS)
    _check_posterior_against_the_rig(rig, _campaign_by_pll(rig))


@pytest.mark.slow
def test_posterior_reproduces_trc_like_records(tmp_path):
    """The same through the files: rig records → extracted backbones → posterior."""
    rig = Rig.preset(TRC, levels=RIG_LEVELS)
    campaign = rig.write_campaign(tmp_path, assemblies=25, seed=CAMPAIGN_SEED, precision=5)
    measured = extract_backbones(campaign)
    truth = read_ground_truth(tmp_path)
    assert len(measured) == len(truth) == 25
    _check_posterior_against_the_rig(rig, measured)


# -- the hierarchical model's calibration ---------------------------------------------

#: Log-locations (relative to the trc-like nominal model) and spreads of the population.
CALIBRATION = {
    "linear_stiffness": (0.002, 0.005),
    "cubic_stiffness": (-0.02, 0.03),
    "microslip.F_s": (0.05, 0.1),
    "viscous_damping": (0.03, 0.05),
}


@pytest.mark.slow  # 88 s; CI keeps test_hierarchical_model_recovers_a_small_population
def test_hierarchical_model_is_calibrated_on_pll_campaigns():
    """Five campaigns, truths from the prior, data from the PLL simulator (not the
    single-harmonic graph the model infers with): 90 % intervals of the population
    log-means and log-spreads hold the truth within two-sided binomial bounds.

    Five campaigns bound only gross miscalibration (a count of 2 or less of 5 fails);
    bench/population_coverage.py runs 20 or more. As the CLI runs it: every measured
    point, the truncation correction, centred where the curves pin a parameter.
    """
    coverage = population_coverage(
        DUFFING, NAMES, np.geomspace(0.3, 5.0, 8), n_campaigns=5, n_curves=6,
        location_scale=0.02, population_scale=0.05, channels=("frequency_hz",), draws=300,
        tune=800, progress=False,
    )  # fmt: skip
    print(coverage)
    assert coverage.bounds() == (3, 5)  # Binomial(5, 0.9): P(X ≤ 2) = 0.0086
    assert coverage.within_bounds()
    # The all-centred form met the log-spread funnel with 22–76 divergences over these 5
    # campaigns (interpolated at 6 levels; the count changed from run to run on the same
    # seeds); the non-centred one had 2. Coverage is the claim; divergences stay rare.
    assert coverage.divergences.sum() <= 0.02 * 5 * 2 * 300


#: The coefficients bench/population_coverage.py lets vary on the trc-like rig.
TRC_NAMES = ["linear_stiffness", "cubic_stiffness", "viscous_damping", "microslip.F_s"]


def test_truncation_correction_brings_pll_backbones_onto_the_single_harmonic_one():
    """Three trc-like assemblies through the time-domain PLL simulator (every harmonic, no
    noise): at 1.4–2.4 mm the single-harmonic balance of the true parameters misses the
    PLL's frequency by more than the 0.02 Hz extraction noise of a lab campaign; less the
    truncation correction (fitted without knowing the truth) the PLL's points lie on it
    to within 0.015 Hz everywhere, and the per-curve fits find the parameters."""
    rig = Rig.preset(TRC, levels=12)
    excitation = rig.shaker_gain * np.asarray(rig.levels_v)
    theta0 = np.array([rig.model.parameters[n] for n in TRC_NAMES])
    theta = theta0 * np.exp(0.1 * np.random.default_rng(2).standard_normal((3, 4)))
    pll = pll_backbones(rig.model, excitation, theta, TRC_NAMES, progress=False)
    assert pll.locked.all()
    curve = np.repeat(np.arange(3), excitation.size)
    amplitude, frequency = pll.amplitude_m.ravel(), pll.frequency_hz.ravel()
    correction = truncation_correction(
        rig.model, TRC_NAMES, curve, amplitude, frequency, pll.damping_ratio.ravel(),
        prior_scale=0.11,
    )  # fmt: skip
    single = np.concatenate(
        [backbone(rig.model, a, parameters=t[None], names=TRC_NAMES).frequency_hz[0]
         for a, t in zip(pll.amplitude_m, theta, strict=True)]
    )  # fmt: skip
    raw, corrected = frequency - single, frequency - correction.frequency_hz - single
    print(f"PLL - single-harmonic frequency: max {np.abs(raw).max():.4f} Hz as measured, "
          f"{np.abs(corrected).max():.4f} Hz less the correction")  # fmt: skip
    assert np.abs(raw).max() > 0.05
    assert np.abs(corrected).max() < 0.015
    assert np.abs(np.log(correction.estimate / theta)).max() < 0.02


def test_centred_where_the_curves_scatter_more_than_their_own_error():
    """Per-curve estimates of two parameters, each curve's error 0.01 in log: the one whose
    population spreads 0.05 is centred, the one that spreads 0.003 is not."""
    rng = np.random.default_rng(0)
    eta = np.array([0.05, 0.003]) * rng.standard_normal((25, 2))
    estimate = np.exp(eta + 0.01 * rng.standard_normal((25, 2)))
    correction = TruncationCorrection(
        np.zeros(1), np.zeros(1), estimate, np.full((25, 2), 0.01), harmonics=5
    )
    assert centred_choice(correction).tolist() == [True, False]


def test_binomial_bounds_reject_full_coverage_over_many_campaigns():
    low, high = binomial_bounds(80, 0.9)
    assert (low, high) == (66, 77)  # 80/80 is 0.9**80 = 2e-4 likely: not calibrated
    assert stats.binom.cdf(low - 1, 80, 0.9) < 0.025 < stats.binom.cdf(low, 80, 0.9)


def test_hierarchical_model_recovers_a_small_population():
    """Five noisy Duffing curves: NUTS without divergences, each curve's parameters found."""
    log_mean, log_spread = np.array([0.004, -0.1]), np.array([0.005, 0.1])
    measured, theta = synthetic_campaign(
        DUFFING, NAMES, log_mean, log_spread, 1e-3 * np.geomspace(0.1, 1.5, 8), n_curves=5, rng=3
    )
    # The curves are the single-harmonic balance itself: no truncation error to subtract.
    pm_model = hierarchical_model(DUFFING, measured, NAMES, truncation=None)
    idata = sample(pm_model, sampler="nuts", draws=300, tune=300, chains=2, progressbar=False)
    assert int(idata.sample_stats["diverging"].sum()) == 0
    per_curve = idata.posterior["theta"].values.reshape(-1, 5, 2)
    z = (per_curve.mean(axis=0) - theta) / per_curve.std(axis=0)
    print(f"per-curve parameters, posterior mean - truth in posterior sd: {z.round(2).tolist()}")
    assert np.all(np.abs(z) < 4)
    # A likelihood of every measured point: LOO runs, over the 5 × 8 points.
    result = loo(idata, pm_model)
    assert result.elpd_i.size == 40 and np.isfinite(result.elpd)
    # New assemblies scatter like the population, not like one curve's noise: their
    # cubic stiffness spread (0.1 in log) shows in the frequency at the top amplitude.
    amplitudes = 1e-3 * np.array([0.1, 1.5])
    new = population_predictive(idata, DUFFING, NAMES, amplitudes, n_draws=600)
    top = new["frequency_hz"].values[:, -1]
    clean = backbone(DUFFING, amplitudes[-1:], parameters=theta, names=NAMES)
    print(f"new assemblies at 1.5 mm: sd {top.std():.3f} Hz; the five curves: "
          f"{clean.frequency_hz[:, 0].std(ddof=1):.3f} Hz; noise 0.02 Hz")  # fmt: skip
    assert top.std() > 3 * 0.02
    # The criticism is handed the population's median assembly, whose spread is the
    # uncertainty of the population-mean curve: about 1/√5 of the assemblies' scatter.
    names, median = posterior_samples(idata)
    assert names == NAMES and median.shape == (200, 2)
    assemblies = idata.posterior["theta"].values.reshape(-1, 2)
    ratio = np.log(median[:, 1]).std() / np.log(assemblies[:, 1]).std()
    print(f"log cubic stiffness: population median sd / assemblies' sd = {ratio:.2f}")
    assert ratio < 0.7
    # So the criticism's test widens by about the population spread over √5, not by the
    # spread itself (the new assemblies' sd at 1.5 mm).
    se_alone = criticize(DUFFING, measured).residual("frequency_hz")[1][-1]
    se_given = criticize(DUFFING, measured, posterior=idata).residual("frequency_hz")[1][-1]
    widening = np.sqrt(max(se_given**2 - se_alone**2, 0.0))
    print(f"frequency standard error at 1.5 mm: {se_alone:.3f} Hz alone, {se_given:.3f} Hz "
          f"given the posterior: widened by {widening:.3f} Hz = {widening / top.std():.2f} of "
          "the population spread (1/√5 = 0.45)")  # fmt: skip
    assert widening < 0.7 * top.std()


def test_loo_refuses_population_matching():
    measured = _duffing_curves()
    pm_model = build_model(DUFFING, measured, names=NAMES, bounds=BOUNDS, family="mvn")
    idata = sample(pm_model, draws=200, tune=200, chains=1, cores=1, progressbar=False)
    assert idata.attrs["population_model"] == "population matching"
    # No observed variable: nothing for PyMC to score point by point ...
    assert not pm_model.observed_RVs
    # ... and LOO says why instead of returning a number.
    with pytest.raises(ValueError, match="not a likelihood of the measured curves"):
        loo(idata, pm_model)
    with pytest.raises(ValueError, match="LOO refused"):
        loo(idata)  # the DataTree alone knows what it is


# -- bad input -----------------------------------------------------------------------


def test_curves_without_a_shared_range_and_levels_outside_it_raise():
    measured = _duffing_curves()
    apart = BackboneSet([*measured[:3], Backbone([2e-3, 3e-3], [110.0, 115.0], [0.004] * 2)])
    with pytest.raises(ValueError, match="share no amplitude range"):
        build_model(DUFFING, apart, names=NAMES, bounds=BOUNDS)
    low, high = measured.common_range()
    with pytest.raises(ValueError, match="outside the range all measured curves share"):
        build_model(
            DUFFING, measured, names=NAMES, bounds=BOUNDS, amplitudes_m=[low, 2 * high, 3 * high]
        )
    # The hierarchical model scores the levels each curve reached, and no curve without one.
    with pytest.raises(ValueError, match="reach none of the amplitude levels"):
        hierarchical_model(DUFFING, measured, NAMES, amplitudes_m=[0.1 * low, 0.2 * low])
    first = measured[0]
    short = Backbone(first.amplitude_m[3:], first.frequency_hz[3:], first.damping_ratio[3:])
    partial = hierarchical_model(
        DUFFING, BackboneSet([short, *measured[1:]]), NAMES, amplitudes_m=[low, high]
    )
    # The short curve did not reach the lowest level: one point; the others two each.
    assert partial["curve_index"].get_value().tolist() == [0, *np.repeat(np.arange(1, 6), 2)]


def test_a_surrogate_must_match_the_priors(duffing_surrogate):
    _, runtime = duffing_surrogate
    measured = _duffing_curves()
    with pytest.raises(ValueError, match=r"missing \['cubic_stiffness'\]"):
        build_model(None, measured, forward="surrogate", surrogate=runtime, names=NAMES[:1])
    with pytest.raises(ValueError, match=r"unknown \['k3'\]"):
        build_model(
            None, measured, forward="surrogate", surrogate=runtime, names=["linear_stiffness", "k3"]
        )
    wide = {**BOUNDS, "cubic_stiffness": (1e9, 1.5e10)}
    with pytest.raises(ValueError, match=r"'cubic_stiffness'.*leave the surrogate's training box"):
        build_model(None, measured, forward="surrogate", surrogate=runtime, bounds=wide)


def test_a_forward_model_without_the_levels_at_the_prior_centre_raises(duffing_surrogate):
    measured = _duffing_curves()
    # No positive stiffness at the centre of the box: harmonic balance gives NaN there.
    soft = {**BOUNDS, "linear_stiffness": (-2 * W0**2, -(W0**2))}
    with pytest.raises(ValueError, match="at the centre of the prior box"):
        build_model(DUFFING, measured, names=NAMES, bounds=soft)
    # A surrogate whose excitation levels do not reach the measured amplitudes.
    _, runtime = duffing_surrogate
    small = _duffing_curves()
    low = BackboneSet(
        Backbone(b.amplitude_m * 10, b.frequency_hz, b.damping_ratio, label=b.label) for b in small
    )
    with pytest.raises(ValueError, match="surrogate forward model at the centre"):
        build_model(None, low, forward="surrogate", surrogate=runtime)


def test_a_chain_through_nan_regions_completes_and_counts_them():
    measured = _duffing_curves()
    # Stiffness below zero in part of the box: the backbone is NaN there (no resonance).
    bounds = {**BOUNDS, "linear_stiffness": (-0.3 * W0**2, 1.7 * W0**2)}
    pm_model = build_model(DUFFING, measured, names=NAMES, bounds=bounds, family="mvn")
    # The warning comes at the 1st, 10th, 100th ... NaN of a label in this process:
    # start the tally afresh so that earlier tests do not decide whether it shows.
    NanCounter.counts.pop("backbone", None)
    before = 0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        idata = sample(
            pm_model, sampler="metropolis", draws=500, tune=500, chains=1, cores=1,
            progressbar=False,
        )  # fmt: skip
    counted = NanCounter.counts.get("backbone", 0) - before
    print(f"NaN predictions counted: {counted}")
    assert counted > 0
    assert any("returned NaN" in str(w.message) for w in caught)
    k = idata.posterior["linear_stiffness"].values
    assert k.shape == (1, 500) and np.all(k > 0)  # the chain went on, never into the NaN region


# -- sampling, traces, files ---------------------------------------------------------


def test_unknown_sampler_and_forward_model_raise():
    measured = _duffing_curves()
    with pytest.raises(ValueError, match="forward must be one of"):
        build_model(DUFFING, measured, forward="simulink")
    with pm.Model() as pm_model:
        pm.Normal("x")
    with pytest.raises(ValueError, match="sampler must be one of"):
        sample(pm_model, sampler="gibbs")


def _normal_model():
    with pm.Model() as pm_model:
        x = pm.Normal("x", 0.0, 1.0, shape=2)
        pm.Deterministic("twice", 2 * x)
    return pm_model


def test_a_trace_folder_reads_back_as_the_run_returned_it(tmp_path):
    idata = sample(
        _normal_model(), sampler="demetropolisz", draws=300, tune=100, chains=2, cores=1,
        progressbar=False, trace=tmp_path / "run.zarr", trace_chunk=64,
    )  # fmt: skip
    again = load_posterior(tmp_path / "run.zarr")
    assert again.attrs["interrupted"] == 0 and idata.attrs["sampler"] == "demetropolisz"
    np.testing.assert_array_equal(again.posterior["x"].values, idata.posterior["x"].values)
    np.testing.assert_allclose(idata.posterior["twice"], 2 * idata.posterior["x"])
    assert idata.posterior.sizes == {"chain": 2, "draw": 300, "x_dim_0": 2, "twice_dim_0": 2}
    assert "accepted" in idata.sample_stats
    # and netCDF
    path = save_posterior(idata, tmp_path / "posterior.nc", metadata={"sampler": "demetropolisz"})
    loaded = load_posterior(path)
    np.testing.assert_array_equal(loaded.posterior["x"].values, idata.posterior["x"].values)
    with pytest.raises(FileNotFoundError):
        load_posterior(tmp_path / "missing.nc")


def test_the_likelihood_density_travels_with_the_draws(tmp_path):
    measured = _duffing_curves()
    density = BackboneDensity.fit(measured, amplitude_levels(measured, n_levels=5), family="mvn")
    pm_model = build_model(DUFFING, measured, names=NAMES, bounds=BOUNDS, density=density)
    assert pm_model.backbone_density is density  # used as given, not refitted
    with pytest.raises(ValueError, match="not both"):
        build_model(DUFFING, measured, density=density, amplitudes_m=density.amplitudes_m)
    normal = _normal_model()
    normal.backbone_density = density
    idata = sample(
        normal, sampler="demetropolisz", draws=50, tune=50, chains=1, cores=1, progressbar=False
    )
    kept = stored_density(load_posterior(save_posterior(idata, tmp_path / "p.nc")))
    np.testing.assert_array_equal(kept.amplitudes_m, density.amplitudes_m)
    np.testing.assert_array_equal(kept.correlation, density.correlation)
    plain = sample(_normal_model(), draws=20, tune=20, chains=1, cores=1, progressbar=False)
    assert stored_density(plain) is None  # no backbone likelihood, nothing stored


def test_an_append_cut_by_a_kill_reads_back_to_the_counted_draws(tmp_path):
    """A kill in the middle of an append leaves one variable longer than the others (the race
    the killed-run test below meets now and then): the chain reads back at the length its
    progress file counts, without the half-written values."""
    folder = tmp_path / "cut.zarr"
    with pm.Model() as model:
        pm.Normal("x", 0.0, 1.0, shape=2)
    sample(model, draws=300, tune=100, chains=1, cores=1, progressbar=False, trace=str(folder),
           trace_chunk=100)  # fmt: skip
    x = zarr.open_group(folder / "chain_0", mode="r+")["x"]
    steps = x.shape[0]
    x.resize((steps + 100, 2))
    x[steps:] = 1e6  # the appended chunk of one variable, the others' never written
    draws = read_trace(folder).posterior["x"].values
    assert draws.shape == (1, 300, 2) and np.abs(draws).max() < 10


def test_a_killed_run_leaves_its_draws(tmp_path):
    """Sampling in a child process, killed mid-run: the draws written so far read back."""
    folder = tmp_path / "killed.zarr"
    script = (
        "import pymc as pm\n"
        "from pm_joint.inference import sample\n"
        "with pm.Model() as model:\n"
        "    pm.Normal('x', 0.0, 1.0, shape=2)\n"
        f"sample(model, draws=10**7, tune=200, chains=2, cores=2, progressbar=False, "
        f"trace={str(folder)!r}, trace_chunk=100)\n"
    )
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    # Its own session, so that the chain processes die with it.
    child = subprocess.Popen([sys.executable, "-c", script], cwd=root, start_new_session=True)
    try:
        written = _wait_for_draws(folder, 1500, child)
    finally:
        os.killpg(child.pid, signal.SIGKILL)
        child.wait()
    idata = load_posterior(folder)
    x = idata.posterior["x"].values
    assert idata.attrs["interrupted"] == 1
    # The chains go on writing between the last poll and the kill: at least what was polled,
    # in whole chunks of 100 steps (200 of them tuning).
    assert x.shape[0] == 2 and x.shape[1] >= written - 200 and np.isfinite(x).all()
    assert (x.shape[1] + 200) % 100 == 0
    # The draws are the standard normal's (Metropolis: about 1 effective draw in 5).
    assert abs(x.mean()) < 0.25 and 0.75 < x.std() < 1.25
    # ... and the run goes on from there to the draws it was asked for.
    with pm.Model() as model:
        pm.Normal("x", 0.0, 1.0, shape=2)
    total = x.shape[1] + 1500
    whole = continue_sampling(model, folder, draws=total, tune=200, progressbar=False)
    joined = whole.posterior["x"].values
    assert joined.shape[:2] == (2, total) and whole.attrs["continued_at"] == x.shape[1]
    np.testing.assert_array_equal(joined[:, : x.shape[1]], x)  # the first part as it was
    rest = joined[:, x.shape[1] :]
    assert abs(rest.mean()) < 0.25 and 0.75 < rest.std() < 1.25
    assert load_posterior(tmp_path / "killed.zarr-continued").posterior.sizes["draw"] == 1500
    assert continue_sampling(model, folder, draws=x.shape[1]).posterior.sizes["draw"] == x.shape[1]


def _wait_for_draws(folder, n, child, timeout_s=120.0):
    """Poll the trace until every chain has written ``n`` steps; return how many."""
    start = time.monotonic()
    while time.monotonic() - start < timeout_s:
        assert child.poll() is None, "the sampling process ended on its own"
        try:
            written = min(written_steps(folder))
        except ValueError:
            written = 0  # not created yet
        if written >= n:
            return written
        time.sleep(0.2)
    raise AssertionError(f"no {n} draws within {timeout_s} s")
