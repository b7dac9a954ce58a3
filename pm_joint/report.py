"""Posterior reports: numbers from arviz and scipy, figures from them, a report folder.

Computing and plotting are kept apart (the arviz way): :func:`summarize`,
:func:`correlation_matrix`, :func:`level_pdfs` and :func:`sampler_info` return
numbers; the ``plot_*`` functions take those numbers (or the DataTree) and
return matplotlib figures or write PNGs; :func:`report` does all of it and
writes a folder with the figures of the paper's Figs. 19–22 and ``report.json``.

The posterior-predictive backbones are the forward model's predictions at the
likelihood's amplitude levels, stored by
:func:`~pm_joint.likelihood.BackboneAmplitude` as ``{name}_predicted``
(channel-major, one value per level and channel).
"""

from __future__ import annotations

import io
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import arviz as az
import numpy as np
import pandas as pd
import xarray as xr
from matplotlib.figure import Figure

from identification.artifacts import atomic_write_bytes, atomic_write_text
from identification.measurements.backbone import BackboneSet
from pm_joint.fitting import CANDIDATES, distances, fit_best
from pm_joint.likelihood import BackboneDensity, level_marks

__all__ = [
    "correlation_matrix",
    "default_var_names",
    "level_pdfs",
    "plot_correlation",
    "plot_level_pdfs",
    "plot_pairs",
    "plot_predictive_backbones",
    "plot_trace_rank",
    "predicted_values",
    "report",
    "sampler_info",
    "summarize",
]

SAMPLE_DIMS = ("chain", "draw")
CI_PROB = 0.94
#: Parameters per pair-scatter matrix (the paper splits 12 into two 6 × 6 matrices).
PAIR_GROUP = 6
#: The paper's colours for the low, mid and high amplitude levels (Fig. 21a).
LEVEL_COLOURS = {"low": "tab:red", "mid": "tab:blue", "high": "tab:green"}
DPI = 120
#: Draws per chain the rank plot is thinned to.
RANK_DRAWS = 1000


# ---------------------------------------------------------------------------
# numbers


def _group(idata: xr.DataTree, name: str) -> xr.Dataset:
    if name not in idata.children:
        raise ValueError(f"the DataTree has no {name!r} group (groups: {list(idata.children)})")
    return idata[name].to_dataset()


def default_var_names(idata: xr.DataTree) -> list[str]:
    """Posterior variables that are one scalar per draw (the free parameters).

    Vector deterministics such as ``backbone_predicted`` are left out.
    """
    posterior = _group(idata, "posterior")
    return [str(n) for n, da in posterior.data_vars.items() if set(da.dims) == set(SAMPLE_DIMS)]


def _var_names(idata: xr.DataTree, var_names: Sequence[str] | None) -> list[str]:
    if var_names is None:
        names = default_var_names(idata)
        if not names:
            raise ValueError("the posterior has no scalar variables; pass var_names")
        return names
    names = [var_names] if isinstance(var_names, str) else list(var_names)
    posterior = _group(idata, "posterior")
    unknown = [n for n in names if n not in posterior.data_vars]
    if unknown:
        raise ValueError(f"unknown posterior variable(s) {unknown}; have {list(posterior)}")
    if not names:
        raise ValueError("var_names is empty")
    return names


def summarize(idata: xr.DataTree, var_names: Sequence[str] | None = None) -> pd.DataFrame:
    """arviz summary: mean, sd, 94 % interval, ess_bulk, ess_tail, r_hat, MCSE (unrounded)."""
    names = _var_names(idata, var_names)
    return az.summary(idata, var_names=names, ci_prob=CI_PROB, round_to="none")


