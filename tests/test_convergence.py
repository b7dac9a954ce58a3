"""The convergence verdict, on a standard normal whose answer is known.

A deliberately short Metropolis run (one chain, or a few dozen draws) must be
called not converged; a long one must pass r̂ ≤ 1.01 and ESS ≥ 400. The
tuned-covariance Metropolis is checked against the paper's coordinate-wise one
on a correlated normal: the same distribution, more effective draws. The
demo's sampler setup must converge, to the analytical marginals, on a
posterior as hard as the demo's population matching: uniform priors on boxes
of scales 1e-5 to 1e10, a sharply identified parameter, flat (prior-set)
directions, a correlated pair, a marginal piled against a box edge and a thin
ridge cut off by the box.
"""

from __future__ import annotations

import arviz as az
import numpy as np
import pymc as pm
import pytest
from scipy import stats

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


def test_kept_logp_gives_pymcs_chain_with_one_evaluation_per_proposal():
    # PyMC's own two-point delta_logp is the reference: the same seed must give the same
    # chain, and KeptLogp must score each proposal once (PyMC's scores two points a step).
    from pymc.step_methods.metropolis import delta_logp

    from pm_joint.inference.steps import CovarianceMetropolis, KeptLogp

    rng = np.random.default_rng(3)
    a = rng.normal(size=(3, 3))
    with pm.Model() as pm_model:
        x = pm.Uniform("x", -5.0, 5.0, shape=3)
        pm.Potential("correlated", pm.logp(pm.MvNormal.dist(np.zeros(3), a @ a.T + np.eye(3)), x))
    point = pm_model.initial_point()
    chains, calls = {}, []

    def counted(logp):
        return lambda q: calls.append(1) or logp(q)

    for label in ("pymc", "kept"):
        with pm_model:
            step = CovarianceMetropolis(rng=np.random.default_rng(7), coordinates="value")
        step.set_tune_steps(400)
        assert isinstance(step.delta_logp, KeptLogp)
        if label == "pymc":
            step.delta_logp = delta_logp(point, pm_model.logp(), step.vars, {}, None)
        else:
            step.delta_logp.logp = counted(step.delta_logp.logp)
        draws, current = [], dict(point)
        for i in range(1000):  # 400 tuning steps (coordinate-wise pilot, then joint), 600 draws
            if i == 400:
                step.stop_tuning()
            current, _ = step.step(current)
            draws.append(current["x_interval__"].copy())
        chains[label] = np.array(draws)
    np.testing.assert_allclose(chains["kept"], chains["pymc"], rtol=0, atol=1e-12)
    # 3 proposals per coordinate-wise pilot step (80 steps), 1 per joint step, plus the start.
    assert len(calls) == 80 * 3 + 920 + 1
    assert len(np.unique(chains["kept"][:, 0])) > 100  # the chain moved


def test_a_step_over_some_variables_scores_by_pymcs_delta_logp():
    # Where another step moves the rest, the current point's logp can change between steps:
    # the step keeps PyMC's two-point difference (compiled only then), and it is that one.
    from pymc.pytensorf import make_shared_replacements
    from pymc.step_methods.metropolis import delta_logp

    from pm_joint.inference.steps import CovarianceMetropolis, KeptLogp

    with pm.Model() as pm_model:
        x = pm.Uniform("x", -5.0, 5.0)
        pm.Normal("y", mu=x, sigma=1.0)
        step = CovarianceMetropolis([x], rng=np.random.default_rng(7))
    assert not isinstance(step.delta_logp, KeptLogp)
    point = pm_model.initial_point()
    shared = make_shared_replacements(point, step.vars, pm_model)  # y held at its value
    reference = delta_logp(point, pm_model.logp(), step.vars, shared, None)
    q0, q1 = np.array([0.1]), np.array([-0.4])
    assert step.delta_logp(q1, q0) != 0.0
    assert step.delta_logp(q1, q0) == pytest.approx(reference(q1, q0), rel=1e-12)


# A demo-like posterior with a known answer. Parameter i has a uniform prior on
# [LOW[i], LOW[i] + WIDTH[i]] (the demo's boxes span scales 1e-4 to 1e10); in box fractions
# u the potentials below make: u0 ~ N(0.5, 0.016) (the demo's linear stiffness), u1 and u3
# flat (its damping terms), (u2, u4) a normal pair with correlation 0.9, u5 a half-normal
# against the upper edge, and u6 + u7 ~ N(1.2, 0.02) a thin ridge that the box cuts off (a
# direction the data do not identify: its length is set by the prior box).
LOW = np.array([3.4e5, 8.4, 2.9e10, -5.6, -1.9e4, 3.1, 1.27e-4, 0.2])
WIDTH = np.array([7.6e4, 6.4, 6.5e9, 12.8, 1.5e4, 1.0, 2.8e-5, 0.05])
RIDGE, RIDGE_SD = 1.2, 0.02


