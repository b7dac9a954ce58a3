"""The calibration of the hierarchical model's intervals: simulation-based coverage of its
population parameters over PLL-simulated campaigns drawn from its own prior."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.model import JointModel
from pm_joint.analysis import convergence_verdict
from pm_joint.inference import HIERARCHICAL_TARGET_ACCEPT, hierarchical_model, sample
from studies.binomial import binomial_bounds
from studies.campaigns import pll_campaign

__all__ = ["Coverage", "population_coverage"]


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
    amplitudes_m: ArrayLike | None = None,
    *,
    n_campaigns: int = 20,
    n_curves: int = 25,
    location_scale: float = 0.05,
    population_scale: float = 0.1,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    prob: float = 0.9,
    sampler: str = "nuts",
    target_accept: float = HIERARCHICAL_TARGET_ACCEPT,
    draws: int = 500,
    tune: int = 500,
    chains: int = 2,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    seed: int = 0,
    centred: bool | str = "auto",
    truncation: int | None = 5,
    progress: bool = True,
) -> Coverage:
    """Simulation-based calibration of :func:`hierarchical_model` on PLL-simulated campaigns.

    Each of ``n_campaigns`` campaigns draws its truth from the model's own
    prior, ``μ ~ N(0, location_scale)`` and ``σ ~ HalfNormal(population_scale)``
    per parameter, then ``n_curves`` assemblies ``θ_i = θ0·exp(μ + σ z_i)``,
    measured by the PLL simulator at ``excitation_levels`` with noise
    (:func:`pll_campaign`); the hierarchical model, with the same priors, is
    sampled on every measured point (``amplitudes_m`` None, as
    ``pm-joint update --population hierarchical`` runs it) or on each curve
    interpolated at those of ``amplitudes_m`` it reached. A calibrated model
    holds the truth in its central ``prob`` intervals of ``log_mean`` and
    ``log_spread`` in about ``prob`` of the campaigns (:meth:`Coverage.bounds`
    gives the two-sided binomial region). The data
    come from the time-domain PLL, the inference from single-harmonic
    balance: model error shows here as undercoverage (``truncation``, the
    hierarchical model's, subtracts the harmonic-balance gap). ``target_accept`` is
    closer to 1 than PyMC's 0.8: spreads drawn from the prior come near 0,
    where the posterior of the spread narrows and NUTS diverges at large steps.
    ``centred`` picks the hierarchical model's parametrisation (its ``centred``).
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
            location_scale=location_scale, population_scale=population_scale, centred=centred,
            truncation=truncation,
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
