"""Studies of the method on simulated campaigns, for bench/, case_studies/ and slow tests.

Nothing in the library imports this module: a study runs the library many
times (criticising rig campaigns, training surrogates, sampling posteriors) to
measure how well it works.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike
from scipy import stats

from identification.analytical.harmonic import backbone
from identification.analytical.pll import pll_backbones
from identification.criticism.criticism import Criticism, Step, criticize
from identification.fitting.least_squares import fit_backbones
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Record
from identification.model import JointModel
from identification.rig import RIG_PRESETS, rig_for_preset
from pm_joint.analysis import convergence_verdict
from pm_joint.inference import hierarchical_model, sample
from surrogates.evaluate import PAPER_TABLE5, backbone_metrics
from surrogates.runtime import SurrogateSpec
from surrogates.train import TrainingConfig, train_surrogate

__all__ = [
    "KEY_CHANNEL",
    "Coverage",
    "StudyResult",
    "binomial_bounds",
    "hidden_effect_study",
    "pll_campaign",
    "population_coverage",
    "synthetic_campaign",
    "table5_study",
]


# ---------------------------------------------------------------------------
# Hidden-effect studies


#: The channel whose error a hidden effect must take down (by ≥ 80 %) in the studies.
#: Damping effects leave the frequency at the noise level already; quadratic
#: stiffness is absorbed by the refitted cubic term in the backbone and shows
#: in the second harmonic of the records.
KEY_CHANNEL = {
    "hidden-cubic": "frequency_hz",
    "hidden-microslip": "frequency_hz",
    "hidden-two": "frequency_hz",
    "hidden-quadratic": "harmonics",
    "hidden-quadratic-damping": "damping_ratio",
    "hidden-coulomb": "damping_ratio",
}
_STEP_RMSE = {
    "frequency_hz": "frequency_rmse_hz",
    "damping_ratio": "damping_rmse",
    "harmonics": "harmonic_rmse",
}


@dataclass
class StudyResult:
    """One hidden-effect scenario run through the criticism loop.

    Keeps the measured backbones, the records and the fitted start model, so the
    same data can be criticised again another way.
    """

    scenario: str
    seed: int
    hidden: tuple[str, ...]
    measured: BackboneSet
    records: list[Record]
    start: JointModel
    criticisms: list[Criticism] = field(default_factory=list)

    @property
    def history(self) -> list[Step]:
        return self.criticisms[-1].history

    @property
    def added(self) -> list[str]:
        return [s.action[2:] for s in self.history if s.action.startswith("+ ")]

    @property
    def first(self) -> str | None:
        """The effect ranked first by the first criticism (None: nothing proposed)."""
        proposed = self.criticisms[0].missing()
        return proposed[0].effect if proposed else None

    def reduction(self, channel: str) -> float | None:
        """Fractional RMSE reduction of a channel from the start to the last step."""
        before, after = (getattr(s, _STEP_RMSE[channel]) for s in (self.history[0],
                                                                   self.history[-1]))  # fmt: skip
        return None if before is None or after is None else float(1 - after / before)

    @property
    def passed(self) -> bool:
        """Control: nothing proposed. Else: the hidden effect(s) found in as many
        rounds, the first of them ranked first, the key channel's error down ≥ 80 %."""
        if not self.hidden:
            return self.first is None
        key = self.reduction(KEY_CHANNEL[self.scenario])
        return (
            self.first in self.hidden
            and sorted(self.added) == sorted(self.hidden)
            and key is not None
            and key >= 0.8
        )

    def row(self) -> dict[str, Any]:
        """Table row: ranked first, what was added, RMSE per step, ΔIC per round."""
        return {
            "scenario": self.scenario,
            "seed": self.seed,
            "hidden": list(self.hidden),
            "ranked_first": self.first,
            "added": self.added,
            "delta_ic": [c.missing()[0].delta_ic for c in self.criticisms if c.missing()],
            "frequency_rmse_hz": [s.frequency_rmse_hz for s in self.history],
            "damping_rmse": [s.damping_rmse for s in self.history],
            "harmonic_rmse": [s.harmonic_rmse for s in self.history],
            "reduction": {c: self.reduction(c) for c in _STEP_RMSE},
            "key_channel": KEY_CHANNEL.get(self.scenario),
            "proposed_at_start": [c.effect for c in self.criticisms[0].missing()],
            "passed": self.passed,
        }