def _draws_table(idata: xr.DataTree, var_names: Sequence[str]) -> pd.DataFrame:
    """One row per draw (all chains pooled), one column per scalar component.

    Components of vector variables are labelled like arviz does, ``name[i, j]``.
    """
    posterior = _group(idata, "posterior")
    columns = {}
    for name in var_names:
        da = posterior[name].stack(__sample__=SAMPLE_DIMS)
        others = [d for d in da.dims if d != "__sample__"]
        if not others:
            columns[name] = da.values
            continue
        flat = da.stack(__component__=others).transpose("__sample__", "__component__")
        for j, label in enumerate(flat["__component__"].values):
            columns[f"{name}[{', '.join(map(str, label))}]"] = flat.values[:, j]
    return pd.DataFrame(columns)


def correlation_matrix(idata: xr.DataTree, var_names: Sequence[str] | None = None) -> pd.DataFrame:
    """Pearson correlation of the posterior draws, chains pooled (the paper's Fig. 20)."""
    return _draws_table(idata, _var_names(idata, var_names)).corr()


def predicted_values(idata: xr.DataTree, name: str = "backbone") -> np.ndarray:
    """Posterior-predictive values at the levels, (n_chains·n_draws, n_levels·n_channels).

    Taken from the deterministic ``{name}_predicted`` of the posterior, else
    from the ``posterior_predictive`` group's ``name``.
    """
    candidates = (("posterior", f"{name}_predicted"), ("posterior_predictive", name))
    for group, variable in candidates:
        if group in idata.children and variable in idata[group].data_vars:
            da = idata[group][variable]
            others = [d for d in da.dims if d not in SAMPLE_DIMS]
            if len(others) != 1:
                raise ValueError(
                    f"{group}/{variable} must have one dimension besides chain and draw, "
                    f"has {others}"
                )
            return da.transpose(*SAMPLE_DIMS, *others).values.reshape(-1, da.sizes[others[0]])
    raise ValueError(
        f"no posterior-predictive backbone in the DataTree: looked for posterior/{name}_predicted "
        f"and posterior_predictive/{name}"
    )


def _checked_predictions(
    idata: xr.DataTree, density: BackboneDensity, name: str = "backbone"
) -> np.ndarray:
    """Predicted values, after checking that they belong to ``density``."""
    values = predicted_values(idata, name)
    if values.shape[1] != density.n_dims:
        raise ValueError(
            f"{name}_predicted has {values.shape[1]} values per draw, but the density has "
            f"{len(density.amplitudes_m)} levels × {len(density.channels)} channel(s) = "
            f"{density.n_dims}: pass the density the model was built with"
        )
    if "observed_data" in idata.children and name in idata["observed_data"].data_vars:
        observed = idata["observed_data"][name].values
        same = observed.shape == density.observations.shape and np.allclose(
            observed, density.observations, rtol=1e-9, atol=0
        )
        if not same:
            raise ValueError(
                f"the density's measured values differ from observed_data/{name} of the trace: "
                "it was fitted at other amplitude levels or to other curves; pass the density "
                "the model was built with"
            )
    return values


def _thin(values: np.ndarray, n: int) -> np.ndarray:
    """At most ``n`` evenly spaced rows (every chain keeps its share)."""
    if len(values) <= n:
        return values
    return values[np.linspace(0, len(values) - 1, n).astype(int)]


