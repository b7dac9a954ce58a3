"""The convergence verdict, on a standard normal whose answer is known.

A deliberately short Metropolis run (one chain, or a few dozen draws) must be
called not converged; a long one must pass r̂ ≤ 1.01 and ESS ≥ 400. The
tuned-covariance Metropolis is checked against the paper's coordinate-wise one
on a correlated normal: the same distribution, more effective draws.
"""

from __future__ import annotations

import arviz as az
import numpy as np
import pymc as pm
import pytest

from pm_joint.analysis import convergence_verdict
from pm_joint.inference import sample


def _normal(dims=2):
    with pm.Model() as pm_model:
        pm.Normal("x", 0.0, 1.0, shape=dims)
    return pm_model


def test_a_short_run_is_not_converged():
    idata = sample(_normal(), draws=40, tune=40, chains=2, cores=1, progressbar=False)
    verdict = convergence_verdict(idata)
    print(verdict.headline())
    assert not verdict.converged and verdict.label == "NOT CONVERGED"
    assert any("ESS < 400" in r for r in verdict.reasons)
    assert verdict.headline().startswith("NOT CONVERGED")
    one = sample(_normal(), draws=4000, tune=500, chains=1, progressbar=False)
    assert not convergence_verdict(one).converged  # one chain: no between-chain r̂


def test_a_long_run_on_a_standard_normal_is_converged():
    idata = sample(_normal(), draws=6000, tune=1000, chains=2, cores=1, progressbar=False)
    verdict = convergence_verdict(idata)
    print(verdict.headline())
    assert verdict.converged, verdict.reasons
    assert verdict.nan_proposals == 0 and verdict.proposals == 2 * 6000
    x = idata.posterior["x"].values.reshape(-1, 2)
    # Against the known answer, within 4 Monte Carlo standard errors.
    ess = float(az.ess(idata, var_names=["x"]).to_dataset()["x"].min())
    assert np.all(np.abs(x.mean(0)) < 4 / np.sqrt(ess))
    assert np.all(np.abs(x.std(0) - 1) < 4 * np.sqrt(0.5 / ess) + 0.02)


def test_nan_proposals_are_counted():
    # A log density of -inf on half the line, as a forward model that returns NaN there.
    with pm.Model() as pm_model:
        x = pm.Normal("x", 0.0, 1.0)
        pm.Potential("hole", pm.math.switch(x > 1.0, -np.inf, 0.0))
    idata = sample(pm_model, draws=2000, tune=500, chains=2, cores=1, progressbar=False)
    verdict = convergence_verdict(idata)
    print(verdict.headline())
    assert 0 < verdict.nan_rate < 1 and "NaN forward output" in verdict.headline()
    assert float(idata.posterior["x"].max()) <= 1.0


@pytest.mark.parametrize("dims", [6])
def test_learned_covariance_beats_coordinatewise_proposals_on_a_correlated_normal(dims):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(dims, dims))
    covariance = a @ a.T + 0.05 * np.eye(dims)
    with pm.Model() as pm_model:
        pm.MvNormal("x", np.zeros(dims), covariance)
    runs = {}
    for label, options in (("paper", {"adapt_covariance": False}), ("tuned", {})):
        idata = sample(pm_model, draws=3000, tune=1000, chains=2, cores=1, progressbar=False,
                       step_options=options)  # fmt: skip
        ess = az.ess(idata, var_names=["x"]).to_dataset()["x"].values
        runs[label] = float(ess.min())
        draws = idata.posterior["x"].values.reshape(-1, dims)
        # Both sample the same distribution: each variance within 4 Monte Carlo standard
        # errors of the truth (a normal variance estimate has relative sd √(2 / ESS)).
        relative = draws.var(0) / np.diag(covariance) - 1
        assert np.all(np.abs(relative) < 4 * np.sqrt(2 / ess)), (label, relative, ess)
    print(f"min bulk ESS, 2 × 3000 draws: {runs}")
    assert runs["tuned"] > 1.5 * runs["paper"]
