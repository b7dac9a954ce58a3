import json

import matplotlib

matplotlib.use("Agg")

import matplotlib.image as mpimg
import numpy as np
import pytest
from arviz_base import from_dict

from identification.analytical import harmonic
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from pm_joint.analysis import correlation_matrix, default_var_names, level_pdfs, summarize
from pm_joint.distributions import BackboneDensity, amplitude_levels, level_marks
from pm_joint.inference import load_posterior, save_posterior
from pm_joint.plotting import plot_level_pdfs
from pm_joint.plotting.posterior import _pair_groups
from pm_joint.report_folder import report

W0 = 2 * np.pi * 100.0
AMPS = np.linspace(5e-5, 1.5e-3, 30)
NAMES = ["linear_stiffness", "cubic_stiffness"]
TEMPLATE = JointModel({"linear_stiffness": W0**2, "cubic_stiffness": 1e10, "viscous_damping": 5.0})
CHAINS, DRAWS = 2, 500


def population(n, rng):
    """Parameter vectors of a population of Duffing joints, (n, 2)."""
    return np.column_stack(
        [W0**2 * (1 + 0.01 * rng.normal(size=n)), 1e10 * (1 + 0.2 * rng.normal(size=n))]
    )


def frequencies(theta, amplitudes_m):
    """Single-harmonic Duffing backbones, (n_sets, n_amplitudes) in Hz."""
    return harmonic.backbone(TEMPLATE, amplitudes_m, parameters=theta, names=NAMES).frequency_hz


@pytest.fixture(scope="module")
def measured():
    theta = population(60, np.random.default_rng(0))
    hb = harmonic.backbone(TEMPLATE, AMPS, parameters=theta, names=NAMES)
    return BackboneSet(
        Backbone(AMPS, f, d, label=f"c{i}")
        for i, (f, d) in enumerate(zip(hb.frequency_hz, hb.damping_ratio, strict=True))
    )


@pytest.fixture(scope="module")
def density(measured):
    return BackboneDensity.fit(measured, candidates=("norm", "gumbel_r", "gumbel_l"))


def trace(theta, predicted, density, **attrs):
    """A DataTree shaped like pm_joint.sample's (2 chains × 500 draws)."""
    rng = np.random.default_rng(7)
    posterior = {n: theta[:, j].reshape(CHAINS, DRAWS) for j, n in enumerate(NAMES)}
    posterior["backbone_predicted"] = predicted.reshape(CHAINS, DRAWS, -1)
    return from_dict(
        {
            "posterior": posterior,
            "sample_stats": {"accepted": (rng.uniform(size=(CHAINS, DRAWS, 2)) < 0.3) * 1.0},
            "observed_data": {"backbone": density.observations},
        },
        attrs={"sample_stats": attrs},
    )


@pytest.fixture(scope="module")
def same_population(density):
    """Posterior-predictive draws from the population the measured curves came from."""
    theta = population(CHAINS * DRAWS, np.random.default_rng(1))
    return theta, frequencies(theta, density.amplitudes_m)


def test_level_pdfs_of_the_measured_population_are_not_rejected(density, same_population):
    result = level_pdfs(trace(*same_population, density), density)
    assert list(result) == ["low", "mid", "high"]
    marks = level_marks(density.amplitudes_m)
    for level, entry in result.items():
        expected = density.observations[:, marks[level]]  # one channel: column = level index
        np.testing.assert_array_equal(entry["measured_hz"], expected)
        assert entry["sampled_hz"].size == CHAINS * DRAWS
        assert entry["distances"]["ks_pvalue"] > 0.05, level
        assert entry["distances"]["wasserstein"] < 0.5 * expected.std()


def test_level_pdfs_reject_a_shift_of_three_standard_deviations(density, same_population):
    theta, predicted = same_population
    shift = 3 * density.observations.std(axis=0, ddof=1)
    result = level_pdfs(trace(theta, predicted + shift, density), density)
    for level, entry in result.items():
        expected = shift[entry["index"]]
        assert entry["distances"]["ks_pvalue"] < 0.01, level
        assert entry["distances"]["wasserstein"] == pytest.approx(expected, rel=0.15)
        assert entry["mean_shift_hz"] == pytest.approx(expected, rel=0.15)
        for fit in ("measured_fit", "sampled_fit"):
            assert entry[fit].family in ("norm", "gumbel_r", "gumbel_l")
    fig = plot_level_pdfs(result)
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert any(t.startswith("KS") for t in legend) and any(t.startswith("W =") for t in legend)


def test_a_density_fitted_elsewhere_is_refused(measured, density, same_population):
    idata = trace(*same_population, density)
    with pytest.raises(ValueError, match="levels"):
        level_pdfs(idata, BackboneDensity.fit(measured, amplitude_levels(measured, n_levels=7)))
    other_levels = amplitude_levels(measured, inset=0.1)  # same count, other amplitudes
    with pytest.raises(ValueError, match="observed_data"):
        level_pdfs(idata, BackboneDensity.fit(measured, other_levels))