def hidden_effect_study(
    scenario: str,
    seed: int = 0,
    *,
    assemblies: int = 3,
    levels: int = 8,
    hold_s: float = 2.5,
    rounds: int = 3,
) -> StudyResult:
    """Run a rig scenario through the loop: fit the base model, criticise, add, repeat.

    The rig (:func:`identification.rig.rig_for_preset`) draws ``assemblies`` assemblies
    and their noise as :meth:`~identification.rig.Rig.write_campaign` does (seeds
    ``[seed, a]`` and ``[seed, a, 1]``) but keeps the records in memory. The
    user's starting model is the preset's base model with its coefficients
    fitted to the backbones alone (frequency and damping, as a user's first fit
    is); the criticism uses the harmonics the backbones carry too. Each round adds
    the effect ranked first, until nothing significant is missing or ``rounds``
    effects were added.
    """
    rig = rig_for_preset(scenario, levels=levels, hold_s=hold_s)
    records = []
    for a in range(1, assemblies + 1):
        model, gain = rig.draw(np.random.default_rng([seed, a]))
        name = f"Config{rig.config}_PRT_Assemb{a}"
        records.append(rig.simulate(model, gain, np.random.default_rng([seed, a, 1]), name))
    measured = extract_backbones(records)
    start = fit_backbones(RIG_PRESETS[scenario].base_model, measured.without_harmonics()).model
    result = StudyResult(
        scenario, seed, RIG_PRESETS[scenario].hidden_effects, measured, records, start
    )
    crit = criticize(start, measured)
    result.criticisms.append(crit)
    for _ in range(rounds):
        proposed = crit.missing()
        if not proposed:
            break
        crit = crit.add(proposed[0].effect)
        result.criticisms.append(crit)
    return result


# ---------------------------------------------------------------------------
# Table-5 study


def table5_study(
    parameters: np.ndarray,
    backbones: np.ndarray,
    spec: SurrogateSpec,
    *,
    sizes: Sequence[int] = (200, 300, 400, 500),
    test: tuple[np.ndarray, np.ndarray] | None = None,
    n_test: int = 100,
    config: TrainingConfig | None = None,
    seed: int = 0,
) -> list[dict[str, Any]]:
    """The paper's Table 5: accuracy against the number of training curves.

    Each size trains a fresh surrogate on the first ``size`` curves of one seeded
    permutation (so the sets are nested) and evaluates it on the same test set:
    ``test`` if given, else ``n_test`` curves held out from the data. A size counts
    every curve handed to training, its validation split included, as the
    paper's "Datasize" does.

    Returns
    -------
    list of dict
        One row per size: ``n_train``, the :func:`backbone_metrics` headline
        figures, frequency MAPE, training seconds, and the paper's MSE / MAE /
        MAPE for that size (None where the paper has no row).
    """
    config = config or TrainingConfig()
    parameters = spec.check_parameters(parameters)
    backbones = spec.check_backbones(backbones)
    order = np.random.default_rng(seed).permutation(len(parameters))
    if test is None:
        test_index, order = order[:n_test], order[n_test:]
        test = (parameters[test_index], backbones[test_index])
    x_test, y_test = (
        spec.check_parameters(test[0], "test parameters"),
        spec.check_backbones(test[1]),
    )
    if max(sizes) > order.size:
        raise ValueError(f"size {max(sizes)} asked for, only {order.size} training curves exist")
    rows = []
    for size in sizes:
        subset = order[:size]
        start = time.perf_counter()
        surrogate = train_surrogate(parameters[subset], backbones[subset], spec, config)
        seconds = time.perf_counter() - start
        metrics = backbone_metrics(surrogate.predict(x_test), y_test, spec)
        paper = PAPER_TABLE5.get(size, (None, None, None))
        rows.append(
            {
                "n_train": size,
                "mse_amplitude_mm2": metrics.get("mse_amplitude_mm2"),
                "mae_amplitude_mm": metrics.get("mae_amplitude_mm"),
                "mape_amplitude_pct": metrics["channels"].get("amplitude_m", {}).get("mape_pct"),
                "mape_frequency_pct": metrics["channels"].get("frequency_hz", {}).get("mape_pct"),
                "pearson": metrics["pearson"],
                "pearson_min_channel": metrics["pearson_min_channel"],
                "train_s": seconds,
                "paper_mse": paper[0],
                "paper_mae": paper[1],
                "paper_mape": paper[2],
            }
        )
    return rows


