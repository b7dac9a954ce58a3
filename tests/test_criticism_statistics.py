"""The criticism's statistics: measured false-discovery rate on null campaigns, the
decision's consistency, admissibility of fitted models, drift between branches, one
curve, no periodic solution in words, and a held-out check on data of an independent
simulator (scipy's DOP853 free decays, no harmonic balance, no catalogue kernel)."""

import math

import numpy as np
import pytest
from independent_sim import free_decay
from scipy.signal import find_peaks

from identification.criticism.adequacy import admissibility, no_solution
from identification.criticism.criticism import criticize
from identification.criticism.drift import branch_drift
from identification.fitting.data import fit_data
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from studies import (
    binomial_bounds,
    clopper_pearson,
    null_study,
    simulated_campaign,
    swap_study,
)

W0 = 2 * np.pi * 101.0
K0 = W0**2
C0 = 2 * 0.003 * W0
LEVELS_M = 1e-3 * np.geomspace(0.05, 2.0, 9)


def linear(**extra) -> JointModel:
    return JointModel({"linear_stiffness": K0, "viscous_damping": C0, **extra})


# --------------------------------------------------------------------------
# The false-discovery rate


def test_null_campaigns_find_nothing_and_the_bootstrap_is_not_anticonservative():
    """Null campaigns (harmonic-balance backbones of assemblies drawn around the truths, one
    and three curves, heteroscedastic noise, amplitude jitter), each criticised with its
    truth's structure. With the systematic floors as stated, nothing is found. With the
    floors switched off the bootstrap alone calibrates the rule: at α = 0.2, 8 campaigns
    give at most 5 false discoveries unless it is anti-conservative (P(X ≥ 6) = 0.1 % at
    the nominal 20 %). The full count is the slow test and ``bench/criticism.py``."""
    rows = null_study(5, curve_counts=(1, 3), n_bootstrap=500, seed=11)
    assert sum(r.false_discovery for r in rows) == 0, rows
    tiny = {"frequency_hz": 1e-6, "damping_ratio": 1e-9, "harmonics": 1e-7}
    rows = null_study(8, curve_counts=(1, 3), n_bootstrap=250, seed=12, alpha=0.2,
                      noise_floor=tiny)  # fmt: skip
    assert sum(r.false_discovery for r in rows) <= 5, rows


def test_clopper_pearson_matches_the_beta_quantiles():
    from scipy import stats

    low, high = clopper_pearson(3, 200)
    assert low == pytest.approx(stats.beta.ppf(0.025, 3, 198))
    assert high == pytest.approx(stats.beta.ppf(0.975, 4, 197))
    assert clopper_pearson(0, 200)[0] == 0.0


@pytest.mark.slow  # 85 s; the swap step's CI check is tests/test_criticism_terms.py's
def test_the_swap_step_keeps_coulomb_friction_beside_the_stribeck_law_that_nests_it():
    """The swap step judging Coulomb friction that is the truth (lab base, three and five
    assemblies, round 1's runners-up as alternatives): Stribeck friction nests it (v_s → ∞),
    so its gain is a likelihood ratio of nested models, at least 0 and, with the
    covariance known, ½χ²₀ + ½χ²₁ (above SEPARATION = 6.63 with probability 0.5 %). At the
    target of 5 % false swaps per decision, eight campaigns give at most 2 (Binomial(8,
    0.05)'s 99 % quantile). With the margin set to 0 (any gain taken) the same eight
    campaigns gave 6 false swaps, so the bound bites. The rate over 200 campaigns of nine
    truths is ``bench/criticism_swap.py``."""
    rows = swap_study(
        8, truths=("coulomb_friction",), curve_counts=(3, 5), n_bootstrap=500, seed=31
    )
    assert all(r.added == "coulomb_friction" for r in rows)
    assert all("stribeck_friction" in r.alternatives for r in rows), rows
    assert sum(r.false_swap for r in rows) <= binomial_bounds(8, 0.05, level=0.98)[1], rows


@pytest.mark.slow
def test_false_discovery_rate_over_sixty_null_campaigns():
    rows = null_study(60, seed=21)
    k = sum(r.false_discovery for r in rows)
    assert clopper_pearson(k, len(rows))[0] <= 0.05, rows