def level_pdfs(
    idata: xr.DataTree,
    density: BackboneDensity,
    levels: Sequence[str] = ("low", "mid", "high"),
    *,
    name: str = "backbone",
    candidates: tuple[str, ...] = CANDIDATES,
    max_fit_samples: int = 4000,
) -> dict[str, dict]:
    """Measured against sampled frequencies at the marked amplitude levels (Fig. 22).

    Parameters
    ----------
    idata
        Trace with the posterior-predictive backbone (see :func:`predicted_values`).
    density
        The likelihood's :class:`~pm_joint.likelihood.BackboneDensity`.
    levels
        Names from :func:`~pm_joint.likelihood.level_marks`.
    candidates
        scipy.stats families for :func:`~pm_joint.fitting.fit_best`.
    max_fit_samples
        The sampled frequencies are thinned evenly to this many for the
        maximum-likelihood fits (MCMC draws are correlated, so little is lost);
        the distances use every draw.

    Returns
    -------
    dict
        Per level: ``index``, ``amplitude_mm``, ``measured_hz``, ``sampled_hz``
        (finite draws only; ``n_dropped`` counts the others), ``measured_fit``
        and ``sampled_fit`` (best :class:`~pm_joint.fitting.DistributionFit` by
        AIC), ``distances`` (``ks_statistic``, ``ks_pvalue``, ``wasserstein``,
        in Hz) and ``mean_shift_hz`` (sampled minus measured mean).
    """
    if "frequency_hz" not in density.channels:
        raise ValueError(f"the density has no frequency channel (channels {density.channels})")
    marks = level_marks(density.amplitudes_m)
    unknown = [level for level in levels if level not in marks]
    if unknown:
        raise ValueError(f"unknown amplitude level(s) {unknown}; choose from {list(marks)}")
    sampled = density.split(_checked_predictions(idata, density, name))["frequency_hz"]
    measured = density.split(density.observations)["frequency_hz"]
    result = {}
    for level in levels:
        i = marks[level]
        column = sampled[:, i]
        finite = column[np.isfinite(column)]
        if finite.size and np.ptp(finite) == 0:
            raise ValueError(
                f"{level} amplitude level: every posterior draw predicts the same frequency "
                f"({finite[0]:.6g} Hz): the chains did not move; tune longer or narrow the priors"
            )
        try:
            measured_fit = fit_best(measured[:, i], candidates)[0]
            sampled_fit = fit_best(_thin(finite, max_fit_samples), candidates)[0]
            gap = distances(measured[:, i], finite)
        except ValueError as exc:
            raise ValueError(f"{level} amplitude level: {exc}") from None
        result[level] = {
            "index": i,
            "amplitude_mm": 1e3 * float(density.amplitudes_m[i]),
            "measured_hz": measured[:, i],
            "sampled_hz": finite,
            "n_dropped": int(column.size - finite.size),
            "measured_fit": measured_fit,
            "sampled_fit": sampled_fit,
            "distances": gap,
            "mean_shift_hz": float(finite.mean() - measured[:, i].mean()),
        }
    return result


# (stat present in sample_stats, sampler) — PyMC records no sampler name.
_SAMPLER_SIGNATURES = (
    ("lambda", "demetropolisz"),
    ("diverging", "nuts"),
    ("accepted", "metropolis"),
)


def sampler_info(idata: xr.DataTree, sampler: str | None = None) -> dict:
    """Sampler name, draws, chains, tuning steps, wall time (s) and mean acceptance rate.

    The name is ``sampler`` if given, else a ``sampler`` attribute of the
    DataTree (or of its ``pm_joint_metadata``), else guessed from the
    sampler statistics PyMC records; None where nothing tells.
    """
    posterior = _group(idata, "posterior")
    stats = idata["sample_stats"].to_dataset() if "sample_stats" in idata.children else xr.Dataset()
    attrs = {**posterior.attrs, **stats.attrs}
    metadata = json.loads(idata.attrs.get("pm_joint_metadata", "{}"))
    sampler = sampler or idata.attrs.get("sampler") or metadata.get("sampler")
    if sampler is None:
        sampler = next((s for stat, s in _SAMPLER_SIGNATURES if stat in stats), None)
    acceptance = None
    # "accepted" is the 0/1 outcome (Metropolis family), "acceptance_rate" NUTS's
    # mean acceptance probability; Metropolis's "accept" is a likelihood ratio, not a rate.
    for stat in ("accepted", "acceptance_rate"):
        if stat in stats:
            acceptance = float(np.nanmean(stats[stat].values.astype(float)))
            break
    wall = attrs.get("sampling_time")
    tuning = attrs.get("tuning_steps")
    return {
        "sampler": sampler,
        "draws": int(posterior.sizes["draw"]),
        "chains": int(posterior.sizes["chain"]),
        "tuning_steps": None if tuning is None else int(tuning),
        "wall_time_s": None if wall is None else float(wall),
        "acceptance_rate": acceptance,
    }


