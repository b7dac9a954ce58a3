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

from identification.analytical.harmonic import backbone
from identification.criticism.criticism import Criticism, Step, criticize
from identification.fitting.least_squares import fit_backbones
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Record
from identification.model import JointModel
from identification.rig import RIG_PRESETS, rig_for_preset
from pm_joint.inference import hierarchical_model, sample
from surrogates.evaluate import PAPER_TABLE5, backbone_metrics
from surrogates.runtime import SurrogateSpec
from surrogates.train import TrainingConfig, train_surrogate

__all__ = [
    "KEY_CHANNEL",
    "Coverage",
    "StudyResult",
    "hidden_effect_study",
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