# --------------------------------------------------------------------------
# Campaigns whose answer is known


#: Each campaign's truth beyond the linear pair, and the effect the criticism must find.
KNOWN = {
    "null": ({}, None),
    "cubic": ({"cubic_stiffness": 1.4e10}, "cubic_stiffness"),
    "friction": ({"coulomb_friction": 0.2}, "coulomb_friction"),
}


@pytest.mark.parametrize("truth", list(KNOWN))
def test_a_campaign_whose_answer_is_known_gets_it(truth):
    """Behaviour, not the rule: criticised with the linear structure, a null campaign (the
    truth's own structure) answers nothing missing, and campaigns with a big hidden effect
    answer it missing (first, or in the proposed group), located where the model fails;
    a finding ``where()`` does not locate is said to be small."""
    extra, hidden = KNOWN[truth]
    measured = simulated_campaign(linear(**extra), 4, seed=5)
    crit = criticize(linear(), measured, n_bootstrap=500)
    proposed = [c.effect for c in crit.missing()]
    if hidden is None:
        assert not crit.significant and proposed == [], crit.summary()
        assert crit.verdict == "nothing missing" and not crit.unexplained
    else:
        assert crit.significant and crit.where(), crit.summary()
        grouped = {e for g in crit.groups for e in g.effects if proposed[0] in g.effects}
        assert hidden == proposed[0] or hidden in grouped, crit.summary()
        assert crit.verdict in ("explained", "partly explained")
    if crit.significant:
        assert crit.small == (not crit.where()), crit.summary()
    text = crit.summary()
    assert f"threshold {crit.threshold:.3g}" in text and "bootstrap campaigns" in text


# --------------------------------------------------------------------------
# Admissibility


def _predicted(model: JointModel):
    from identification.analytical.harmonic import backbone

    hb = backbone(model, LEVELS_M)
    return hb.frequency_hz, hb.damping_ratio


def test_negative_friction_and_negative_damping_are_inadmissible():
    model = linear(coulomb_friction=-0.2)
    problems = admissibility(model, LEVELS_M, *_predicted(model))
    assert any("coulomb_friction has a negative coefficient" in p for p in problems)
    # Coulomb's equivalent damping 4F/(πaω) = 8.0 /s at 0.05 mm outweighs C0 = 3.8 /s there,
    # not at 2 mm (0.2 /s)
    (negative,) = [p for p in problems if "negative total damping" in p]
    assert negative.startswith("negative total damping (energy fed in by the joint) at 0.05–")
    assert "–2 mm" not in negative


def test_a_stiffness_cancelled_by_a_large_tanh_is_inadmissible():
    """4·k with a tanh taking 3·k off at small amplitude: the same small-amplitude stiffness,
    terms that add up to 7× their net."""
    x_s = 1e-3
    model = JointModel({"linear_stiffness": 4 * K0, "viscous_damping": C0,
                        "tanh_saturation": {"coefficient": -3 * K0 * x_s, "x_s": x_s}})  # fmt: skip
    problems = admissibility(model, LEVELS_M, *_predicted(model))
    (cancel,) = [p for p in problems if "terms cancel in the equivalent stiffness" in p]
    ratio = float(cancel.split("up to ")[1].split("×")[0])
    assert ratio == pytest.approx(7.0, rel=0.05)


def test_a_hardening_told_as_a_stiffer_structure_minus_a_spring_is_inadmissible():
    """A clearance's hardening (lab-clearance from SINDy's cubic start, seed 0) was fitted
    as a 46 % stiffer structure, a cubic turned softening, and a tanh taking 1.9e5 off at
    rest: terms adding up to under twice their net, so no cancellation is flagged, but the
    tanh is a spring pushing away from equilibrium at rest. A saturating spring that
    carries load at rest (the lab's tanh truth), cubic softening or hardening and x|x|
    have no negative stiffness at rest."""
    tanh = {"coefficient": -144.6, "x_s": 7.543e-4}
    clearance = JointModel({"linear_stiffness": 5.929e5, "viscous_damping": 3.766,
                            "cubic_stiffness": -1.859e10, "tanh_saturation": tanh})  # fmt: skip
    problems = admissibility(clearance, LEVELS_M, *_predicted(clearance))
    assert not any("terms cancel" in p for p in problems)
    (rest,) = problems
    assert rest.startswith("tanh_saturation has a negative stiffness at rest (-1.92e+05, 32 %")
    for physical in (
        linear(tanh_saturation={"coefficient": 20.0, "x_s": 5e-4}).replace(
            linear_stiffness=K0 - 4e4
        ),
        linear(cubic_stiffness=-2e10),
        linear(cubic_stiffness=1.4e10, abs_stiffness=-2.4e7),
    ):
        assert admissibility(physical, LEVELS_M, *_predicted(physical)) == [], physical