# ---------------------------------------------------------------------------
# figures


def _new_axes(n: int = 1, figsize: tuple[float, float] = (7, 4.5)):
    # A bare Figure (no pyplot): no global state, nothing to close, any backend.
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(1, n, squeeze=False)[0]
    return fig, axes


def _save_png(fig, path: Path) -> Path:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=DPI)
    return atomic_write_bytes(path, buffer.getvalue())


def _save_collection(collection, path: Path) -> Path:
    """Save an arviz PlotCollection's figure and free it (arviz draws through pyplot)."""
    import matplotlib.pyplot as plt

    fig = collection.get_viz("figure")
    try:
        return _save_png(fig, path)
    finally:
        plt.close(fig)


def _pair_groups(names: list[str]) -> list[list[str]]:
    """Groups of :data:`PAIR_GROUP`; a lone last name is paired with the one before."""
    groups = [names[i : i + PAIR_GROUP] for i in range(0, len(names), PAIR_GROUP)]
    if len(groups) > 1 and len(groups[-1]) == 1:
        groups[-1] = [names[-2], names[-1]]
    return groups


def plot_pairs(
    idata: xr.DataTree, var_names: Sequence[str] | None, out_dir: str | os.PathLike
) -> list[Path]:
    """Pair scatter matrices with marginal histograms, six parameters each (Fig. 19).

    Writes ``pairs_1.png``, ``pairs_2.png``, … into ``out_dir``; returns their paths.
    """
    out_dir = Path(out_dir)
    paths = []
    for k, group in enumerate(_pair_groups(_var_names(idata, var_names)), start=1):
        collection = az.plot_pair(
            idata, var_names=group, marginal_kind="hist", backend="matplotlib"
        )
        paths.append(_save_collection(collection, out_dir / f"pairs_{k}.png"))
    return paths


