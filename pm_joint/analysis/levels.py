"""Measured against sampled backbone values at the likelihood's amplitude levels.

The posterior-predictive backbones are the forward model's predictions at the
likelihood's amplitude levels, stored by
:func:`~pm_joint.distributions.BackboneAmplitude` as ``{name}_predicted``
(channel-major, one value per level and channel). :func:`level_pdfs` compares
them with the measured values at the low, mid and high levels (the paper's Fig. 22).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

from pm_joint.analysis.summaries import SAMPLE_DIMS
from pm_joint.distributions import CANDIDATES, BackboneDensity, distances, fit_best, level_marks

__all__ = ["UnmovedDraws", "checked_predictions", "level_pdfs", "predicted_values", "thin_rows"]


class UnmovedDraws(ValueError):
    """Every draw predicts one value at a level: the chains never moved, there is no
    distribution of the sampled values to fit or compare."""


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


def checked_predictions(
    idata: xr.DataTree, density: BackboneDensity, name: str = "backbone"
) -> np.ndarray:
    """:func:`predicted_values`, after checking that they belong to ``density``."""
    values = predicted_values(idata, name)
    if values.shape[1] != density.n_dims:
        raise ValueError(
            f"{name}_predicted has {values.shape[1]} values per draw, but the density has "
            f"{len(density.amplitudes_m)} levels × {len(density.channels)} channel(s) = "
            f"{density.n_dims}: pass the density the model was built with"
        )
    # Where the trace keeps the measured matrix: constant_data (population matching as a
    # potential), observed_data in posteriors written before.
    for group, variable in (("constant_data", f"{name}_measured"), ("observed_data", name)):
        if group not in idata.children or variable not in idata[group].data_vars:
            continue
        observed = idata[group][variable].values
        same = observed.shape == density.observations.shape and np.allclose(
            observed, density.observations, rtol=1e-9, atol=0
        )
        if not same:
            raise ValueError(
                f"the density's measured values differ from {group}/{variable} of the trace: "
                "it was fitted at other amplitude levels or to other curves; pass the density "
                "the model was built with"
            )
    return values


def thin_rows(values: np.ndarray, n_rows: int) -> np.ndarray:
    """At most ``n_rows`` evenly spaced rows (every chain keeps its share)."""
    if len(values) <= n_rows:
        return values
    return values[np.linspace(0, len(values) - 1, n_rows).astype(int)]


def level_pdfs(
    idata: xr.DataTree,
    density: BackboneDensity,
    marks: Sequence[str] = ("low", "mid", "high"),
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
        The likelihood's :class:`~pm_joint.distributions.BackboneDensity`.
    marks
        Level names from :func:`~pm_joint.distributions.level_marks`.
    candidates
        scipy.stats families for :func:`~pm_joint.distributions.fit_best`.
    max_fit_samples
        The sampled frequencies are thinned evenly to this many for the
        maximum-likelihood fits (MCMC draws are correlated, so little is lost);
        the distances use every draw.

    Returns
    -------
    dict
        Per level: ``index``, ``amplitude_mm``, ``measured_hz``, ``sampled_hz``
        (finite draws only; ``n_dropped`` counts the others), ``measured_fit``
        and ``sampled_fit`` (best :class:`~pm_joint.distributions.DistributionFit` by
        AIC), ``distances`` (``ks_statistic``, ``ks_pvalue``, ``wasserstein``,
        in Hz) and ``mean_shift_hz`` (sampled minus measured mean).
    """
    if "frequency_hz" not in density.channels:
        raise ValueError(f"the density has no frequency channel (channels {density.channels})")
    indices = level_marks(density.amplitudes_m)
    unknown = [mark for mark in marks if mark not in indices]
    if unknown:
        raise ValueError(f"unknown amplitude level(s) {unknown}; choose from {list(indices)}")
    sampled = density.split(checked_predictions(idata, density, name))["frequency_hz"]
    measured = density.split(density.observations)["frequency_hz"]
    result = {}
    for level in marks:
        i = indices[level]
        column = sampled[:, i]
        finite = column[np.isfinite(column)]
        if finite.size and np.ptp(finite) == 0:
            raise UnmovedDraws(
                f"{level} amplitude level: every posterior draw predicts the same frequency "
                f"({finite[0]:.6g} Hz): the chains did not move; tune longer or narrow the priors"
            )
        try:
            measured_fit = fit_best(measured[:, i], candidates)[0]
            sampled_fit = fit_best(thin_rows(finite, max_fit_samples), candidates)[0]
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
