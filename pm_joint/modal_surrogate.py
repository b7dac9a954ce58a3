"""``pm-joint train-surrogate`` of an N-mode ModalModel: one surrogate per mode's backbone.

The N-mode twin of :func:`pm_joint.pipeline.train_surrogate_stage`. For every mode the
campaign's ``--modes N`` table carries: the amplitude grid where three of that mode's
measured curves cover (:func:`surrogates.grid.measured_grid`, without asking the curves
for a drive: decays and modal-filter reads need not have one), a dataset of that mode's
backbones over the updating's prior box (:func:`surrogates.dataset.modal.
generate_modal_dataset`, the N-mode harmonic balance the updating otherwise runs on), the
paper's network trained on it and exported as a one-mode surrogate folder
(``OUT/mode{m}``), its test figures beside the baselines and the mode's assembly scatter;
then the index (:class:`surrogates.modal.ModalSurrogate`). Measured curves are not
training data here: an N-mode model's label of one curve would need the curve's every
mode, which a per-mode table does not pair.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from identification.measurements.backbone import BackboneSet
from identification.multimode.model import ModalModel
from pm_joint import plotting
from pm_joint.inference.modal import modal_bounds, modal_update_names
from surrogates.dataset.modal import generate_modal_dataset
from surrogates.grid import assembly_scatter, measured_grid
from surrogates.modal import ModalSurrogate, mode_folder
from surrogates.runtime import SurrogateRuntime

__all__ = ["train_modal_surrogate"]


def train_modal_surrogate(
    model: ModalModel,
    measured: Mapping[int, BackboneSet],
    out: str | os.PathLike,
    *,
    n_curves: int = 500,
    n_amplitudes: int = 41,
    config: Any = None,
    max_epochs: int | None = None,
    seed: int = 0,
    progress: bool = True,
) -> ModalSurrogate:
    """Train and export a surrogate of every measured mode's backbone of ``model``.

    Parameters
    ----------
    model
        The ModalModel (its structure and the values of what is not updated).
    measured
        Each mode's measured backbones, by mode from 1 (what ``update`` scores).
    out
        The folder: ``mode{m}/`` per mode (surrogate, ``dataset.npz``, a prediction
        figure) and the index ``modal_surrogate.json``.
    n_curves, n_amplitudes
        Designed parameter sets (one design, the same for every mode) and grid points.
    config
        A :class:`~surrogates.train.TrainingConfig` (default: the one-mode stage's, the
        paper's network on the residual of a cubic head, damping as a decay rate).
    max_epochs
        Caps every training stage.
    seed, progress
        The design's and the training's seed; progress bars.

    Returns
    -------
    ModalSurrogate
        The exported surrogates, loaded back.
    """
    # torch only here: `pm-joint update` never loads it.
    from surrogates.export import export_surrogate
    from surrogates.train import stage_config, train_on_dataset

    out = Path(out)
    names = modal_update_names(model)
    bounds = modal_bounds(model, names, measured)
    box = np.array([bounds[n] for n in names])
    config = stage_config(config, seed=seed, progress=progress, max_epochs=max_epochs)
    runtimes = {}
    for mode in sorted(measured):
        grid = measured_grid(measured[mode], n_amplitudes, drive=False)
        scatter = assembly_scatter(measured[mode], grid.amplitudes_m, drive=False)
        dataset = generate_modal_dataset(
            model, names, box, grid.amplitudes_m, mode=mode, n=n_curves, seed=seed
        )
        dataset = dataclasses.replace(
            dataset, provenance={**dataset.provenance, "grid": grid.to_dict()}
        ).with_splits(0.1, 0.1, seed=seed)
        folder = mode_folder(out, mode)
        dataset.save(folder / "dataset.npz")
        by_channel = {"frequency_hz": scatter[:, 0], "damping_ratio": scatter[:, 1]}
        export_surrogate(train_on_dataset(dataset, config, scatter=by_channel), folder)
        runtimes[mode] = SurrogateRuntime.load(folder)
        figure = plotting.plot_surrogate_check(runtimes[mode], dataset)
        plotting.save_png(figure, folder / "surrogate_predictions.png", dpi=110)
    surrogate = ModalSurrogate(runtimes, model.content_sha256, out)
    surrogate.write_index(out)
    return surrogate