def plot_trace_rank(
    idata: xr.DataTree, var_names: Sequence[str] | None, out_dir: str | os.PathLike
) -> list[Path]:
    """Trace and rank plots (mixing of the chains); writes ``trace.png`` and ``rank.png``.

    The rank plot uses at most :data:`RANK_DRAWS` evenly thinned draws per
    chain: its multi-chain uniformity test costs minutes at the paper's 30 000.
    A single chain has no rank plot (ranks compare chains), only a trace.
    """
    out_dir = Path(out_dir)
    names = _var_names(idata, var_names)
    trace = az.plot_trace(idata, var_names=names, backend="matplotlib")
    if _group(idata, "posterior").sizes["chain"] < 2:
        return [_save_collection(trace, out_dir / "trace.png")]
    factor = -(-_group(idata, "posterior").sizes["draw"] // RANK_DRAWS)
    rank = az.plot_rank(
        idata, var_names=names, thin=factor > 1, stats={"thin": {"factor": factor}},
        backend="matplotlib",
    )  # fmt: skip
    return [
        _save_collection(trace, out_dir / "trace.png"),
        _save_collection(rank, out_dir / "rank.png"),
    ]


def plot_correlation(corr: pd.DataFrame, ax=None) -> Figure:
    """Heatmap of a correlation matrix with the values written in (Fig. 20)."""
    if corr.shape[0] != corr.shape[1] or list(corr.index) != list(corr.columns):
        raise ValueError(f"corr must be a square matrix with equal labels, got shape {corr.shape}")
    n = corr.shape[0]
    if ax is None:
        side = min(3 + 0.6 * n, 14)
        _, (ax,) = _new_axes(figsize=(side + 1, side))
    image = ax.imshow(corr.values, cmap="RdBu_r", vmin=-1, vmax=1)
    ax.figure.colorbar(image, ax=ax, label="correlation")
    labels = [str(c) for c in corr.columns]
    ax.set_xticks(range(n), labels, rotation=45, ha="right")
    ax.set_yticks(range(n), labels)
    fontsize = max(5, 10 - 0.3 * n)
    for (i, j), value in np.ndenumerate(corr.values):
        colour = "white" if abs(value) > 0.6 else "black"
        ax.text(j, i, f"{value:.2f}", ha="center", va="center", color=colour, fontsize=fontsize)
    ax.set_title("posterior correlation")
    return ax.figure


def plot_predictive_backbones(
    idata: xr.DataTree,
    density: BackboneDensity,
    measured: BackboneSet,
    ax=None,
    *,
    name: str = "backbone",
    n_lines: int = 100,
) -> Figure:
    """Sampled backbones at the amplitude levels against the measured curves (Fig. 21).

    Up to ``n_lines`` posterior draws as thin lines, the 94 % band and median of
    all draws, the measured curves, and the low/mid/high levels marked.
    """
    if "frequency_hz" not in density.channels:
        raise ValueError(f"the density has no frequency channel (channels {density.channels})")
    sampled = density.split(_checked_predictions(idata, density, name))["frequency_hz"]
    amplitude_mm = 1e3 * density.amplitudes_m
    if ax is None:
        _, (ax,) = _new_axes()
    ax.plot(amplitude_mm, _thin(sampled, n_lines).T, color="tab:orange", lw=0.5, alpha=0.15)
    tail = 100 * (1 - CI_PROB) / 2
    low, median, high = np.nanpercentile(sampled, [tail, 50, 100 - tail], axis=0)
    ax.fill_between(
        amplitude_mm, low, high, color="tab:orange", alpha=0.3,
        label=f"posterior predictive {100 * CI_PROB:.0f} %",
    )  # fmt: skip
    ax.plot(amplitude_mm, median, color="tab:orange", lw=2, label="posterior predictive median")
    for k, curve in enumerate(measured):
        ax.plot(
            curve.amplitude_mm, curve.frequency_hz, color="black", lw=0.8, marker=".", ms=3,
            label="measured" if k == 0 else None,
        )  # fmt: skip
    for level, i in level_marks(density.amplitudes_m).items():
        ax.axvline(
            amplitude_mm[i], color=LEVEL_COLOURS[level], ls="--", lw=1,
            label=f"{level} ({amplitude_mm[i]:.3g} mm)",
        )  # fmt: skip
    ax.set(xlabel="amplitude (mm)", ylabel="frequency (Hz)", title="measured and sampled backbones")
    ax.legend(fontsize="small")
    return ax.figure


def plot_level_pdfs(result: Mapping[str, Mapping], axes=None) -> Figure:
    """Measured and sampled frequency histograms with their best-fit PDFs (Fig. 22).

    ``result`` is the output of :func:`level_pdfs`; one panel per level, the
    fitted families and the KS / Wasserstein distances in each legend.
    """
    if not result:
        raise ValueError("no amplitude levels to plot")
    if axes is None:
        _, axes = _new_axes(len(result), figsize=(4.5 * len(result), 4))
    axes = np.atleast_1d(axes).ravel()
    if len(axes) != len(result):
        raise ValueError(f"need {len(result)} axes (one per level), got {len(axes)}")
    for ax, (level, entry) in zip(axes, result.items(), strict=True):
        measured, sampled = entry["measured_hz"], entry["sampled_hz"]
        low, high = min(measured.min(), sampled.min()), max(measured.max(), sampled.max())
        pad = 0.1 * (high - low)
        grid = np.linspace(low - pad, high + pad, 400)
        for values, fit, colour, what in (
            (measured, entry["measured_fit"], "black", "measured"),
            (sampled, entry["sampled_fit"], LEVEL_COLOURS.get(level, "tab:orange"), "sampled"),
        ):
            ax.hist(values, bins="auto", density=True, color=colour, alpha=0.25)
            ax.plot(grid, fit.dist.pdf(grid), color=colour, lw=2, label=f"{what}: {fit.family}")
        d = entry["distances"]
        ax.plot([], [], " ", label=f"KS {d['ks_statistic']:.2f} (p = {d['ks_pvalue']:.2g})")
        ax.plot([], [], " ", label=f"W = {d['wasserstein']:.3g} Hz")
        ax.set(
            xlabel="frequency (Hz)", ylabel="probability density",
            title=f"{level} amplitude ({entry['amplitude_mm']:.3g} mm)",
        )  # fmt: skip
        ax.legend(fontsize="small")
    return axes[0].figure


# ---------------------------------------------------------------------------
# the report folder


def _jsonable(value):
    """Plain JSON types; NaN and inf become null (strict JSON has no NaN)."""
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple | np.ndarray):
        return [_jsonable(v) for v in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return float(value) if np.isfinite(value) else None
    return value


def _level_pdfs_record(result: Mapping[str, Mapping]) -> dict:
    """:func:`level_pdfs` without the sample arrays, with their means and spreads."""
    out = {}
    for level, entry in result.items():
        measured, sampled = entry["measured_hz"], entry["sampled_hz"]
        out[level] = {
            "index": entry["index"],
            "amplitude_mm": entry["amplitude_mm"],
            "n_measured": measured.size,
            "n_sampled": sampled.size,
            "n_dropped": entry["n_dropped"],
            "measured_mean_hz": measured.mean(),
            "measured_sd_hz": measured.std(ddof=1),
            "sampled_mean_hz": sampled.mean(),
            "sampled_sd_hz": sampled.std(ddof=1),
            "mean_shift_hz": entry["mean_shift_hz"],
            "measured_fit": entry["measured_fit"].to_dict(),
            "sampled_fit": entry["sampled_fit"].to_dict(),
            "distances": entry["distances"],
        }
    return out


def report(
    idata: xr.DataTree,
    measured: BackboneSet,
    *,
    density: BackboneDensity | None = None,
    var_names: Sequence[str] | None = None,
    out: str | os.PathLike = "report/",
    sampler: str | None = None,
    name: str = "backbone",
) -> dict:
    """Write the report folder: every figure as PNG and ``report.json``.

    Parameters
    ----------
    idata
        The trace of :func:`pm_joint.updating.sample`.
    measured
        The measured backbones the model was updated with.
    density
        The likelihood's density; default: fitted to ``measured`` with the
        defaults of :func:`pm_joint.updating.build_model` (checked against the
        trace's observed data, so other levels raise rather than mislead).
    var_names
        Parameters to report; default :func:`default_var_names`.
    out
        The report folder (created if missing).
    sampler
        Sampler name, where the trace does not tell (see :func:`sampler_info`).

    Returns
    -------
    dict
        The content of ``report.json``: ``var_names``, ``summary`` (records),
        ``correlation`` (``variables``, ``matrix``), ``level_pdfs``, ``sampler``
        and ``files`` (names in ``out``, ``report.json`` last).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = _var_names(idata, var_names)
    if density is None:
        density = BackboneDensity.fit(measured)
    pdfs = level_pdfs(idata, density, name=name)
    corr = correlation_matrix(idata, names)
    files = [*plot_pairs(idata, names, out), *plot_trace_rank(idata, names, out)]
    files.append(_save_png(plot_correlation(corr), out / "correlation.png"))
    backbones = plot_predictive_backbones(idata, density, measured, name=name)
    files.append(_save_png(backbones, out / "predictive_backbones.png"))
    files.append(_save_png(plot_level_pdfs(pdfs), out / "level_pdfs.png"))
    content = _jsonable(
        {
            "var_names": names,
            "summary": summarize(idata, names).reset_index(names="variable").to_dict("records"),
            "correlation": {"variables": list(corr.columns), "matrix": corr.values},
            "level_pdfs": _level_pdfs_record(pdfs),
            "sampler": sampler_info(idata, sampler),
            "files": [p.name for p in files] + ["report.json"],
        }
    )
    atomic_write_text(out / "report.json", json.dumps(content, indent=2, allow_nan=False))
    return content
