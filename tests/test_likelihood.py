import json
import warnings

import numpy as np
import pymc as pm
import pytensor
import pytensor.tensor as pt
import pytest
from oscillators import POPULATION_AMPLITUDES_M
from scipy import stats

from identification.measurements.backbone import Backbone, BackboneSet
from pm_joint.distributions import (
    BackboneAmplitude,
    BackboneDensity,
    NanCounter,
    amplitude_levels,
    interpolate_backbone,
    logp_graph,
)

W0 = 2 * np.pi * 100.0


@pytest.mark.parametrize("family", ["copula", "mvn"])
def test_pytensor_graph_equals_numpy_density(duffing_assemblies, family):
    density = BackboneDensity.fit(
        duffing_assemblies, channels=("frequency_hz", "damping_ratio"), family=family
    )
    v = pt.vector("v")
    f = pytensor.function([v], logp_graph(density, v))
    rows = np.vstack([density.observations[:4], density.sample(4, rng=1)])
    np.testing.assert_allclose([f(r) for r in rows], density.logpdf(rows), rtol=0, atol=1e-6)


@pytest.mark.parametrize("family", ["copula", "mvn"])
def test_a_density_written_as_json_reads_back_as_the_same_density(duffing_assemblies, family):
    levels = amplitude_levels(duffing_assemblies, n_levels=6, inset=0.1)
    density = BackboneDensity.fit(
        duffing_assemblies, levels, channels=("frequency_hz", "damping_ratio"), family=family
    )
    again = BackboneDensity.from_dict(json.loads(json.dumps(density.to_dict())))
    assert (again.family, again.channels) == (family, density.channels)
    assert [m.family for m in again.marginals] == [m.family for m in density.marginals]
    np.testing.assert_array_equal(again.amplitudes_m, levels)
    np.testing.assert_array_equal(again.observations, density.observations)
    rows = np.vstack([density.observations[:3], density.sample(3, rng=4)])
    np.testing.assert_array_equal(again.logpdf(rows), density.logpdf(rows))  # not a refit


def test_gaussian_copula_with_normal_marginals_is_a_multivariate_normal(duffing_assemblies):
    density = BackboneDensity.fit(duffing_assemblies, candidates=("norm",))
    sigma = np.array([m.params[1] for m in density.marginals])
    mu = np.array([m.params[0] for m in density.marginals])
    cov = density.correlation * np.outer(sigma, sigma)
    y = density.sample(5, rng=3)
    expected = stats.multivariate_normal(mu, cov).logpdf(y)
    np.testing.assert_allclose(density.logpdf(y), expected, rtol=1e-10)


def test_samples_reproduce_the_measured_spread(duffing_assemblies):
    density = BackboneDensity.fit(duffing_assemblies)
    draws = density.sample(20_000, rng=2)
    np.testing.assert_allclose(draws.mean(0), density.observations.mean(0), rtol=2e-4)
    np.testing.assert_allclose(draws.std(0), density.observations.std(0, ddof=1), rtol=0.1)


def test_interpolation_gives_nan_outside_the_predicted_range():
    backbone = np.column_stack([[1e-4, 2e-4, 3e-4], [100.0, 101.0, 103.0], [0.01] * 3])
    out = interpolate_backbone(backbone, [1.5e-4, 2.5e-4, 4e-4], ["frequency_hz"]).eval()
    np.testing.assert_allclose(out[:2], [100.5, 102.0])
    assert np.isnan(out[2])


def _duffing_backbone_graph(k_scale, k3, amplitudes):
    """Single-harmonic Duffing backbone written directly in pytensor."""
    omega = pt.sqrt(W0**2 * k_scale + 0.75 * k3 * amplitudes**2)
    freq = omega / (2 * np.pi)
    return pt.stack([pt.as_tensor(amplitudes), freq, pt.zeros_like(freq)], axis=1)


