"""The posterior report folder: every figure of the paper's Figs. 19–22 and ``report.json``.

:func:`report` computes with :mod:`pm_joint.analysis`, draws with
:mod:`pm_joint.plotting` and writes both into one folder; it returns what it
wrote, which the HTML page (:mod:`pm_joint.html`) is built from.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from identification.artifacts import atomic_write_text
from identification.measurements.backbone import BackboneSet
from pm_joint.analysis import (
    UnmovedDraws,
    convergence_verdict,
    correlation_matrix,
    group_dataset,
    level_pdfs,
    resolve_var_names,
    sampler_info,
    summarize,
    unmoved_components,
)
from pm_joint.distributions import BackboneDensity
from pm_joint.inference.models import HIERARCHICAL, POPULATION_MATCHING
from pm_joint.inference.storage import stored_density
from pm_joint.plotting import (
    plot_correlation,
    plot_level_pdfs,
    plot_pairs,
    plot_predictive_backbones,
    plot_trace_rank,
    save_png,
)

__all__ = ["POPULATION_MEANING", "report"]

#: What each population model's posterior is, in the words every report prints.
POPULATION_MEANING = {
    POPULATION_MATCHING: (
        "Population matching (the paper's method): the posterior is the set of parameter "
        "vectors whose predicted backbones look like members of the measured population, "
        "scored by the population density fitted to the measured curves. Its intervals are "
        "a population range, not the uncertainty of one assembly; it is the population's "
        "distribution only where the forward model is one-to-one over the prior box (see "
        "the identifiability check), else the prior box shapes the marginals. It is no "
        "likelihood of the measured curves: LOO and WAIC are refused."
    ),
    HIERARCHICAL: (
        "Hierarchical population model: every measured curve has its own parameters, drawn "
        "from a log-normal population whose median ({p}_population) and log-spread "
        "(log_spread) are estimated; every measured point is scored by a normal likelihood "
        "with an amplitude-dependent measurement error. Intervals of the population "
        "parameters are posterior uncertainty; new assemblies (posterior_predictive) include "
        "the population scatter and the noise; LOO scores the measured points."
    ),
}


def _jsonable(value: Any) -> Any:
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


def _level_pdfs_record(result: Mapping[str, Mapping]) -> dict[str, Any]:
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
) -> dict[str, Any]:
    """Write the report folder: every figure as PNG and ``report.json``.

    Parameters
    ----------
    idata
        The trace of :func:`pm_joint.sample` (or :func:`pm_joint.load_posterior`).
    measured
        The measured backbones the model was updated with.
    density
        The likelihood's density; default: the one stored with the posterior
        (:func:`pm_joint.sample` keeps it for a :func:`pm_joint.build_model`
        model, :func:`pm_joint.save_posterior` writes it), else (a posterior
        written before densities were stored) one fitted to ``measured`` with
        the defaults of :func:`pm_joint.build_model`, with a warning; either is
        checked against the trace's observed data, so other levels raise rather
        than mislead.
    var_names
        Parameters to report; default
        :func:`~pm_joint.analysis.summaries.default_var_names`.
    out
        The report folder (created if missing).
    sampler
        Sampler name, where the trace does not tell (see
        :func:`~pm_joint.analysis.summaries.sampler_info`).

    Returns
    -------
    dict
        The content of ``report.json``: ``convergence`` (the verdict,
        :func:`~pm_joint.analysis.convergence_verdict`) first, then
        ``population_model`` (which model, and what its posterior means),
        ``identifiability`` (population matching) or ``loo`` (hierarchical),
        ``level_pdfs`` (population matching; empty otherwise), ``var_names``,
        ``summary`` (records), ``correlation`` (``variables``, ``matrix``),
        ``sampler``, ``not_computed`` (one sentence per figure or number this
        posterior cannot give, and why; each is also a warning) and ``files``
        (names in ``out``, ``report.json`` last).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = resolve_var_names(idata, var_names)
    verdict = convergence_verdict(idata)
    kind = idata.attrs.get("population_model", POPULATION_MATCHING)
    not_computed = _what_cannot_be_computed(idata, names)
    unmoved = {c.split("[")[0] for c in unmoved_components(idata, names)}
    paired = [n for n in names if n not in unmoved]
    files = [*(plot_pairs(idata, paired, out) if paired else []),
             *plot_trace_rank(idata, names, out)]  # fmt: skip
    corr = correlation_matrix(idata, names)
    files.append(save_png(plot_correlation(corr), out / "correlation.png"))
    content: dict[str, Any] = {
        "convergence": verdict.to_dict(),
        "population_model": {"kind": kind, "meaning": POPULATION_MEANING[kind]},
    }
    if kind == POPULATION_MATCHING:
        density = density or stored_density(idata)
        if density is None:
            warnings.warn(
                "no likelihood density is stored with this posterior (written before pm-joint "
                "stored it, or not from build_model): refitting one at the default amplitude "
                "levels",
                UserWarning,
                stacklevel=2,
            )
            density = BackboneDensity.fit(measured)
        try:
            pdfs = level_pdfs(idata, density, name=name)
        except UnmovedDraws as exc:
            pdfs = {}
            not_computed.append(f"the PDFs at the amplitude levels: {exc}")
        backbones = plot_predictive_backbones(idata, density, measured, name=name)
        files.append(save_png(backbones, out / "predictive_backbones.png"))
        if pdfs:
            files.append(save_png(plot_level_pdfs(pdfs), out / "level_pdfs.png"))
        content["level_pdfs"] = _level_pdfs_record(pdfs)
        stored = idata.attrs.get("identifiability")
        content["identifiability"] = json.loads(stored) if stored else None
        content["loo"] = "refused: population matching has no likelihood of the measured curves"
    else:
        stored = idata.attrs.get("loo")
        content["loo"] = json.loads(stored) if stored else None
        stored = idata.attrs.get("varying_choice")
        content["identifiability"] = json.loads(stored) if stored else None
        content["level_pdfs"] = {}
    content = _jsonable(
        {
            **content,
            "var_names": names,
            "summary": summarize(idata, names).reset_index(names="variable").to_dict("records"),
            "correlation": {"variables": list(corr.columns), "matrix": corr.values},
            "sampler": sampler_info(idata, sampler),
            "not_computed": not_computed,
            "files": [p.name for p in files] + ["report.json"],
        }
    )
    for line in not_computed:
        warnings.warn(f"not computed from this posterior: {line}", UserWarning, stacklevel=2)
    atomic_write_text(out / "report.json", json.dumps(content, indent=2, allow_nan=False))
    return content


def _what_cannot_be_computed(idata: xr.DataTree, names: Sequence[str]) -> list[str]:
    """One plain sentence per figure or number that this posterior cannot give, and why.

    A chain that never moved a parameter (a short run whose proposals were all
    rejected) leaves no spread to bin, smooth or correlate; one chain has no
    ranks to compare and no r̂.
    """
    posterior = group_dataset(idata, "posterior")
    shape = f"{posterior.sizes['chain']} chain(s) × {posterior.sizes['draw']} draw(s)"
    lines = []
    unmoved = unmoved_components(idata, names)
    if unmoved:
        lines.append(
            f"the pair plot, histogram and correlations of {', '.join(unmoved)}: every one of "
            f"the {shape} holds one value (the chains never moved it), so there is no spread "
            "to bin or correlate; sample longer or tune longer"
        )
    if posterior.sizes["chain"] < 2:
        lines.append(f"r̂ and the rank plot: {shape}; both compare chains, run at least two")
    return lines