def test_a_physical_joint_is_admissible():
    """Membrane hardening, microslip softening and its damping, viscous damping: terms of both
    signs, none cancelling another."""
    k_t = 0.06 * K0
    slip = {"coefficient": 1.0, "k_t": k_t, "F_s": k_t * 2e-4}
    model = JointModel({"linear_stiffness": K0 - k_t, "viscous_damping": C0,
                        "cubic_stiffness": 1.4e10, "microslip": slip})  # fmt: skip
    assert admissibility(model, LEVELS_M, *_predicted(model)) == []


def test_no_periodic_solution_is_said_in_words():
    softening = linear(cubic_stiffness=-2e11)  # ω² = k − ¾·2·10¹¹·a² < 0 above 1.64 mm
    f, z = _predicted(softening)
    assert np.isnan(f[-1]) and np.isfinite(f[0])
    last = 1e3 * LEVELS_M[np.flatnonzero(np.isfinite(f))[-1]]
    assert no_solution(LEVELS_M, np.column_stack([f, z])) == (
        f"no periodic solution above {last:.2g} mm"
    )
    measured = simulated_campaign(linear(), 3, seed=2)
    crit = criticize(softening, measured, n_bootstrap=500, candidates=[])
    assert any("the model as given has no periodic solution above" in c for c in crit.caveats)


# --------------------------------------------------------------------------
# Drift between the branches


def _up_down(rate_hz_per_hold: float, n: int, seed: int) -> BackboneSet:
    """Runs stepped up and down over 9 levels; the frequency drifts linearly in hold index."""
    rng = np.random.default_rng(seed)
    a = np.concatenate([LEVELS_M, LEVELS_M[-2::-1]]) * np.exp(0.01 * rng.standard_normal(17))
    curves = []
    for i in range(n):
        offset = 0.3 * rng.standard_normal()
        f = 101 + offset + 2e5 * a**2 + rate_hz_per_hold * np.arange(17)
        z = 0.003 * (1 + 0.02 * rng.standard_normal()) + 0 * a
        curves.append(Backbone(a, f + 0.003 * rng.standard_normal(17), z, label=f"run{i}"))
    return BackboneSet(curves)


def test_drift_follows_time_between_the_branches_not_amplitude():
    drifting = branch_drift(fit_data(_up_down(0.01, 5, seed=1)), alpha=0.01)
    frequency = next(d for d in drifting if d.channel == "frequency_hz")
    assert frequency.significant and frequency.time_unit == "hold"
    assert frequency.rate == pytest.approx(0.01, rel=0.05)
    assert "drift, not joint physics" in frequency.text
    steady = branch_drift(fit_data(_up_down(0.0, 5, seed=1)), alpha=0.01)
    assert not any(d.significant for d in steady)
    # the branches are averaged: a drift linear in time adds a constant, nothing is proposed
    crit = criticize(JointModel({"linear_stiffness": K0, "viscous_damping": C0,
                                 "cubic_stiffness": 1e10}), _up_down(0.01, 5, seed=1),
                     n_bootstrap=500)  # fmt: skip
    assert crit.verdict == "drift" and not crit.missing()


# --------------------------------------------------------------------------
# One curve


def test_one_curve_uses_its_own_noise_and_says_so():
    measured = simulated_campaign(linear(), 1, seed=4)
    crit = criticize(linear(), measured, n_bootstrap=500)
    assert crit.metric.covariance.kind == "within-curve"
    assert any("population scatter is unknown" in c for c in crit.caveats)
    assert crit.verdict == "nothing missing"
    hardening = simulated_campaign(linear(cubic_stiffness=1.4e10), 1, seed=4)
    found = criticize(linear(), hardening, n_bootstrap=500)
    assert found.missing()[0].effect == "cubic_stiffness"


