"""Figures of a posterior: pairs, trace and rank, correlation, sampled backbones, PDFs.

The paper's Figs. 19–22. Each ``plot_*`` takes numbers from
:mod:`pm_joint.analysis` (or the DataTree) and returns a matplotlib Figure or,
for arviz's own plots, writes PNG files atomically and returns their paths.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path

import arviz as az
import numpy as np
import pandas as pd
import xarray as xr
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from identification.measurements.backbone import BackboneSet
from pm_joint.analysis import (
    CI_PROB,
    checked_predictions,
    group_dataset,
    resolve_var_names,
    thin_rows,
)
from pm_joint.distributions import BackboneDensity, level_marks
from pm_joint.plotting.files import new_axes, save_collection

__all__ = [
    "LEVEL_COLOURS",
    "plot_correlation",
    "plot_level_pdfs",
    "plot_pairs",
    "plot_predictive_backbones",
    "plot_trace_rank",
]

#: Parameters per pair-scatter matrix (the paper splits 12 into two 6 × 6 matrices).
PAIR_GROUP = 6
#: The paper's colours for the low, mid and high amplitude levels (Fig. 21a).
LEVEL_COLOURS = {"low": "tab:red", "mid": "tab:blue", "high": "tab:green"}
#: Draws per chain the rank plot is thinned to.
RANK_DRAWS = 1000


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
    for k, group in enumerate(_pair_groups(resolve_var_names(idata, var_names)), start=1):
        collection = az.plot_pair(
            idata, var_names=group, marginal_kind="hist", backend="matplotlib"
        )
        paths.append(save_collection(collection, out_dir / f"pairs_{k}.png"))
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
    names = resolve_var_names(idata, var_names)
    trace = az.plot_trace(idata, var_names=names, backend="matplotlib")
    if group_dataset(idata, "posterior").sizes["chain"] < 2:
        return [save_collection(trace, out_dir / "trace.png")]
    factor = -(-group_dataset(idata, "posterior").sizes["draw"] // RANK_DRAWS)
    rank = az.plot_rank(
        idata, var_names=names, thin=factor > 1, stats={"thin": {"factor": factor}},
        backend="matplotlib",
    )  # fmt: skip
    return [
        save_collection(trace, out_dir / "trace.png"),
        save_collection(rank, out_dir / "rank.png"),
    ]


def plot_correlation(corr: pd.DataFrame, ax: Axes | None = None) -> Figure:
    """Heatmap of a correlation matrix with the values written in (Fig. 20)."""
    if corr.shape[0] != corr.shape[1] or list(corr.index) != list(corr.columns):
        raise ValueError(f"corr must be a square matrix with equal labels, got shape {corr.shape}")
    n = corr.shape[0]
    if ax is None:
        side = min(3 + 0.6 * n, 14)
        _, (ax,) = new_axes(figsize=(side + 1, side))
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
    ax: Axes | None = None,
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
    sampled = density.split(checked_predictions(idata, density, name))["frequency_hz"]
    amplitude_mm = 1e3 * density.amplitudes_m
    if ax is None:
        _, (ax,) = new_axes()
    ax.plot(amplitude_mm, thin_rows(sampled, n_lines).T, color="tab:orange", lw=0.5, alpha=0.15)
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


def plot_level_pdfs(result: Mapping[str, Mapping], axes: Sequence[Axes] | None = None) -> Figure:
    """Measured and sampled frequency histograms with their best-fit PDFs (Fig. 22).

    ``result`` is the output of :func:`level_pdfs`; one panel per level, the
    fitted families and the KS / Wasserstein distances in each legend.
    """
    if not result:
        raise ValueError("no amplitude levels to plot")
    if axes is None:
        _, axes = new_axes(len(result), figsize=(4.5 * len(result), 4))
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
