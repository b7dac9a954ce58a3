"""The paper's Table 5: surrogate accuracy against the number of training curves."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from studies.rows import Row
from surrogates.dataset import BackboneDataset
from surrogates.evaluate import PAPER_TABLE5
from surrogates.train import TrainingConfig, train_on_dataset

__all__ = ["Table5Row", "table5_study"]


@dataclass(frozen=True, kw_only=True)
class Table5Row(Row):
    """One training size of :func:`table5_study`.

    Attributes
    ----------
    n_train, n_validation, n_test
        Curves of each split.
    rmse_frequency_hz
        Frequency RMSE (Hz) of the surrogate on the test split's analytical curves.
    rmse_frequency_hz_linear, rmse_frequency_hz_cubic, rmse_frequency_hz_mean_curve
        The same of the baselines.
    frequency_to_linear, frequency_to_cubic, frequency_to_scatter_max
        The surrogate's frequency RMSE over the linear and cubic baselines' and over the
        scatter.
    table5_representation
        How the paper's amplitude figures were made.
    mse_amplitude_mm2, mae_amplitude_mm, mape_amplitude_pct
        The paper's amplitude figures at excitation levels
        (:func:`~surrogates.evaluate.table5_figures`).
    train_s
        Training seconds.
    paper_mse, paper_mae, paper_mape
        The paper's figures for this size (None where the paper has no row).
    """

    n_train: int
    n_validation: int
    n_test: int
    rmse_frequency_hz: float | None
    rmse_frequency_hz_linear: float | None
    rmse_frequency_hz_cubic: float | None
    rmse_frequency_hz_mean_curve: float | None
    frequency_to_linear: float | None
    frequency_to_cubic: float | None
    frequency_to_scatter_max: float | None
    table5_representation: str | None
    mse_amplitude_mm2: float | None
    mae_amplitude_mm: float | None
    mape_amplitude_pct: float | None
    train_s: float
    paper_mse: float | None
    paper_mae: float | None
    paper_mape: float | None


def table5_study(
    dataset: BackboneDataset,
    *,
    sizes: Sequence[int] = (200, 300, 400, 500),
    config: TrainingConfig | None = None,
    seed: int = 0,
    scatter: Mapping[str, ArrayLike] | None = None,
) -> list[Table5Row]:
    """The paper's Table 5: accuracy against the number of training curves, on test figures.

    Each size trains a fresh surrogate on the first ``size`` curves of one seeded
    permutation of the dataset's train split (so the sets are nested), stops it
    early on the whole validation split and scores it on the test split, beside
    the linear, cubic and mean-curve baselines fitted on the same curves
    (:func:`~surrogates.evaluate.accuracy_report`).

    Parameters
    ----------
    dataset
        The dataset, with its splits.
    sizes
        Training sizes.
    config
        Training settings.
    seed
        Seed of the permutation of the train split.
    scatter
        The measured scatter per channel, for the ratios to it.

    Returns
    -------
    list of Table5Row
        One row per size.
    """
    train = np.random.default_rng(seed).permutation(dataset.in_split("train"))
    others = np.concatenate([dataset.in_split("validation"), dataset.in_split("test")])
    if max(sizes) > train.size:
        raise ValueError(f"size {max(sizes)} asked for, only {train.size} training curves exist")
    rows = []
    for size in sizes:
        subset = dataset.subset(np.sort(np.concatenate([train[:size], others])))
        surrogate = train_on_dataset(subset, config, scatter=scatter)
        # the surrogate's test report is a nested dict (surrogates.evaluate.accuracy_report)
        report = surrogate.test_report
        analytical = report["analytical"] or {}
        frequency = {
            name: figures.get("frequency_hz", {}).get("rmse")
            for name, figures in analytical.get("models", {}).items()
        }
        ratios = analytical.get("ratios", {}).get("frequency_hz", {})
        table5 = report["table5"] or {}
        amplitude = table5.get("surrogate", {})
        paper = PAPER_TABLE5.get(size, (None, None, None))
        rows.append(
            Table5Row(
                n_train=size,
                n_validation=surrogate.n_validation,
                n_test=report["counts"]["all"]["test"],
                rmse_frequency_hz=frequency.get("surrogate"),
                rmse_frequency_hz_linear=frequency.get("linear"),
                rmse_frequency_hz_cubic=frequency.get("cubic"),
                rmse_frequency_hz_mean_curve=frequency.get("mean_curve"),
                frequency_to_linear=ratios.get("to_linear"),
                frequency_to_cubic=ratios.get("to_cubic"),
                frequency_to_scatter_max=ratios.get("to_scatter_max"),
                table5_representation=table5.get("representation"),
                mse_amplitude_mm2=amplitude.get("mse_amplitude_mm2"),
                mae_amplitude_mm=amplitude.get("mae_amplitude_mm"),
                mape_amplitude_pct=amplitude.get("mape_amplitude_pct"),
                train_s=surrogate.train_seconds,
                paper_mse=paper[0],
                paper_mae=paper[1],
                paper_mape=paper[2],
            )
        )
    return rows