def test_model_logp_is_the_density_at_the_prediction(duffing_assemblies):
    levels = amplitude_levels(duffing_assemblies, n_levels=7)
    density = BackboneDensity.fit(duffing_assemblies, levels)
    with pm.Model() as model:
        k_scale = pm.Uniform("k_scale", 0.95, 1.05)
        k3 = pm.Uniform("k3", 0.0, 3e10)
        backbone = _duffing_backbone_graph(k_scale, k3, POPULATION_AMPLITUDES_M)
        BackboneAmplitude("backbone", backbone, observed=duffing_assemblies, density=density)
    point = model.initial_point()
    point["k_scale_interval__"] = 0.1
    logp_terms = model.compile_fn(
        # Population matching is a potential (no likelihood of the curves): its one term.
        model.logp(sum=False, vars=model.potentials),
        inputs=model.value_vars,
    )
    got = float(np.sum(logp_terms(point)))
    k_scale_value = 0.95 + 0.1 / (1 + np.exp(-0.1))
    k3_value = 3e10 / 2
    on_grid = np.sqrt(W0**2 * k_scale_value + 0.75 * k3_value * POPULATION_AMPLITUDES_M**2) / (
        2 * np.pi
    )
    prediction = np.interp(levels, POPULATION_AMPLITUDES_M, on_grid)
    assert got == pytest.approx(float(density.logpdf(prediction)), abs=1e-6)


def test_metropolis_posterior_predictive_matches_the_measured_population(duffing_assemblies):
    """The paper's scheme: posterior predictive backbones look like the measured ones."""
    levels = amplitude_levels(duffing_assemblies, n_levels=5)
    with pm.Model():
        k_scale = pm.Uniform("k_scale", 0.95, 1.05)
        k3 = pm.Uniform("k3", 0.0, 3e10)
        backbone = _duffing_backbone_graph(k_scale, k3, POPULATION_AMPLITUDES_M)
        BackboneAmplitude("backbone", backbone, observed=duffing_assemblies, amplitudes_m=levels)
        idata = pm.sample(
            draws=1500, tune=500, chains=1, step=pm.Metropolis(), random_seed=1,
            progressbar=False, compute_convergence_checks=False,
        )  # fmt: skip
    predicted = idata.posterior["backbone_predicted"].values.reshape(-1, len(levels))
    observed = duffing_assemblies.frequency_matrix(levels)
    for j in (0, len(levels) // 2, len(levels) - 1):
        assert stats.ks_2samp(predicted[::5, j], observed[:, j]).pvalue > 0.05


def test_levels_outside_the_shared_range_raise(duffing_assemblies):
    low, high = duffing_assemblies.common_range()
    with pytest.raises(ValueError, match="outside the range all measured curves share"):
        BackboneDensity.fit(duffing_assemblies, [low, 0.5 * (low + high), 2 * high])


def test_curves_without_a_shared_range_raise():
    a = Backbone([1e-4, 2e-4], [100.0, 101.0], [0.01, 0.01], label="a")
    b = Backbone([3e-4, 4e-4], [100.0, 101.0], [0.01, 0.01], label="b")
    with pytest.raises(ValueError, match="share no amplitude range"):
        BackboneDensity.fit(BackboneSet([a, b]))


def test_nan_prediction_gives_minus_inf_and_is_counted(duffing_assemblies):
    density = BackboneDensity.fit(duffing_assemblies)
    x = pt.vector("x")
    counted = NanCounter("test-nan")(x)
    f = pytensor.function([x], logp_graph(density, counted))
    before = NanCounter.counts.get("test-nan", 0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert f(np.full(density.n_dims, np.nan)) == -np.inf
    assert NanCounter.counts["test-nan"] == before + 1
    assert any("returned NaN" in str(w.message) for w in caught)


def test_far_predictions_are_unlikely_not_impossible(duffing_assemblies):
    """A tail probability that underflows must not make a poor prediction impossible."""
    density = BackboneDensity.fit(duffing_assemblies, candidates=("gumbel_l",))
    centre = density.observations.mean(axis=0)
    spread = density.observations.std(axis=0)
    v = pt.vector("v")
    graph = pytensor.function([v], logp_graph(density, v))
    values = [float(graph(centre + k * spread)) for k in (0, 10, 60)]
    assert np.all(np.isfinite(values)) and values[0] > values[1] > values[2]
    np.testing.assert_allclose(values, density.logpdf([centre + k * spread for k in (0, 10, 60)]))