def bivariate_trace(rho, offset=0.0):
    rng = np.random.default_rng(3)
    draws = rng.multivariate_normal([0, 0], [[1, rho], [rho, 1]], size=(CHAINS, DRAWS))
    draws[1] += offset  # the second chain elsewhere: not converged
    return from_dict({"posterior": {"a": draws[..., 0], "b": draws[..., 1]}})


def test_correlation_matrix_recovers_a_known_correlation():
    corr = correlation_matrix(bivariate_trace(0.8))
    assert list(corr.columns) == ["a", "b"]
    assert corr.loc["a", "b"] == pytest.approx(0.8, abs=0.05)
    np.testing.assert_allclose(np.diag(corr), 1.0)


def test_summary_diagnoses_mixed_and_unmixed_chains():
    mixed = summarize(bivariate_trace(0.0), ["a", "b"])
    for column in ("mean", "sd", "r_hat", "ess_bulk", "ess_tail"):
        assert column in mixed.columns
    assert any("94" in c for c in mixed.columns)  # the 94 % interval bounds
    # Independent draws: R-hat ≈ 1, bulk ESS ≈ the number of draws.
    np.testing.assert_allclose(mixed["r_hat"], 1.0, atol=0.01)
    np.testing.assert_allclose(mixed["ess_bulk"], CHAINS * DRAWS, rtol=0.25)
    stuck = summarize(bivariate_trace(0.0, offset=3.0), ["a"])
    assert stuck.loc["a", "r_hat"] > 1.5


def test_report_writes_every_file_it_lists(tmp_path, measured, density, same_population):
    idata = trace(*same_population, density, sampling_time=12.5, tuning_steps=100)
    assert default_var_names(idata) == NAMES  # backbone_predicted is no parameter
    out = tmp_path / "report"
    result = report(idata, measured, density=density, out=out)
    assert json.loads((out / "report.json").read_text()) == result
    assert set(result) >= {"summary", "correlation", "level_pdfs", "sampler", "files"}
    assert result["files"][-1] == "report.json"
    for name in result["files"]:
        path = out / name
        assert path.stat().st_size > 0, name
        if name.endswith(".png"):
            image = mpimg.imread(path)
            assert image.ndim == 3 and image.shape[0] > 100 and np.ptp(image) > 0, name
    assert {"pairs_1.png", "trace.png", "rank.png", "correlation.png"} <= set(result["files"])
    assert [r["variable"] for r in result["summary"]] == NAMES
    assert {"r_hat", "ess_bulk", "ess_tail"} <= set(result["summary"][0])
    mid = result["level_pdfs"]["mid"]
    assert mid["measured_fit"]["family"] and len(mid["sampled_fit"]["params"]) >= 2
    assert set(mid["distances"]) == {"ks_statistic", "ks_pvalue", "wasserstein"}
    sampler = result["sampler"]
    assert sampler["sampler"] == "metropolis"
    assert (sampler["draws"], sampler["chains"], sampler["wall_time_s"]) == (DRAWS, CHAINS, 12.5)
    assert sampler["acceptance_rate"] == pytest.approx(0.3, abs=0.02)


def test_report_fits_the_default_density_when_none_is_given(tmp_path, measured, same_population):
    # The trace's observed values come from the default levels, so the default fit matches.
    default = BackboneDensity.fit(measured, candidates=("norm",))
    idata = trace(*same_population, default)
    with pytest.warns(UserWarning, match="no likelihood density is stored"):
        result = report(idata, measured, var_names=["cubic_stiffness"], out=tmp_path)
    assert result["var_names"] == ["cubic_stiffness"]
    assert all((tmp_path / name).is_file() for name in result["files"])


def test_report_draws_the_density_stored_with_the_posterior(tmp_path, measured, same_population):
    # Levels other than the default: a default refit would not match the trace.
    stored = BackboneDensity.fit(measured, amplitude_levels(measured, inset=0.1), family="mvn")
    theta, _ = same_population
    path = save_posterior(
        trace(theta, frequencies(theta, stored.amplitudes_m), stored), tmp_path / "p.nc",
        density=stored,
    )  # fmt: skip
    result = report(load_posterior(path), measured, out=tmp_path / "report")
    for level, entry in result["level_pdfs"].items():
        expected = 1e3 * stored.amplitudes_m[level_marks(stored.amplitudes_m)[level]]
        assert entry["amplitude_mm"] == pytest.approx(expected, rel=1e-12)
        assert entry["distances"]["ks_pvalue"] > 0.05, level


def test_pair_matrices_hold_six_parameters_and_never_one_alone():
    names = [f"k{i}" for i in range(1, 14)]
    assert [len(g) for g in _pair_groups(names[:12])] == [6, 6]
    assert _pair_groups(names)[-1] == ["k12", "k13"]  # the paper's 12 plus one more
    assert _pair_groups(names[:3]) == [names[:3]]


def _round(action, verdict_text, significant, fails, ranking=()):
    summary = "\n".join([f"model: after {action}", *(f"fails: {f}" for f in fails),
                         f"verdict: {verdict_text}"])  # fmt: skip
    return {"action": action, "verdict": verdict_text.split(":")[0], "summary": summary,
            "verdict_text": verdict_text, "significant": significant,
            "ranking": list(ranking)}  # fmt: skip