def _demo_like_posterior():
    with pm.Model() as pm_model:
        theta = pm.math.stack(
            [pm.Uniform(f"p{i}", LOW[i], LOW[i] + WIDTH[i]) for i in range(LOW.size)]
        )
        u = (theta - LOW) / WIDTH
        pm.Potential("sharp", -0.5 * ((u[0] - 0.5) / 0.016) ** 2)
        a, b = (u[2] - 0.5) / 0.1, (u[4] - 0.5) / 0.1
        pm.Potential("pair", -0.5 * (a**2 - 1.8 * a * b + b**2) / (1 - 0.9**2))
        pm.Potential("edge", -0.5 * ((1 - u[5]) / 0.1) ** 2)
        pm.Potential("ridge", -0.5 * ((u[6] + u[7] - RIDGE) / RIDGE_SD) ** 2)
    return pm_model


def _demo_like_marginals() -> tuple[np.ndarray, np.ndarray]:
    """Means and sds of the box fractions: closed forms, the ridge's by quadrature."""
    flat = 12**-0.5
    mean = [0.5, 0.5, 0.5, 0.5, 0.5, 1 - 0.1 * np.sqrt(2 / np.pi)]
    sd = [0.016, flat, 0.1, flat, 0.1, 0.1 * np.sqrt(1 - 2 / np.pi)]
    # u6's density: the ridge's normal integrated over u7 in (0, 1); u7's is the same.
    grid = np.linspace(0.0, 1.0, 100_001)
    density = stats.norm.cdf((grid + 1 - RIDGE) / RIDGE_SD) - stats.norm.cdf(
        (grid - RIDGE) / RIDGE_SD
    )
    density /= np.trapezoid(density, grid)
    ridge_mean = np.trapezoid(grid * density, grid)
    ridge_sd = np.sqrt(np.trapezoid((grid - ridge_mean) ** 2 * density, grid))
    return np.array([*mean, ridge_mean, ridge_mean]), np.array([*sd, ridge_sd, ridge_sd])


def _box_fractions(idata) -> np.ndarray:
    posterior = idata.posterior
    return np.stack(
        [(posterior[f"p{i}"].values.ravel() - LOW[i]) / WIDTH[i] for i in range(LOW.size)], -1
    )


def test_the_demo_sampler_converges_to_the_known_marginals_of_a_demo_like_posterior():
    # The demo's setting (pm-joint's Metropolis, 1 tuning step in 6), scaled down.
    idata = sample(_demo_like_posterior(), draws=20_000, tune=4_000, chains=2, cores=1,
                   progressbar=False)  # fmt: skip
    verdict = convergence_verdict(idata)
    print(verdict.headline())
    assert verdict.converged, verdict.reasons
    assert verdict.nan_proposals == 0  # out-of-box proposals are not NaN forward outputs
    assert idata.sample_stats["outside_box"].values.any()
    u = _box_fractions(idata)
    mean, sd = _demo_like_marginals()
    ess = np.array([row["ess_bulk"] for row in verdict.parameters])
    # Within 4 Monte Carlo standard errors of the analytical answer, both ways. An sd
    # estimate's relative error is about sqrt((kurtosis - 1) / (4 ESS)); kurtosis ≤ 4 here.
    z_mean = (u.mean(0) - mean) / (sd / np.sqrt(ess))
    relative_sd = u.std(0) / sd - 1
    print("mean error / MCSE", np.round(z_mean, 2), "sd relative error", np.round(relative_sd, 3))
    assert np.all(np.abs(z_mean) < 4)
    assert np.all(np.abs(relative_sd) < 4 * np.sqrt(3 / (4 * ess)))


@pytest.mark.slow
def test_logit_coordinates_do_not_converge_on_the_demo_like_ridge():
    # What the box coordinates fix: in PyMC's logit coordinates the straight ridge is
    # curved, and the same run leaves it unconverged (measured: max r̂ 1.047, min bulk ESS 47).
    idata = sample(_demo_like_posterior(), draws=20_000, tune=4_000, chains=2, cores=1,
                   progressbar=False, step_options={"coordinates": "value"})  # fmt: skip
    verdict = convergence_verdict(idata)
    print(verdict.headline())
    assert not verdict.converged
    assert any("p6" in reason for reason in verdict.reasons)