# ---------------------------------------------------------------------------
# Population-coverage study


def synthetic_campaign(
    model: JointModel,
    names: Sequence[str],
    log_mean: ArrayLike,
    log_spread: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    n_curves: int = 25,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    rng: np.random.Generator | int | None = None,
) -> tuple[BackboneSet, np.ndarray]:
    """Backbones of assemblies drawn from a known population, with measurement noise.

    Curve i has ``θ_i = θ0·exp(log_mean + log_spread·N(0, 1))`` (θ0 the template's
    values of ``names``, the hierarchical model's population), its
    single-harmonic backbone at ``amplitudes_m``, and independent Normal noise:
    ``frequency_noise_hz`` on each frequency, ``damping_noise`` relative on each
    damping ratio. Returns the curves and the θ_i ``(n_curves, len(names))``.
    """
    rng = np.random.default_rng(rng)
    theta0 = np.array([model.parameters[n] for n in names])
    eta = np.asarray(log_mean, float) + np.asarray(log_spread, float) * rng.standard_normal(
        (n_curves, theta0.size)
    )
    theta = theta0 * np.exp(eta)
    hb = backbone(model, amplitudes_m, parameters=theta, names=names)
    if not hb.converged.all():
        raise ValueError(
            f"some draws of the population of {list(names)} have no backbone at every amplitude "
            "(no positive stiffness?): narrow log_spread or move log_mean"
        )
    frequency = hb.frequency_hz + frequency_noise_hz * rng.standard_normal(hb.frequency_hz.shape)
    damping = hb.damping_ratio * (1 + damping_noise * rng.standard_normal(hb.damping_ratio.shape))
    curves = [
        Backbone(hb.amplitude_m, f, d, label=f"assembly{i + 1}", source="synthetic_campaign")
        for i, (f, d) in enumerate(zip(frequency, damping, strict=True))
    ]
    return BackboneSet(curves), theta


def pll_campaign(
    model: JointModel,
    names: Sequence[str],
    theta: np.ndarray,
    excitation_levels: ArrayLike,
    *,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    noise_slope: float = -0.3,
    rng: np.random.Generator | int | None = None,
) -> BackboneSet:
    """Backbones of assemblies ``theta`` as the PLL simulator measures them, with noise.

    Each assembly is held at every base-acceleration level of
    ``excitation_levels`` (m/s²) under phase-locked-loop control
    (:func:`~identification.analytical.pll.pll_backbones`: time integration,
    every harmonic, not the single-harmonic balance the hierarchical model
    infers with). Noise grows towards small responses, as extraction noise
    does: ``frequency_noise_hz·(a/a_ref)^noise_slope`` on each frequency and
    the relative ``damping_noise`` times the same factor on each damping ratio
    (``a_ref`` the geometric mean of the campaign's amplitudes). Holds the
    loop did not lock are left out of their curve.
    """
    rng = np.random.default_rng(rng)
    result = pll_backbones(model, excitation_levels, theta, list(names), progress=False)
    locked = result.locked & np.isfinite(result.frequency_hz)
    amplitude = result.amplitude_m
    factor = (amplitude / np.exp(np.mean(np.log(amplitude[locked])))) ** noise_slope
    frequency = result.frequency_hz + frequency_noise_hz * factor * rng.standard_normal(
        amplitude.shape
    )
    damping = result.damping_ratio * (
        1 + damping_noise * factor * rng.standard_normal(amplitude.shape)
    )
    return BackboneSet(
        Backbone(
            amplitude[i, ok],
            frequency[i, ok],
            damping[i, ok],
            label=f"assembly{i + 1}",
            source="pll_campaign",
        )
        for i, ok in enumerate(locked)
    )


