"""The pipeline stages, in the order of the science.

records → backbones → SINDy model → analytical backbones → surrogate →
updating → criticism → report. Each stage is one function that reads what
earlier stages left on disk and writes its own artifacts; the ``pm-joint``
subcommands and the demo call these and nothing else.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # stages write PNG files; no display is needed or wanted

import numpy as np
from matplotlib.figure import Figure

from identification.analytical import harmonic, pll
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Campaign
from identification.model import JointModel
from identification.rig import RIG_PRESETS, Rig
from identification.sindy import PAPER_LIBRARY, Identification, identify, plot_validation

__all__ = [
    "analytical_backbones",
    "campaign_backbones",
    "criticize_campaign",
    "identify_campaign",
    "load_backbones",
    "record_labels",
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
    levels: int = 10,
    workers: int | None = 1,
    progress: bool = True,
) -> Campaign:
    """Write a virtual campaign of the rig preset ``preset`` in the TRC layout.

    Records are simulated and written by ``workers`` processes (None: one per
    CPU); the files do not depend on it. With more than one, call this from a
    script's ``if __name__ == "__main__":`` block: worker processes start by
    importing the main script.
    """
    if preset not in RIG_PRESETS:
        raise ValueError(f"unknown rig preset {preset!r}; available: {', '.join(RIG_PRESETS)}")
    rig = Rig.preset(preset, levels=levels)
    workers = min(workers or os.cpu_count() or 1, assemblies * runs)
    options = {"assemblies": assemblies, "runs": runs, "seed": seed, "progress": progress}
    if workers < 2:
        return rig.write_campaign(out, **options)
    # forkserver: workers start from a clean process, not a fork of this
    # (possibly multi-threaded) one.
    context = multiprocessing.get_context("forkserver")
    with ProcessPoolExecutor(workers, mp_context=context) as executor:
        return rig.write_campaign(out, executor=executor, **options)


def campaign_backbones(
    folder: str | os.PathLike,
    out: str | os.PathLike | None = None,
    *,
    n_periods: int = 70,
    progress: bool = True,
) -> BackboneSet:
    """Backbones of every record in a campaign folder; optionally saved as CSV (+ PNG)."""
    backbones = extract_backbones(Campaign(folder), n_periods=n_periods, progress=progress)
    if out is not None:
        out = Path(out)
        backbones.to_csv(out)
        fig = Figure(figsize=(10, 4))
        axes = fig.subplots(1, 2)
        backbones.plot(axes)
        fig.tight_layout()
        fig.savefig(out.with_suffix(".png"), dpi=110)
    return backbones


def load_backbones(source: str | os.PathLike) -> BackboneSet:
    """Backbones from a CSV written by :func:`campaign_backbones` or from a campaign folder."""
    source = Path(source)
    if source.is_dir():
        return campaign_backbones(source, progress=False)
    return BackboneSet.from_csv(source)


def identify_campaign(
    folder: str | os.PathLike,
    effects: Sequence[str] = PAPER_LIBRARY,
    *,
    records: int = 3,
    out: str | os.PathLike | None = None,
    **options,
) -> Identification:
    """SINDy identification from the first ``records`` records of a campaign.

    With ``out`` (a JSON path) the model is written there, with the velocity
    and acceleration validation figures (the paper's Figs. 9–10) beside it.
    """
    campaign = Campaign(folder)
    chosen = [campaign[i] for i in range(min(records, len(campaign)))]
    result = identify(chosen, list(effects), **options)
    if out is not None:
        out = Path(out)
        result.model.to_json(out)
        from identification.sindy import record_kinematics, validate

        validation = validate(result.model, record_kinematics(chosen[0]))
        for channel in ("velocity", "acceleration"):
            fig = Figure(figsize=(10, 7))
            plot_validation(validation, fig.subplots(3, 1), channel=channel)
            fig.tight_layout()
            fig.savefig(out.with_name(f"{out.stem}_validation_{channel}.png"), dpi=100)
    return result


def analytical_backbones(
    model: JointModel,
    measured: BackboneSet,
    out: str | os.PathLike | None = None,
    *,
    n_levels: int = 41,
) -> dict[str, Backbone]:
    """The model's backbone by multi-harmonic balance and by the PLL simulator.

    Both span the measured amplitudes; with ``out`` (a PNG path) they are drawn
    over the measured curves (the paper's Fig. 12).
    """
    low = min(b.amplitude_range_m[0] for b in measured)
    high = max(b.amplitude_range_m[1] for b in measured)
    amplitudes = np.geomspace(low, high, n_levels)
    hb = harmonic.backbone(model, amplitudes, method="multi")
    ok = hb.converged
    curves = {
        "harmonic balance": Backbone(
            hb.amplitude_m[ok], hb.frequency_hz[ok], hb.damping_ratio[ok],
            label="harmonic balance", source=model.name,
        ),
    }  # fmt: skip
    levels = np.abs(hb.base_acceleration[ok])
    result = pll.simulate_pll(model, np.geomspace(levels.min(), levels.max(), n_levels))
    locked = result.locked
    if locked.sum() >= 2:
        curves["PLL"] = Backbone(
            result.amplitude_m[locked], result.frequency_hz[locked],
            result.damping_ratio[locked], excitation_level=result.level[locked],
            label="PLL", source=model.name,
        )  # fmt: skip
    if out is not None:
        fig = Figure(figsize=(10, 4))
        ax_f, ax_d = fig.subplots(1, 2)
        for b in measured:
            ax_f.plot(b.amplitude_mm, b.frequency_hz, color="0.75", lw=0.8)
            ax_d.plot(b.amplitude_mm, 100 * b.damping_ratio, color="0.75", lw=0.8)
        for (label, b), style in zip(curves.items(), ("-", "o"), strict=False):
            ax_f.plot(b.amplitude_mm, b.frequency_hz, style, label=label, ms=3)
            ax_d.plot(b.amplitude_mm, 100 * b.damping_ratio, style, label=label, ms=3)
        ax_f.set(xlabel="amplitude (mm)", ylabel="frequency (Hz)", title="measured (grey) vs model")
        ax_d.set(xlabel="amplitude (mm)", ylabel="damping ratio (%)")
        ax_f.legend()
        fig.tight_layout()
        fig.savefig(out, dpi=110)
    return curves


def criticize_campaign(
    folder: str | os.PathLike,
    model: JointModel | str | os.PathLike,
    out: str | os.PathLike,
    *,
    rounds: int = 0,
    measured: BackboneSet | None = None,
    posterior=None,
):
    """Criticize a model against a campaign; optionally add the best effect ``rounds`` times.

    ``measured`` are the campaign's backbones when already extracted (with the
    harmonics they carry); else they are extracted from the records once.
    ``posterior`` (a DataTree) gives the predictive bands and the medians the
    model is compared at. Writes ``criticism.json`` and figures to ``out`` (for
    the last round, whose history holds every step) and returns the last
    :class:`~identification.criticism.criticism.Criticism`.
    """
    from pm_joint.analysis.posterior import criticize

    if not isinstance(model, JointModel):
        model = JointModel.from_json(model)
    if measured is None:
        measured = extract_backbones(Campaign(folder))
    crit = criticize(model, measured, posterior=posterior)
    for _ in range(rounds):
        proposals = crit.missing()
        if not proposals:
            break
        crit = crit.add(proposals[0].effect)
    crit.write(out)
    return crit


def update_backbones(
    measured: BackboneSet,
    model: JointModel | None,
    out: str | os.PathLike,
    *,
    forward: str = "surrogate",
    surrogate: str | os.PathLike | None = None,
    names: Sequence[str] | None = None,
    sampler: str = "metropolis",
    draws: int = 30_000,
    tune: int = 2_000,
    chains: int = 2,
    seed: int = 0,
    report_dir: str | os.PathLike | None = None,
    trace: str | os.PathLike | None = None,
    resume: bool = False,
):
    """Stochastic updating on measured backbones; saves the posterior (netCDF).

    With ``trace`` (a zarr folder) the draws are written there as they are
    taken; with ``resume`` a run that stopped continues from that folder
    (:func:`pm_joint.updating.continue_sampling`). Without it an existing
    folder is refused rather than overwritten.
    With ``report_dir`` the arviz report (summary, pairs, correlation, trace,
    predictive backbones, PDFs at low/mid/high amplitude) is written there.
    Returns the DataTree.
    """
    from pm_joint.report import report
    from pm_joint.updating import build_model, continue_sampling, sample, save_posterior

    earlier_run = trace is not None and Path(trace).exists()
    if earlier_run and not resume:
        raise ValueError(
            f"{trace} holds the draws of an earlier run: resume it, or remove it to start again"
        )
    levels = None
    if forward == "surrogate":
        levels = _levels_within_surrogate(measured, surrogate)
    pm_model = build_model(
        model, measured, forward=forward, surrogate=surrogate, names=names, levels=levels
    )
    if earlier_run:  # and resume
        idata = continue_sampling(pm_model, trace, draws=draws, sampler=sampler)
    else:
        idata = sample(
            pm_model, sampler=sampler, draws=draws, tune=tune, chains=chains, random_seed=seed,
            trace=trace,
        )  # fmt: skip
    save_posterior(
        idata, out, metadata={"forward": forward, "sampler": sampler, "surrogate": str(surrogate)}
    )
    if report_dir is not None:
        from pm_joint.likelihood import BackboneDensity

        density = BackboneDensity.fit(measured, levels)  # as build_model fitted it
        report(idata, measured, density=density, out=report_dir, sampler=sampler)
    return idata


def _levels_within_surrogate(measured: BackboneSet, surrogate) -> np.ndarray:
    """Likelihood levels over the amplitudes both the measurements and the surrogate cover.

    The surrogate's range is that of its prediction at the centre of its
    training box; a model that cannot be held at the largest measured
    amplitudes (its excitation would have to fall) is compared where it can.
    """
    from pm_joint.likelihood import amplitude_levels
    from surrogates.runtime import SurrogateRuntime

    runtime = surrogate if isinstance(surrogate, SurrogateRuntime) else None
    runtime = runtime or SurrogateRuntime.load(surrogate)
    centre = np.mean(np.asarray(runtime.bounds, dtype=float), axis=1)
    amplitude = runtime.amplitude_m(centre)
    low, high = measured.common_range()
    low, high = max(low, float(np.min(amplitude))), min(high, float(np.max(amplitude)))
    levels = amplitude_levels(measured)
    inside = levels[(levels >= low) & (levels <= high)]
    if inside.size < 3:
        raise ValueError(
            f"the surrogate covers {1e3 * np.min(amplitude):.3g}–{1e3 * np.max(amplitude):.3g} mm "
            f"at the centre of its box: fewer than 3 likelihood levels of the measured range"
        )
    return np.linspace(inside[0], inside[-1], levels.size)


def posterior_sections(report_folder: str | os.PathLike, page_folder: str | os.PathLike):
    """Report sections of an arviz report folder (written by :func:`pm_joint.report.report`)."""
    import json

    from pm_joint.html import Section

    folder = Path(report_folder)
    content = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    rel = Path(os.path.relpath(folder, page_folder))
    files = [f for f in content["files"] if f.endswith(".png")]
    summary_rows = [
        {k: v for k, v in row.items() if k in ("variable", "index", "mean", "sd", "eti94_lb",
                                                "eti94_ub", "ess_bulk", "r_hat")}
        for row in content["summary"]
    ]  # fmt: skip
    pdf_rows = [
        {
            "level": level,
            "amplitude_mm": entry.get("amplitude_mm"),
            "measured_family": entry["measured_fit"]["family"],
            "sampled_family": entry["sampled_fit"]["family"],
            "ks_statistic": entry["distances"]["ks_statistic"],
            "ks_pvalue": entry["distances"]["ks_pvalue"],
            "wasserstein_hz": entry["distances"]["wasserstein"],
        }
        for level, entry in content["level_pdfs"].items()
    ]
    sampler = content.get("sampler", {})
    return [
        Section(
            "Stochastic updating",
            f"Sampler: {sampler.get('sampler')}, {sampler.get('draws')} draws × "
            f"{sampler.get('chains')} chains; mean acceptance {sampler.get('acceptance_rate')}.",
            tables=[("posterior summary", summary_rows)],
            figures=[(str(rel / f), f.removesuffix(".png").replace("_", " ")) for f in files],
            files=[(str(rel / "report.json"), "report.json")],
        ),
        Section(
            "PDFs at low, mid and high amplitude",
            "Measured against sampled frequencies, each with its best-fitting distribution "
            "family (AIC) and the distances between them (the paper's Fig. 22).",
            tables=[("per amplitude level", pdf_rows)],
        ),
    ]


def criticism_section(folder: str | os.PathLike, page_folder: str | os.PathLike):
    """Report section of a criticism folder (written by :meth:`Criticism.write`)."""
    import json

    from pm_joint.html import Section

    folder = Path(folder)
    content = json.loads((folder / "criticism.json").read_text(encoding="utf-8"))
    rel = Path(os.path.relpath(folder, page_folder))
    verdict = (
        "Something significant is missing." if content["significant"]
        else "Nothing significant missing."
    )  # fmt: skip
    fails = "; ".join(r.get("text", str(r)) for r in content.get("fails_at", [])) or "nowhere"
    return Section(
        "Model criticism",
        f"{verdict} Where the model fails: {fails}.",
        tables=[
            ("ranked missing effects", content["ranking"]),
            (
                "error history",
                [
                    {k: v for k, v in step.items() if not isinstance(v, (list, dict))}
                    for step in content.get("history", [])
                ],
            ),
        ],
        figures=[
            (str(rel / "comparison.png"), "measured vs predicted, residual bands"),
            (str(rel / "signatures.png"), "residual beside the top candidates' signatures"),
            (str(rel / "history.png"), "the error along the loop"),
        ],
        files=[(str(rel / "criticism.json"), "criticism.json")],
    )


def run_report(
    measured: BackboneSet,
    out: str | os.PathLike,
    *,
    posterior: str | os.PathLike | None = None,
    criticism: str | os.PathLike | None = None,
) -> Path:
    """HTML report of a run: measured backbones, the posterior and the criticism."""
    from pm_joint.html import Section, write_index
    from pm_joint.report import report
    from pm_joint.updating import load_posterior

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=(10, 4))
    measured.plot(fig.subplots(1, 2))
    fig.tight_layout()
    fig.savefig(out / "backbones.png", dpi=110)
    sections = [
        Section(
            "Measured backbones",
            f"{len(measured)} backbones.",
            figures=[("backbones.png", "frequency and damping against amplitude")],
        )
    ]
    if posterior is not None:
        report(load_posterior(posterior), measured, out=out / "posterior")
        sections += posterior_sections(out / "posterior", out)
    if criticism is not None:
        sections.append(criticism_section(criticism, out))
    return write_index(out, "pm-joint report", sections)


def record_labels(records: Sequence, model: JointModel, names: Sequence[str]) -> np.ndarray:
    """Parameters of each record alone: least squares on the model's own terms.

    The paper labels its measured backbones by identifying each record; with
    the model's support fixed (no thresholding) that is a well-posed fit of
    the same parameters, record by record. Shape parameters keep the model's
    values.
    """
    shapes = {t.effect: dict(t.shape) for t in model.terms if t.shape}
    rows = []
    for record in records:
        fitted = identify(record, model.effects, threshold=None, shapes=shapes).model
        values = {**model.parameters, **fitted.parameters}
        rows.append([values[n] for n in names])
    return np.array(rows)


def train_surrogate_stage(
    measured: BackboneSet,
    model: JointModel,
    out: str | os.PathLike,
    *,
    labels: np.ndarray | None = None,
    n_curves: int = 500,
    spread: float = 0.2,
    max_epochs: int | None = None,
    seed: int = 0,
    progress: bool = True,
):
    """Dataset (analytical + measured curves), training and ONNX export, as the paper.

    ``labels`` are the measured curves' parameters in the order of
    :func:`identification.fitting.least_squares.default_free` (e.g. :func:`record_labels`);
    without them only analytical curves are used. The training box covers
    ± ``spread`` around the model and every label. The analytical curves
    (harmonic balance, inverted onto fixed excitation levels) make up the rest
    of ``n_curves``. Writes ``out/surrogate.onnx``, its sidecar,
    ``out/dataset.npz`` and a prediction figure; returns the
    :class:`~surrogates.runtime.SurrogateRuntime`.
    """
    from identification.fitting.least_squares import default_free
    from surrogates.dataset import add_measured, default_bounds, generate_dataset
    from surrogates.export import export_surrogate
    from surrogates.runtime import SurrogateRuntime
    from surrogates.train import TrainingConfig, train_surrogate

    out = Path(out)
    names = default_free(model)
    box = default_bounds(model, names, spread)
    n_measured = 0
    if labels is not None:
        labels = np.asarray(labels, dtype=float)
        margin = 0.05 * (box[:, 1] - box[:, 0])
        box[:, 0] = np.minimum(box[:, 0], labels.min(axis=0) - margin)
        box[:, 1] = np.maximum(box[:, 1], labels.max(axis=0) + margin)
        n_measured = len(measured)
    low, high = _reachable_range(
        model,
        min(b.amplitude_range_m[0] for b in measured),
        max(b.amplitude_range_m[1] for b in measured),
    )
    dataset = generate_dataset(
        model, names, max(n_curves - n_measured, 1), bounds=box,
        amplitude_range_m=(low, high), seed=seed, progress=progress,
    )  # fmt: skip
    if labels is not None:
        dataset = add_measured(dataset, measured, labels)
    dataset.save(out / "dataset.npz")
    config = TrainingConfig(seed=seed, progress=progress)
    if max_epochs is not None:
        config = TrainingConfig(
            seed=seed, progress=progress, max_epochs=max_epochs, patience=max_epochs,
            finetune_epochs=max_epochs // 2,
        )  # fmt: skip
    surrogate = train_surrogate(dataset.X, dataset.Y, dataset.spec, config)
    export_surrogate(surrogate, out)
    runtime = SurrogateRuntime.load(out)
    _plot_surrogate_check(runtime, dataset, out / "surrogate_predictions.png")
    return runtime


def _reachable_range(model: JointModel, low: float, high: float) -> tuple[float, float]:
    """The part of ``[low, high]`` a stepped excitation can hold the model at.

    Excitation levels map one-to-one onto amplitudes only while the base
    acceleration the backbone needs increases with amplitude; past its first
    maximum a PLL test jumps, so the range ends there.
    """
    grid = np.geomspace(low, high, 200)
    hb = harmonic.backbone(model, grid, method="multi")
    level = np.where(hb.converged, hb.base_acceleration, np.nan)
    falling = np.flatnonzero(~(np.diff(level) > 0))
    end = grid[falling[0]] if falling.size else high
    if end <= low * 1.5:
        raise ValueError(
            f"model {model.name or model.equation()!r}: its backbone needs a base acceleration "
            f"that does not increase over the measured {1e3 * low:.3g}–{1e3 * high:.3g} mm"
        )
    return low, float(end)


def _plot_surrogate_check(runtime, dataset, path: Path, n: int = 6) -> None:
    """A few curves of the dataset against the surrogate's prediction (the paper's Fig. 17)."""
    rows = np.linspace(0, len(dataset) - 1, n).astype(int)
    predicted = runtime.predict(dataset.X[rows])
    a, f = dataset.spec.channel_index("amplitude_m"), dataset.spec.channel_index("frequency_hz")
    fig = Figure(figsize=(6, 4.5))
    ax = fig.subplots()
    for k, row in enumerate(rows):
        line = ax.plot(1e3 * dataset.Y[row, :, a], dataset.Y[row, :, f], "o", ms=3)[0]
        ax.plot(1e3 * predicted[k, :, a], predicted[k, :, f], "-", color=line.get_color())
    ax.set(xlabel="amplitude (mm)", ylabel="frequency (Hz)",
           title="dataset curves (dots) vs surrogate (lines)")  # fmt: skip
    fig.tight_layout()
    fig.savefig(path, dpi=110)
