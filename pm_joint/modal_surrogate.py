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
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from identification.measurements.backbone import BackboneSet
from identification.multimode.model import FORMAT as MODAL_FORMAT
from identification.multimode.model import ModalModel
from pm_joint import plotting
from pm_joint.forward.modal_harmonic import modal_backbone_numpy, template_values
from pm_joint.inference.modal import modal_bounds, modal_update_names
from surrogates.dataset.modal import ModeBackbones, ModeEvaluation, generate_modal_dataset
from surrogates.grid import assembly_scatter, measured_grid
from surrogates.modal import ModalSurrogate, mode_folder
from surrogates.runtime import SurrogateRuntime

__all__ = ["mode_evaluation", "train_modal_surrogate"]


def mode_evaluation(
    model: ModalModel, names: Sequence[str], amplitudes_m: np.ndarray, mode: int
) -> ModeEvaluation:
    """Mode ``mode``'s backbones of parameter sets on ``amplitudes_m``, from the N-mode
    harmonic balance (:func:`~pm_joint.forward.modal_harmonic.modal_backbone_numpy`, many
    sets at once): the hold's drive from the power balance ``ζ = Γ A / (2 ω² a)``, the
    other modes' share from the balance's energy shares."""
    participation = template_values(model)[f"mode{mode}.participation"]

    def evaluate(parameters: np.ndarray) -> ModeBackbones:
        out = modal_backbone_numpy(model, parameters, list(names), amplitudes_m, mode=mode)
        omega = 2 * np.pi * out.frequency_hz
        return ModeBackbones(
            frequency_hz=out.frequency_hz,
            damping_ratio=out.damping_ratio,
            drive_m_s2=2 * omega**2 * amplitudes_m * out.damping_ratio / participation,
            other_modes_energy_share=1 - np.asarray(out.energy_share)[..., mode - 1],
            settled=np.asarray(out.converged, dtype=bool),
        )

    return evaluate


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
            mode_evaluation(model, names, grid.amplitudes_m, mode), names, box,
            grid.amplitudes_m, n=n_curves, seed=seed,
            provenance={"model": model.to_dict(), "model_format": MODAL_FORMAT, "mode": mode,
                        "method": "modal_harmonic"},
        )  # fmt: skip
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