def binomial_bounds(n: int, prob: float, level: float = 0.95) -> tuple[int, int]:
    """Two-sided ``level`` acceptance region of a Binomial(n, prob) count (equal tails)."""
    tail = 0.5 * (1 - level)
    return int(stats.binom.ppf(tail, n, prob)), int(stats.binom.isf(tail, n, prob))


@dataclass(frozen=True)
class Coverage:
    """Central intervals of the population parameters over simulated campaigns.

    ``truth_mean``/``truth_spread`` are the ``(n_campaigns, n_params)`` log-locations
    ``μ`` and log-spreads ``σ`` each campaign was drawn with (from the prior);
    ``mean_interval``/``spread_interval`` the ``(n_campaigns, n_params, 2)``
    central ``prob`` intervals; ``divergences`` and ``max_rhat`` per campaign.
    """

    names: tuple[str, ...]
    truth_mean: np.ndarray
    truth_spread: np.ndarray
    mean_interval: np.ndarray
    spread_interval: np.ndarray
    divergences: np.ndarray
    max_rhat: np.ndarray
    prob: float

    @staticmethod
    def _inside(interval: np.ndarray, truth: np.ndarray) -> np.ndarray:
        return (interval[..., 0] <= truth) & (truth <= interval[..., 1])

    @property
    def mean_covered(self) -> np.ndarray:
        return self._inside(self.mean_interval, self.truth_mean)

    @property
    def spread_covered(self) -> np.ndarray:
        return self._inside(self.spread_interval, self.truth_spread)

    @property
    def n_campaigns(self) -> int:
        return int(self.truth_mean.shape[0])

    def bounds(self, level: float = 0.95) -> tuple[int, int]:
        """Counts per parameter a calibrated model gives with probability ``level``.

        Campaigns are independent, so each parameter's count is Binomial(n_campaigns,
        prob); the parameters of one campaign share its data, so counts pooled over
        parameters are not binomial and get no bounds here.
        """
        return binomial_bounds(self.n_campaigns, self.prob, level)

    def within_bounds(self, level: float = 0.95) -> bool:
        low, high = self.bounds(level)
        counts = np.concatenate([self.mean_covered.sum(0), self.spread_covered.sum(0)])
        return bool(np.all((counts >= low) & (counts <= high)))

    def to_dict(self, level: float = 0.95) -> dict[str, Any]:
        low, high = self.bounds(level)
        return {
            "parameters": list(self.names),
            "n_campaigns": self.n_campaigns,
            "prob": self.prob,
            "binomial_bounds": [low, high],
            "bounds_level": level,
            "mean_covered": dict(zip(self.names, self.mean_covered.sum(0).tolist(), strict=True)),
            "spread_covered": dict(
                zip(self.names, self.spread_covered.sum(0).tolist(), strict=True)
            ),
            "within_bounds": self.within_bounds(level),
            "divergences": self.divergences.tolist(),
            "max_rhat": self.max_rhat.tolist(),
        }

    def __str__(self) -> str:
        low, high = self.bounds()
        parts = []
        for label, covered in (("mean", self.mean_covered), ("spread", self.spread_covered)):
            counts = ", ".join(
                f"{n} {c}/{self.n_campaigns}"
                for n, c in zip(self.names, covered.sum(0), strict=True)
            )
            parts.append(f"log-{label}: {counts}")
        return (
            f"{100 * self.prob:g} % intervals holding the truth over {self.n_campaigns} "
            f"campaigns ({'; '.join(parts)}); calibrated: each count in [{low}, {high}] "
            f"(two-sided 95 % binomial); divergences per campaign {self.divergences.tolist()}, "
            f"max r̂ {float(self.max_rhat.max()):.3f}"
        )


