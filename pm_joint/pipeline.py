"""The pipeline stages, in the order of the science.

records → backbones → SINDy model → analytical backbones → surrogate →
updating → criticism → report. A stage reads what it needs from a
:class:`~pm_joint.workspace.Workspace`, calls the library, writes its artifacts,
puts what it made back into the workspace and returns it; the ``pm-joint``
subcommands and the demo call these and nothing else. Figures come from
:mod:`pm_joint.plotting`, the page from :mod:`pm_joint.html`.
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import warnings
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import xarray as xr

from identification.analytical import harmonic, pll
from identification.artifacts import atomic_write_text
from identification.criticism.moves import run_rounds
from identification.criticism.participation import ModeParticipation, locked_mode
from identification.fitting.least_squares import default_free
from identification.measurements.backbone import Backbone, BackboneSet, read_backbone_table
from identification.measurements.columns import ColumnCampaign
from identification.measurements.decay import extract_decay_backbone
from identification.measurements.decay_modes import (
    ModalDecay,
    modal_decay_table,
    record_decay_modes,
    record_second_mode,
)
from identification.measurements.modal_backbones import (
    ModalBackboneSet,
    extract_modal_backbones,
    mode_backbones,
    second_mode_warnings,
)
from identification.measurements.modal_filter import SECOND_MODE_SHARE
from identification.measurements.modes import Modes, read_modes
from identification.measurements.records import Campaign
from identification.model import JointModel, parameter_bounds
from identification.rig import RIG_PRESETS, ForceRig, rig_for_preset
from identification.sindy import (
    PAPER_LIBRARY,
    Identification,
    identify,
    record_kinematics,
    validate,
)
from pm_joint import html, plotting
from pm_joint.analysis import (
    attach_loo,
    convergence_verdict,
    identifiability,
    population_predictive,
)
from pm_joint.inference import (
    amplitudes_within_surrogate,
    build_model,
    continue_sampling,
    hierarchical_model,
    sample,
    save_posterior,
)
from pm_joint.inference.traces import earlier_trace
from pm_joint.inference.varying import varying_parameters
from pm_joint.report_folder import report
from pm_joint.sampler_defaults import (
    GRADIENT_SAMPLERS,
    run_settings,
    sampler_reason,
)
from pm_joint.workspace import Workspace
from surrogates.dataset import add_measured, generate_dataset, record_labels
from surrogates.grid import GRID_CHANNELS, assembly_scatter, measured_grid
from surrogates.labels import MisfitPolicy
from surrogates.runtime import SurrogateRuntime

if TYPE_CHECKING:
    from surrogates.train import TrainingConfig

__all__ = [
    "analytical_backbones",
    "campaign_backbones",
    "campaign_decay_modes",
    "campaign_modal_backbones",
    "criticize_campaign",
    "decay_second_mode_warnings",
    "identify_campaign",
    "label_records",
    "posterior_report",
    "run_report",
    "second_mode_warnings",
    "surrogate_box",
    "train_surrogate_stage",
    "update_backbones",
    "write_rig_campaign",
]


def write_rig_campaign(
    preset: str,
    out: str | os.PathLike,
    *,
    assemblies: int = 25,
    runs: int = 1,
    seed: int = 0,
    n_levels: int = 10,
    workers: int | None = 1,
    progress: bool = True,
    executor: Any = None,
    force_driven: bool = False,
    quantity: str = "velocity",
) -> Campaign | ColumnCampaign:
    """Write a virtual campaign of the rig preset ``preset`` in the TRC layout.

    ``n_levels`` excitation levels per record. With ``force_driven`` the
    structure is driven by a measured force and each record ends in a
    ring-down, written in the column layout with a ``quantity`` response
    (:class:`~identification.rig.force.ForceRig`). Records are simulated and
    written by ``workers`` processes (None: one per CPU); the files do not
    depend on it. With more than one, call this from a script's
    ``if __name__ == "__main__":`` block: worker processes start by importing
    the main script. An ``executor`` (e.g. a dask Client) replaces the
    ``workers`` processes.
    """
    if preset not in RIG_PRESETS:
        raise ValueError(f"unknown rig preset {preset!r}; available: {', '.join(RIG_PRESETS)}")
    if force_driven:
        rig = ForceRig.preset(preset, levels=n_levels, response_quantity=quantity)
    else:
        rig = rig_for_preset(preset, levels=n_levels)
    workers = min(workers or os.cpu_count() or 1, assemblies * runs)
    options = {"assemblies": assemblies, "runs": runs, "seed": seed, "progress": progress}
    if executor is not None or workers < 2:
        return rig.write_campaign(out, executor=executor, **options)
    # forkserver: workers start from a clean process, not a fork of this
    # (possibly multi-threaded) one.
    context = multiprocessing.get_context("forkserver")
    with ProcessPoolExecutor(workers, mp_context=context) as executor:
        return rig.write_campaign(out, executor=executor, **options)


def campaign_backbones(
    workspace: Workspace,
    *,
    mode_shapes: str | os.PathLike | Modes | None = None,
    second_mode_share: float = SECOND_MODE_SHARE,
) -> BackboneSet:
    """Extract the backbones of every record; writes the workspace's CSV and a PNG beside it.

    One mode per record. Driven records whose sensors and given shapes (a TRC
    modes file, or ``mode_shapes``) show another mode carrying more than
    ``second_mode_share`` of a hold's energy get one warning line each
    (:func:`~identification.measurements.modal_backbones.second_mode_warnings`);
    the backbones do not depend on it.
    """
    backbones = workspace.extract_backbones()
    figure = plotting.plot_measured_backbones(backbones)
    plotting.save_png(figure, workspace.backbones_csv.with_suffix(".png"), dpi=110)
    shapes = _mode_shapes(mode_shapes, workspace)
    if workspace.layout.test != "free-decay" and _most_given_modes(workspace, shapes) >= 2:
        lines = second_mode_warnings(
            workspace.records, mode_shapes=shapes, n_periods=workspace.n_periods,
            threshold=second_mode_share,
        )  # fmt: skip
        for line in lines:
            warnings.warn(line, stacklevel=2)
    return backbones


def _most_given_modes(workspace: Workspace, mode_shapes: Modes | None) -> int:
    """The most mode shapes given to any record (``mode_shapes``, else the TRC modes files),
    found without reading a record again."""
    if mode_shapes is not None:
        return mode_shapes.shapes.shape[1]
    campaign = workspace.campaign
    if not isinstance(campaign, Campaign):
        return 0
    given = [m.shapes.shape[1] for m in campaign.config_modes().values() if m is not None]
    return max(given, default=0)


def campaign_modal_backbones(
    workspace: Workspace,
    n_modes: int,
    *,
    mode_shapes: str | os.PathLike | Modes | None = None,
) -> ModalBackboneSet:
    """Backbones of ``n_modes`` ≥ 2 modes of every record, written to the workspace's CSV.

    The table (a ``mode`` column, each mode's participation) and its sidecar JSON
    (:func:`~identification.measurements.modal_backbones.sidecar_path`: shapes'
    source, reference sensors, alignment and reconstruction errors) are
    described in :mod:`identification.measurements.modal_backbones`; a PNG per
    mode (``…_mode{m}.png``) draws the backbones of the records that locked it.
    Free decays read per mode: :func:`campaign_decay_modes`.
    """
    if workspace.layout.test == "free-decay":
        raise ValueError(
            f"--modes {n_modes} on free decays: use campaign_decay_modes (this reads holds)"
        )
    result = extract_modal_backbones(
        workspace.records, n_modes, mode_shapes=_mode_shapes(mode_shapes, workspace),
        n_periods=workspace.n_periods,
    )  # fmt: skip
    csv = workspace.backbones_csv
    result.to_csv(csv)
    for mode in range(1, n_modes + 1):
        curves = result.mode_backbones(mode)
        if len(curves):
            figure = plotting.plot_measured_backbones(curves)
            plotting.save_png(figure, csv.with_name(f"{csv.stem}_mode{mode}.png"), dpi=110)
    return result


def _mode_shapes(
    mode_shapes: str | os.PathLike | Modes | None, workspace: Workspace
) -> Modes | None:
    """A ``--mode-shapes`` file read (one row per sensor, then the frequencies)."""
    if mode_shapes is None or isinstance(mode_shapes, Modes):
        return mode_shapes
    return read_modes(mode_shapes, decimal_comma=workspace.layout.decimal_comma, points=None)


def campaign_decay_modes(
    workspace: Workspace,
    n_modes: int,
    *,
    mode_shapes: str | os.PathLike | Modes | None = None,
) -> list[ModalDecay]:
    """Each record's free decay by mode (``--test free-decay --modes N``): the
    :class:`~identification.measurements.decay_modes.ModalDecay` of each (several sensors
    through their modal filter, shapes as for :func:`campaign_modal_backbones`), written as
    one table (:func:`~identification.measurements.decay_modes.modal_decay_table`) to the
    workspace's CSV."""
    shapes = _mode_shapes(mode_shapes, workspace)
    decays = [record_decay_modes(r, n_modes, shapes, **workspace.decay_options)
              for r in workspace.records]  # fmt: skip
    atomic_write_text(workspace.backbones_csv, modal_decay_table(decays).to_csv(index=False))
    return decays


def decay_second_mode_warnings(
    workspace: Workspace, *, mode_shapes: str | os.PathLike | Modes | None = None
) -> list[str]:
    """One warning line per free-decay record that a one-mode reading leaves a second mode in
    (a record of several sensors looked at through all of them, shapes as for
    :func:`campaign_modal_backbones`)."""
    shapes = _mode_shapes(mode_shapes, workspace)
    found = (record_second_mode(r, shapes, **workspace.decay_options) for r in workspace.records)
    return [line for line in found if line is not None]


def identify_campaign(
    workspace: Workspace,
    effects: Sequence[str] = PAPER_LIBRARY,
    *,
    n_records: int = 3,
    out: str | os.PathLike | None = None,
    **options: Any,
) -> Identification:
    """SINDy identification from the first ``n_records`` records; the workspace's model becomes it.

    Records that cannot be identified are refused first: a base-driven record
    whose excitation is zero, a free decay that does not decay
    (:func:`~identification.measurements.decay.extract_decay_backbone`; a
    driven column record without an excitation is refused when read). A
    force-driven record drives the model with the equivalent base acceleration
    ``−g·F``, ``g`` its stated or estimated modal forcing gain
    (:mod:`identification.measurements.forcing`); the model keeps the median
    gain as its ``forcing_gain``. With ``out`` (a JSON path) the model is
    written there, with the velocity and acceleration validation figures (the
    paper's Figs. 9–10) beside it.
    """
    chosen = workspace.records[: min(n_records, len(workspace.records))]
    gains = []
    for i, record in enumerate(chosen):
        if record.test == "free-decay":
            extract_decay_backbone(record, **workspace.decay_options)  # refuses a non-decay
        elif not np.any(record.excitation):
            raise ValueError(
                f"{record.path or record.name}: the excitation ({record.excitation_kind}) is "
                "zero throughout: nothing drives this record, and a steady response alone "
                "gives its own frequency as the 'natural' one; a ring-down is read with "
                "--test free-decay"
            )
        if record.excitation_kind == "force":
            gains.append(record.forcing_gain)
            chosen[i] = record.with_forcing_gain(record.forcing_gain)
    result = identify(chosen, list(effects), **options)
    if gains:
        model = result.model.with_forcing_gain(float(np.median(gains)))
        result = dataclasses.replace(result, model=model)
    workspace.model = result.model
    if out is not None:
        out = Path(out)
        result.model.to_json(out)
        preprocessing = {k: options[k] for k in ("n_harmonics", "edge_periods", "band_hz")
                         if k in options}  # fmt: skip
        validation = validate(result.model, record_kinematics(chosen[0], **preprocessing))
        for channel in ("velocity", "acceleration"):
            figure = plotting.plot_validation_figure(validation, channel)
            path = out.with_name(f"{out.stem}_validation_{channel}.png")
            plotting.save_png(figure, path, dpi=100)
    return result


def analytical_backbones(
    workspace: Workspace, out: str | os.PathLike | None = None, *, n_points: int = 41
) -> dict[str, Backbone]:
    """The model's backbone by multi-harmonic balance and by the PLL simulator.

    Both span the measured amplitudes (``n_points`` amplitudes, then as many
    excitation levels); with ``out`` (a PNG path) they are drawn over the
    measured curves (the paper's Fig. 12).
    """
    model, measured = workspace.model, workspace.backbones
    low = min(b.amplitude_range_m[0] for b in measured)
    high = max(b.amplitude_range_m[1] for b in measured)
    amplitudes = np.geomspace(low, high, n_points)
    hb = harmonic.backbone(model, amplitudes, method="multi")
    ok = hb.converged
    curves = {
        "harmonic balance": Backbone(
            hb.amplitude_m[ok], hb.frequency_hz[ok], hb.damping_ratio[ok],
            label="harmonic balance", source=model.name,
        ),
    }  # fmt: skip
    excitation = np.abs(hb.base_acceleration[ok])
    excitation_levels = np.geomspace(excitation.min(), excitation.max(), n_points)
    result = pll.simulate_pll(model, excitation_levels)
    locked = result.locked
    if locked.sum() >= 2:
        curves["PLL"] = Backbone(
            result.amplitude_m[locked], result.frequency_hz[locked],
            result.damping_ratio[locked], excitation_level=result.level[locked],
            label="PLL", source=model.name,
        )  # fmt: skip
    if out is not None:
        plotting.save_png(plotting.plot_analytical_backbones(measured, curves), out, dpi=110)
    return curves


def criticize_campaign(
    folder: str | os.PathLike | Workspace,
    model: JointModel | str | os.PathLike,
    out: str | os.PathLike,
    *,
    rounds: int = 0,
    measured: BackboneSet | None = None,
    posterior=None,
    executor: Any = None,
):
    """Criticize a model against a campaign; optionally add up to ``rounds`` effects
    (forward-backward stepwise: :func:`~identification.criticism.criticism.run_rounds`).

    ``measured`` are the campaign's backbones when already extracted (with the
    harmonics they carry); else the campaign's workspace gives them (its
    ``backbones.csv`` when fresh, else one extraction from the records);
    ``folder`` may be that workspace. A modal backbone table (``pm-joint backbones
    --modes N``: a CSV with a ``mode`` column) gives the backbones of the mode its holds
    are locked on and the next mode's participation, which places a second mode the
    criticism names (:mod:`identification.criticism.participation`).
    ``posterior`` (a DataTree) gives the predictive bands and the medians the
    model is compared at; from a hierarchical posterior these are the draws of
    the population's median assembly, so the test widens by the uncertainty of
    the population-mean curve, not by the scatter of the assemblies
    (:func:`~pm_joint.analysis.posterior.posterior_samples`). Writes
    ``criticism.json`` and figures to ``out`` (for the last round, whose history
    holds every step) and returns the last
    :class:`~identification.criticism.criticism.Criticism`. ``executor`` (a dask
    ``Client``, a ``concurrent.futures`` executor) runs the candidates' refits; the
    report does not depend on it.
    """
    from pm_joint.analysis.posterior import criticize

    if not isinstance(model, JointModel):
        model = JointModel.from_json(model)
    participation = None
    if measured is None:
        workspace = folder if isinstance(folder, Workspace) else Workspace(folder)
        measured, participation = _criticized_backbones(workspace)
    crit = criticize(
        model, measured, posterior=posterior, executor=executor, participation=participation
    )
    crit = run_rounds(crit, rounds)[-1]
    crit.write(out)
    return crit


def _criticized_backbones(
    workspace: Workspace,
) -> tuple[BackboneSet, ModeParticipation | None]:
    """The backbones a criticism compares with, and the next mode's participation where
    the workspace is a modal backbone table (a CSV with a ``mode`` column)."""
    if workspace.is_campaign:
        return workspace.backbones, None
    where = str(workspace.source)
    table = read_backbone_table(workspace.source)
    if "mode" not in table.columns:
        return BackboneSet.from_table(table, source=where), None
    measured = mode_backbones(table, locked_mode(table, where), source=where)
    return measured, ModeParticipation.from_table(table, where)


def label_records(
    workspace: Workspace, names: Sequence[str] | None = None, **options: Any
) -> np.ndarray:
    """Parameters of each record alone (:func:`~surrogates.dataset.record_labels`).

    ``names`` default: :func:`identification.fitting.least_squares.default_free` of the
    workspace's model; rows in the order of the records. ``options`` are the
    identification's preprocessing (``edge_periods``, ``band_hz``), as
    :func:`identify_campaign` takes them.
    """
    model = workspace.model
    return record_labels(workspace.records, model, names or default_free(model), **options)


def surrogate_box(
    model: JointModel,
    names: Sequence[str],
    labels: np.ndarray | None = None,
    relative_spread: float = 0.2,
) -> np.ndarray:
    """``(len(names), 2)`` training box: ± ``relative_spread`` around the model's values,
    widened to cover every label (``(n, len(names))``) by 5 % of its span beyond."""
    box = parameter_bounds(model, list(names), relative_spread)
    if labels is not None:
        labels = np.asarray(labels, dtype=float)
        margin = 0.05 * (box[:, 1] - box[:, 0])
        box[:, 0] = np.minimum(box[:, 0], labels.min(axis=0) - margin)
        box[:, 1] = np.maximum(box[:, 1], labels.max(axis=0) + margin)
    return box


def train_surrogate_stage(
    workspace: Workspace,
    out: str | os.PathLike,
    *,
    labels: np.ndarray | None = None,
    n_curves: int = 500,
    relative_spread: float = 0.2,
    n_amplitudes: int = 41,
    config: TrainingConfig | None = None,
    max_epochs: int | None = None,
    hold_out_measured: bool = True,
    misfit_threshold: float = 1.0,
    misfit_policy: MisfitPolicy = "downweight",
    seed: int = 0,
    progress: bool = True,
    executor: Any = None,
) -> SurrogateRuntime:
    """Amplitude-grid dataset (analytical + measured curves), training and ONNX export.

    The backbones are sampled on ``n_amplitudes`` response amplitudes geometric
    over the amplitudes at least three measured curves cover
    (:func:`surrogates.grid.measured_grid`, recorded in the dataset's provenance
    and the sidecar under ``grid``): frequency, damping ratio,
    base acceleration and the ``has_backbone`` mask, defined for every parameter
    vector of the box, so no analytical curve is dropped. ``labels`` are the
    measured curves' parameters in the order of
    :func:`identification.fitting.least_squares.default_free` (e.g.
    :func:`label_records`); without them only analytical curves are used. The box
    covers ± ``relative_spread`` around the model and every label (5 % of the span
    beyond). Analytical curves make up the rest of ``n_curves``. Each measured
    curve's label misfit (its label's backbone against the curve, in assembly
    standard deviations of frequency) is recorded; beyond ``misfit_threshold`` the
    curve is down-weighted, left out or kept (``misfit_policy``,
    :mod:`surrogates.labels`). Curves are split 80/10/10 into train, validation
    (early stopping) and an independent test split, analytical and measured apart;
    ``hold_out_measured`` (default) puts every measured curve in test, so the
    likelihood's curves are no training data and the measured test figures are
    independent: their labels misfit them (the identified model's damping differs
    from the curves' by tens of assembly SDs), and in validation they would steer
    the early stopping. False trains on them too, as the paper. ``config``
    defaults to the paper's network on the residual of a cubic head, the damping
    learnt as the decay rate ``2π f ζ`` (:class:`~surrogates.train.TrainingConfig`,
    ``head_degree=3, damping_target="decay_rate"``); ``max_epochs``
    caps every stage.

    Writes ``out/surrogate.onnx`` and its sidecar (counts, test figures beside
    the baselines and the assembly scatter, label misfits), ``out/dataset.npz``
    and a prediction figure; the workspace's surrogate becomes the exported
    runtime, which is returned. The dataset's curves are computed on
    ``executor`` when given (a process pool or a dask Client: the dataset is the
    serial one, bit for bit).
    """
    # torch only here: `pm-joint update` and the reports never load it.
    from surrogates.export import export_surrogate
    from surrogates.train import stage_config, train_on_dataset

    out = Path(out)
    model, measured = workspace.model, workspace.backbones
    names = default_free(model)
    box = surrogate_box(model, names, labels, relative_spread)
    n_measured = 0 if labels is None else len(measured)
    grid = measured_grid(measured, n_amplitudes)
    scatter = assembly_scatter(measured, grid.amplitudes_m)
    dataset = generate_dataset(
        model, names, max(n_curves - n_measured, 1), representation="amplitude_grid",
        bounds=box, amplitude_range_m=grid.range_m, n_levels=n_amplitudes, seed=seed,
        progress=progress, executor=executor,
    )  # fmt: skip
    dataset = dataclasses.replace(
        dataset, provenance={**dataset.provenance, "grid": grid.to_dict()}
    )
    if labels is not None:
        dataset = add_measured(
            dataset, measured, labels, scatter=scatter, misfit_threshold=misfit_threshold,
            misfit_policy=misfit_policy,
        )  # fmt: skip
    dataset = dataset.with_splits(0.1, 0.1, seed=seed, hold_out_measured=hold_out_measured)
    dataset.save(out / "dataset.npz")
    config = stage_config(config, seed=seed, progress=progress, max_epochs=max_epochs)
    by_channel = dict(zip(GRID_CHANNELS[:3], scatter.T, strict=True))
    surrogate = train_on_dataset(dataset, config, scatter=by_channel)
    export_surrogate(surrogate, out)
    runtime = SurrogateRuntime.load(out)
    figure = plotting.plot_surrogate_check(runtime, dataset)
    plotting.save_png(figure, out / "surrogate_predictions.png", dpi=110)
    workspace.surrogate = runtime
    return runtime


def update_backbones(
    workspace: Workspace,
    out: str | os.PathLike,
    *,
    population: str = "matching",
    forward: str = "surrogate",
    names: Sequence[str] | None = None,
    amplitudes_m: np.ndarray | None = None,
    channels: Sequence[str] | None = None,
    family: str = "copula",
    sampler: str | None = None,
    draws: int | None = None,
    tune: int | None = None,
    chains: int = 2,
    seed: int = 0,
    trace: str | os.PathLike | None = None,
    resume: bool = False,
) -> xr.DataTree:
    """Stochastic updating on the workspace's backbones; saves the posterior (netCDF).

    ``population`` picks the population model:

    ``"matching"``
        The paper's population matching (:func:`~pm_joint.inference.build_model`):
        the likelihood density is the workspace's (fitted once) at
        ``amplitudes_m`` (default: for a surrogate, the levels both it and the
        measurements cover, :func:`~pm_joint.inference.amplitudes_within_surrogate`;
        else the default grid), saved with the posterior so a later report draws
        exactly what was sampled. The posterior is a population range; whether
        the forward model is one-to-one over the box is checked at the draws
        (:func:`~pm_joint.analysis.identifiability`, attribute ``identifiability``).
    ``"hierarchical"``
        The hierarchical model (:func:`~pm_joint.inference.hierarchical_model`)
        on the harmonic-balance graph, less its truncation error at per-curve
        estimates (5 harmonics), with relative damping noise, centred where each
        curve pins a parameter more tightly than the curves scatter and
        non-centred elsewhere (``centred="auto"``): the workspace's model is the
        template, ``names`` vary from assembly to assembly (default: those of
        :func:`~identification.fitting.least_squares.default_free` that the curves
        inform beyond their scatter, :func:`~pm_joint.inference.varying.varying_parameters`;
        the rest are held at the template, attribute ``varying_choice`` says which and
        why), every measured point of frequency and
        damping (``channels``) is scored. The saved posterior has its
        ``log_likelihood`` group, its LOO (attribute ``loo``) and a
        ``posterior_predictive`` group of new assemblies (population scatter
        and noise included) at 41 amplitudes over the measured range.

    ``sampler``, ``draws`` and ``tune`` default per population and forward model
    (:data:`~pm_joint.inference.SAMPLER_DEFAULTS`). With ``trace`` (a folder)
    the draws are written there as they are taken; with ``resume`` a run that
    stopped continues from that folder
    (:func:`~pm_joint.inference.continue_sampling`). Without it an existing
    folder is refused rather than overwritten. The posterior carries its
    convergence verdict (attribute ``convergence``, JSON); the workspace's
    posterior becomes the returned DataTree.
    """
    sampler, draws, tune = run_settings(population, forward, sampler, draws, tune)
    earlier_run = earlier_trace(trace, resume)
    measured = workspace.backbones
    density = surrogate = None
    if population == "hierarchical":
        channels = tuple(channels or ("frequency_hz", "damping_ratio"))
        choice = None
        if names is None:
            choice = varying_parameters(
                workspace.model, measured, default_free(workspace.model), channels=channels
            )
            names = choice.varying
        names = list(names)
        # Centred where the curves pin a parameter, non-centred elsewhere ("auto"): either form
        # alone left unconverged chains on some campaigns (the demo's for all-centred, the
        # trc-like PLL ones for all-non-centred), each where the other converged.
        pm_model = hierarchical_model(
            workspace.model, measured, names, amplitudes_m=amplitudes_m, channels=channels,
            centred="auto",
        )  # fmt: skip
    else:
        channels = tuple(channels or ("frequency_hz",))
        surrogate = workspace.surrogate if forward == "surrogate" else None
        if amplitudes_m is None and surrogate is not None:
            amplitudes_m = amplitudes_within_surrogate(measured, surrogate)
        density = workspace.density(amplitudes_m, channels=channels, family=family)
        # A gradient sampler compiles the surrogate's network with the model (native graph).
        pm_model = build_model(
            workspace.model, measured, forward=forward, surrogate=surrogate, names=names,
            density=density, native_graph=sampler in GRADIENT_SAMPLERS,
        )  # fmt: skip
    if earlier_run:  # and resume
        idata = continue_sampling(pm_model, trace, draws=draws, sampler=sampler)
    else:
        idata = sample(
            pm_model, sampler=sampler, draws=draws, tune=tune, chains=chains, random_seed=seed,
            trace=trace,
        )  # fmt: skip
    verdict = convergence_verdict(idata)
    idata.attrs["convergence"] = json.dumps(verdict.to_dict())
    if population == "hierarchical":
        _hierarchical_extras(idata, pm_model, workspace.model, names, channels, measured)
        if choice is not None:
            idata.attrs["varying_choice"] = json.dumps(
                {"text": choice.text(), "held": choice.held, "reach": choice.reach}
            )
    else:
        idata.attrs["identifiability"] = json.dumps(identifiability(pm_model, idata))
    reason = sampler_reason(population, forward, sampler)
    idata.attrs["sampler_reason"] = reason
    metadata = {
        "forward": forward,
        "sampler": sampler,
        "sampler_reason": reason,
        "surrogate": str(surrogate),
        "population_model": pm_model.population_model,
    }
    save_posterior(idata, out, metadata=metadata, density=density)
    workspace.posterior = idata
    return idata


def _hierarchical_extras(idata, pm_model, model, names, channels, measured) -> None:
    """LOO (attribute ``loo``) and new assemblies (group ``posterior_predictive``)."""
    attach_loo(idata, pm_model)
    low = min(b.amplitude_range_m[0] for b in measured)
    high = max(b.amplitude_range_m[1] for b in measured)
    new = population_predictive(idata, model, names, np.geomspace(low, high, 41),
                                channels=channels)  # fmt: skip
    # arviz's layout: one chain of draws (of new assemblies, not of the chains' order).
    idata["posterior_predictive"] = xr.DataTree(new.rename(sample="draw").expand_dims(chain=1))
    idata.attrs["varying_parameters"] = json.dumps(list(names))


def posterior_report(workspace: Workspace, out: str | os.PathLike) -> dict[str, Any]:
    """The report folder of the workspace's posterior (:func:`pm_joint.report_folder.report`).

    The likelihood density is the one stored with the posterior; a posterior
    without one gets a warning and a density refitted at the default levels.
    """
    return report(workspace.posterior, workspace.backbones, out=out)


def run_report(
    workspace: Workspace,
    out: str | os.PathLike,
    *,
    criticism: str | os.PathLike | None = None,
) -> Path:
    """HTML report of a run: measured backbones, the posterior (if any) and a criticism folder."""
    out = Path(out)
    measured = workspace.backbones
    plotting.save_png(plotting.plot_measured_backbones(measured), out / "backbones.png", dpi=110)
    sections = [
        html.Section(
            "Measured backbones",
            f"{len(measured)} backbones.",
            figures=[("backbones.png", "frequency and damping against amplitude")],
        )
    ]
    if workspace.has_posterior:
        content = posterior_report(workspace, out / "posterior")
        sections += html.posterior_sections(content, out / "posterior", out)
    if criticism is not None:
        # A folder `pm-joint criticize` wrote in another run: its record is the file.
        record = json.loads((Path(criticism) / "criticism.json").read_text(encoding="utf-8"))
        sections.append(html.criticism_section(record, criticism, out))
    return html.write_index(out, "pm-joint report", sections)