# --------------------------------------------------------------------------
# Held-out: backbones from free decays of an independent simulator


def decay_backbone(force, x0_m: float, seconds: float, label: str, rng) -> Backbone:
    """Backbone of a ring-down: per cycle the mean of successive peak and trough, the
    period between upward zero crossings, the logarithmic decrement over the cycle (ζ =
    δ/2π), read at the levels (log-linear), with 0.2 % frequency-independent noise."""
    decay = free_decay(force, x0_m, 0.0, fs_hz=5000.0, duration_s=seconds, rtol=1e-7)
    t, x = decay["time_s"], decay["displacement_m"]
    peaks, _ = find_peaks(x)
    troughs, _ = find_peaks(-x)
    peak_t, peak_x = t[peaks], x[peaks]
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    crossing = t[up] - x[up] * (t[up + 1] - t[up]) / (x[up + 1] - x[up])
    amplitude = 0.5 * (peak_x[:-1] + np.interp(peak_t[:-1], t[troughs], -x[troughs]))
    period = np.interp(peak_t[:-1], crossing[1:], np.diff(crossing))
    zeta = np.log(peak_x[:-1] / peak_x[1:]) / (2 * np.pi)
    order = np.argsort(amplitude)
    inside = (LEVELS_M > amplitude.min()) & (LEVELS_M < amplitude.max())  # noqa: SIM300
    a = LEVELS_M[inside]
    log_a = np.log(amplitude[order])
    f = np.interp(np.log(a), log_a, 1 / period[order])
    z = np.interp(np.log(a), log_a, zeta[order])
    return Backbone(a, f * (1 + 2e-5 * rng.standard_normal(a.size)),
                    z * (1 + 2e-3 * rng.standard_normal(a.size)), label=label)  # fmt: skip


def decay_campaign(extra, n: int, seed: int, zeta: float = 0.01) -> BackboneSet:
    rng = np.random.default_rng(seed)
    curves = []
    for i in range(n):
        k = K0 * math.exp(0.005 * rng.standard_normal())
        c = 2 * zeta * W0 * math.exp(0.05 * rng.standard_normal())

        def force(x, v, k=k, c=c):
            return k * x + c * v + extra(x, v)

        curves.append(decay_backbone(force, 2.3e-3, 0.9, f"assembly{i}", rng))
    return BackboneSet(curves)


def test_power_law_damping_of_an_independent_simulator_is_not_explained_as_physics():
    """c·|v|^1.5 damping (not in the catalogue), ring-downs integrated by DOP853: something
    is missing, and the verdict says the catalogue does not (fully) explain it; nothing
    inadmissible is proposed."""
    measured = decay_campaign(lambda x, v: 40.0 * math.copysign(abs(v) ** 1.5, v), 4, seed=1)
    crit = criticize(linear(viscous_damping=2 * 0.01 * W0), measured, n_bootstrap=1000)
    assert crit.significant
    assert crit.verdict in ("partly explained", "not explained by the catalogue"), crit.summary()
    assert crit.unexplained and crit.explained_share is not None
    assert all(not c.problems for c in crit.missing())
    assert "free-form reference" in crit.summary()


@pytest.mark.slow
@pytest.mark.parametrize(
    ("extra", "expected"),
    [
        (lambda x, v: 0.0, None),
        (lambda x, v: 1.4e10 * x**3, "cubic_stiffness"),
        (lambda x, v: 2.0 * math.copysign(1.0, v) if abs(v) > 1e-9 else 0.0, "coulomb_friction"),
    ],
)
def test_independent_ring_downs_null_and_catalogue_effects(extra, expected):
    measured = decay_campaign(extra, 5, seed=3)
    crit = criticize(linear(viscous_damping=2 * 0.01 * W0), measured)
    if expected is None:
        assert crit.verdict == "nothing missing", crit.summary()
    else:
        effects = {crit.missing()[0].effect} | {e for g in crit.groups for e in g.effects}
        assert expected in effects and crit.verdict == "explained", crit.summary()