def population_coverage(
    model: JointModel,
    names: Sequence[str],
    excitation_levels: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    n_campaigns: int = 20,
    n_curves: int = 25,
    location_scale: float = 0.05,
    population_scale: float = 0.1,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    prob: float = 0.9,
    sampler: str = "nuts",
    target_accept: float = 0.95,
    draws: int = 500,
    tune: int = 500,
    chains: int = 2,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    seed: int = 0,
    progress: bool = True,
) -> Coverage:
    """Simulation-based calibration of :func:`hierarchical_model` on PLL-simulated campaigns.

    Each of ``n_campaigns`` campaigns draws its truth from the model's own
    prior, ``μ ~ N(0, location_scale)`` and ``σ ~ HalfNormal(population_scale)``
    per parameter, then ``n_curves`` assemblies ``θ_i = θ0·exp(μ + σ z_i)``,
    measured by the PLL simulator at ``excitation_levels`` with noise
    (:func:`pll_campaign`); every curve is interpolated at ``amplitudes_m``
    (which all curves must reach; campaigns then share one compiled model)
    and the hierarchical model, with the same priors, is sampled. A calibrated
    model holds the truth in its central ``prob`` intervals of ``log_mean``
    and ``log_spread`` in about ``prob`` of the campaigns
    (:meth:`Coverage.bounds` gives the two-sided binomial region). The data
    come from the time-domain PLL, the inference from single-harmonic
    balance: model error shows here as undercoverage. ``target_accept`` is
    closer to 1 than PyMC's 0.8: spreads drawn from the prior come near 0,
    where the posterior of the spread narrows and NUTS diverges at large steps.
    """
    from tqdm.auto import tqdm

    names = tuple(names)
    theta0 = np.array([model.parameters[n] for n in names])
    truths_mean, truths_spread, means, spreads, divergences, rhats = [], [], [], [], [], []
    tail = 0.5 * (1 - prob)
    for campaign in tqdm(range(n_campaigns), desc="campaigns", disable=not progress):
        rng = np.random.default_rng([seed, campaign])
        mu = location_scale * rng.standard_normal(theta0.size)
        sigma = np.abs(population_scale * rng.standard_normal(theta0.size))
        theta = theta0 * np.exp(mu + sigma * rng.standard_normal((n_curves, theta0.size)))
        measured = pll_campaign(
            model, names, theta, excitation_levels, frequency_noise_hz=frequency_noise_hz,
            damping_noise=damping_noise, rng=rng,
        )  # fmt: skip
        pm_model = hierarchical_model(
            model, measured, names, amplitudes_m=amplitudes_m, channels=channels,
            location_scale=location_scale, population_scale=population_scale,
        )  # fmt: skip
        idata = sample(
            pm_model, sampler=sampler, draws=draws, tune=tune, chains=chains,
            random_seed=seed + campaign, progressbar=False,
            step_options={"target_accept": target_accept},
        )  # fmt: skip
        intervals = []
        for variable in ("log_mean", "log_spread"):
            values = idata.posterior[variable].values.reshape(-1, len(names))
            intervals.append(np.quantile(values, [tail, 1 - tail], axis=0).T)
        truths_mean.append(mu)
        truths_spread.append(sigma)
        means.append(intervals[0])
        spreads.append(intervals[1])
        divergences.append(int(idata.sample_stats["diverging"].sum()))
        rhats.append(max(r["r_hat"] for r in convergence_verdict(idata).parameters))
    return Coverage(
        names, np.array(truths_mean), np.array(truths_spread), np.array(means),
        np.array(spreads), np.array(divergences), np.array(rhats), prob,
    )  # fmt: skip