def test_the_criticism_section_leads_with_each_rounds_finding(tmp_path):
    """What was missing and where the model failed come first, round by round; the final
    model's state ("nothing missing") after them, not instead of them."""
    from pm_joint.html import criticism_section

    found = {"effect": "microslip", "reading": "softening that saturates", "gain": 812.345678}
    record = {
        "significant": False,
        "equation": "ẍ + k·x = −a_base(t)",
        "fails_at": [],
        "history": [],
        "rounds": [
            _round("start", "explained by microslip", True,
                   ["frequency over-predicted between 0.1 and 1 mm"], [found]),
            _round("+ microslip", "nothing missing beyond the scatter", False,
                   ["nowhere beyond the scatter"]),
        ],
    }  # fmt: skip
    section = criticism_section(record, tmp_path / "criticism", tmp_path)
    first, second, final = section.text.split("\n\n")
    assert first.startswith("Round 1 of 2 (start): explained by microslip.")
    assert "Where it fails: frequency over-predicted between 0.1 and 1 mm." in first
    assert "Most likely missing: microslip, softening that saturates." in first
    assert second.startswith("Round 2 of 2 (+ microslip): nothing missing beyond the scatter.")
    assert final.startswith("The final model, ẍ + k·x = −a_base(t): Nothing significant missing.")
    assert section.code.startswith("--- round 1 of 2 (start): explained by microslip\nmodel:")
    assert [title for title, _ in section.tables][:2] == [
        "round 1 (start): ranked missing effects",
        "round 2 (+ microslip): ranked missing effects",
    ]


def test_report_text_formats_its_numbers(tmp_path):
    from pm_joint.html import _section, posterior_sections

    sampler = {"sampler": "metropolis", "reason": "why", "draws": 600, "chains": 2,
               "acceptance_rate": 0.26176666666666665}  # fmt: skip
    content = {"files": [], "summary": [{"variable": "k", "mean": 1.23456789}], "level_pdfs": {},
               "sampler": sampler}  # fmt: skip
    (section,) = posterior_sections(content, tmp_path, tmp_path)
    assert "mean acceptance 0.26." in section.text
    page = _section(section)
    assert "1.235" in page and "1.2345" not in page


def _short_trace(theta, density):
    """One chain of the draws ``theta`` (n, 2), as ``pm-joint update --chains 1`` leaves it."""
    predicted = frequencies(theta, density.amplitudes_m)
    posterior = {n: theta[None, :, j] for j, n in enumerate(NAMES)}
    posterior["backbone_predicted"] = predicted[None]
    accepted = np.zeros((1, len(theta), 2))
    return from_dict(
        {"posterior": posterior, "sample_stats": {"accepted": accepted},
         "observed_data": {"backbone": density.observations}},
    )  # fmt: skip


@pytest.mark.parametrize("moved", [True, False])
def test_report_of_one_short_chain_says_what_it_cannot_compute(moved, tmp_path, measured, density):
    """1 chain × 20 draws through ``pm-joint report``: r̂ and ranks need two chains; a chain
    that never moved (every proposal rejected) has no spread for the pair plot, the
    correlations and the PDFs per level. The report says so, and draws everything else."""
    from pm_joint.cli import main
    from pm_joint.html import missing_links

    theta = population(20, np.random.default_rng(3))
    if not moved:
        theta[:] = theta[0]
    posterior = save_posterior(_short_trace(theta, density), tmp_path / "p.nc", density=density)
    measured.to_csv(tmp_path / "backbones.csv")
    argv = ["report", str(tmp_path / "backbones.csv"), "--posterior", str(posterior)]
    with pytest.warns(UserWarning, match="not computed from this posterior: ") as warned:
        assert main([*argv, "--out", str(tmp_path / "out")]) == 0
    content = json.loads((tmp_path / "out" / "posterior" / "report.json").read_text())
    said = content["not_computed"]
    assert said[-1 if moved else 1].startswith("r̂ and the rank plot: 1 chain(s) × 20 draw(s)")
    assert "rank.png" not in content["files"]
    figures = {"pairs_1.png", "level_pdfs.png"}
    if moved:
        assert len(said) == 1 and figures <= set(content["files"])
        assert list(content["level_pdfs"]) == ["low", "mid", "high"]
    else:
        pair = "the pair plot, histogram and correlations of linear_stiffness, cubic_stiffness"
        assert said[0].startswith(f"{pair}: every one of the 1 chain(s) × 20 draw(s) holds one")
        assert said[2].startswith("the PDFs at the amplitude levels: low amplitude level: every")
        assert len(said) == 3 and not figures & set(content["files"])
        assert content["level_pdfs"] == {}
    assert {"trace.png", "predictive_backbones.png", "correlation.png"} <= set(content["files"])
    assert [str(w.message) for w in warned if "not computed" in str(w.message)] == [
        f"not computed from this posterior: {line}" for line in said
    ]
    index = tmp_path / "out" / "index.html"
    assert missing_links(index) == []
    assert index.read_text().count("Not computed from this posterior: ") == len(said)
