"""Studies of the method on simulated campaigns, for bench/, case_studies/ and slow tests.

Nothing in the library imports this module: a study runs the library many
times (training surrogates, sampling posteriors) to measure how well it works.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.harmonic import backbone
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel
from pm_joint.inference import hierarchical_model, sample
from surrogates.evaluate import PAPER_TABLE5, backbone_metrics
from surrogates.runtime import SurrogateSpec
from surrogates.train import TrainingConfig, train_surrogate

__all__ = ["Coverage", "population_coverage", "synthetic_campaign", "table5_study"]


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


@dataclass(frozen=True)
class Coverage:
    """Intervals of the population log-location ``μ`` over synthetic campaigns.

    ``lower``/``upper`` are ``(n_campaigns, n_params)`` central ``prob``
    intervals, ``truth`` the ``μ`` the campaigns were drawn with,
    ``divergences`` the NUTS divergences per campaign.
    """

    names: tuple[str, ...]
    truth: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    divergences: np.ndarray
    prob: float

    @property
    def covered(self) -> np.ndarray:
        return (self.lower <= self.truth) & (self.truth <= self.upper)

    @property
    def count(self) -> int:
        return int(self.covered.sum())

    def __str__(self) -> str:
        per_parameter = ", ".join(
            f"{n} {c}/{len(self.covered)}"
            for n, c in zip(self.names, self.covered.sum(0), strict=True)
        )
        return (
            f"population log-mean inside the {100 * self.prob:g} % interval in {self.count} of "
            f"{self.covered.size} cases ({per_parameter}); NUTS divergences per campaign: "
            f"{self.divergences.tolist()}"
        )


def population_coverage(
    model: JointModel,
    names: Sequence[str],
    log_mean: ArrayLike,
    log_spread: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    n_campaigns: int = 20,
    n_curves: int = 25,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    prob: float = 0.9,
    draws: int = 500,
    tune: int = 500,
    chains: int = 2,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    seed: int = 0,
    progress: bool = True,
) -> Coverage:
    """Simulation-based check of :func:`hierarchical_model`: how often its interval holds the truth.

    Draws ``n_campaigns`` campaigns of ``n_curves`` assemblies with
    :func:`synthetic_campaign` (its noise levels), samples each with NUTS and
    records the central ``prob`` interval of every ``log_mean``. A calibrated
    model holds the truth in about ``prob`` of the cases. Campaigns share their
    amplitudes, so the compiled model is reused (numba's cache) after the first.
    """
    from tqdm.auto import tqdm

    names = tuple(names)
    truth = np.asarray(log_mean, dtype=float)
    lower, upper, divergences = [], [], []
    tail = 0.5 * (1 - prob)
    for campaign in tqdm(range(n_campaigns), desc="campaigns", disable=not progress):
        measured, _ = synthetic_campaign(
            model, names, truth, log_spread, amplitudes_m,
            n_curves=n_curves, frequency_noise_hz=frequency_noise_hz,
            damping_noise=damping_noise, rng=[seed, campaign],
        )  # fmt: skip
        pm_model = hierarchical_model(model, measured, names, channels=channels)
        idata = sample(
            pm_model, sampler="nuts", draws=draws, tune=tune, chains=chains,
            random_seed=seed + campaign, progressbar=False,
        )  # fmt: skip
        draws_mu = idata.posterior["log_mean"].values.reshape(-1, len(names))
        low, high = np.quantile(draws_mu, [tail, 1 - tail], axis=0)
        lower.append(low)
        upper.append(high)
        divergences.append(int(idata.sample_stats["diverging"].sum()))
    return Coverage(names, truth, np.array(lower), np.array(upper), np.array(divergences), prob)
