"""What a population posterior means: LOO where there is a likelihood, identifiability where
there is none, and new assemblies drawn from the hierarchical population.

:func:`loo`
    PSIS-LOO of the hierarchical model (pointwise log-likelihood of the
    measured points); refuses population matching, whose term is no
    likelihood of the measured curves.
:func:`identifiability`
    Population matching's condition: is the forward model one-to-one over the
    prior box? Singular values of the Jacobian of the predicted levels with
    respect to θ (in prior-box widths, levels whitened by the measured scatter)
    at posterior draws.
:func:`population_predictive`
    Backbones of new assemblies from the hierarchical posterior: population
    scatter and measurement noise included.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Sequence
from typing import Any

import arviz as az
import numpy as np
import pymc as pm
import xarray as xr

from identification.analytical.harmonic import backbone
from identification.model import JointModel
from pm_joint.analysis.summaries import SAMPLE_DIMS, group_dataset
from pm_joint.inference.models import POPULATION_MATCHING, POPULATION_SUFFIX

__all__ = ["attach_loo", "identifiability", "loo", "population_predictive"]


def loo(idata: xr.DataTree, pm_model: pm.Model | None = None) -> Any:
    """PSIS-LOO (arviz) over the measured points of a hierarchical posterior.

    Computes the ``log_likelihood`` group with ``pm.compute_log_likelihood``
    when it is missing (then ``pm_model`` is needed) and keeps it in ``idata``.

    Raises
    ------
    ValueError
        For a population-matching posterior: its term scores the model's
        predictions under the population density of the measured curves and is
        no likelihood of those curves; a LOO of it would be a number without
        meaning.
    """
    kind = idata.attrs.get("population_model") or getattr(pm_model, "population_model", None)
    if kind == POPULATION_MATCHING:
        raise ValueError(
            "LOO refused: population matching (the paper's method) scores the model's "
            "predicted backbone under the population density fitted to the measured curves; "
            "it is not a likelihood of the measured curves, so there is no pointwise "
            "log-likelihood to leave out. Use the hierarchical model "
            "(pm-joint update --population hierarchical) for LOO."
        )
    if "log_likelihood" not in idata.children:
        if pm_model is None:
            raise ValueError("the DataTree has no log_likelihood group: pass the pm_model")
        pm.compute_log_likelihood(idata, model=pm_model, progressbar=False)
    channels = list(idata["log_likelihood"].data_vars)
    if len(channels) > 1:  # one value per measured point and channel, summed per point
        total = sum(idata["log_likelihood"][c] for c in channels)
        tree = xr.DataTree.from_dict(
            {
                "/posterior": idata["posterior"].to_dataset(),
                "/log_likelihood": xr.Dataset({"points": total}),
            }
        )
        return az.loo(tree, var_name="points", pointwise=True)
    return az.loo(idata, var_name=channels[0], pointwise=True)


def attach_loo(idata: xr.DataTree, pm_model: pm.Model) -> None:
    """:func:`loo`'s summary as ``idata``'s attribute ``loo`` (JSON): ELPD, its standard
    error, ``p_loo``, the points and how many have a Pareto k above 0.7; where arviz's PSIS
    cannot fit a Pareto tail (a point whose log-likelihood takes one value over the tail's
    draws, seen on short runs), why, and a warning: the report says so instead of a number."""
    try:
        result = loo(idata, pm_model)
    except ValueError as error:
        idata.attrs["loo"] = json.dumps(f"not computed, arviz's PSIS failed: {error}")
        warnings.warn(f"LOO not computed: {error}", stacklevel=3)
        return
    pareto_k = np.asarray(result.pareto_k).ravel()
    idata.attrs["loo"] = json.dumps(
        {
            "elpd_loo": float(result.elpd),
            "se": float(result.se),
            "p_loo": float(result.p),
            "n_points": int(pareto_k.size),
            "pareto_k_above_0.7": int(np.sum(pareto_k > 0.7)),
        }
    )


def identifiability(
    pm_model: pm.Model,
    idata: xr.DataTree,
    *,
    name: str = "backbone",
    n_draws: int = 8,
    step: float = 1e-3,
) -> dict[str, Any]:
    """Is the forward model one-to-one over the prior box at the posterior draws?

    For ``n_draws`` posterior draws, the Jacobian of the predicted values at
    the likelihood's levels (``{name}_predicted``) with respect to θ is taken
    by central differences of ``step`` prior-box widths, each column scaled to
    one box width and each row divided by the measured population's spread at
    that level. A singular value below 1 is a direction in which crossing the
    whole box moves the predictions by less than the assembly-to-assembly
    scatter: there the posterior's marginals are set by the prior box, not by
    the data, and the posterior is no estimate of the population.

    Returns
    -------
    dict
        ``singular_values`` (per draw, largest first), ``flat_directions`` (per
        draw, the count below 1), ``n_parameters``, ``n_levels``, ``one_to_one``
        (no flat direction at any draw) and ``text``.
    """
    free = list(pm_model.free_RVs)
    names = [rv.name for rv in free]
    bounds = np.array([_uniform_bounds(pm_model, rv) for rv in free])
    density = getattr(pm_model, "backbone_density", None)
    scatter = np.std(density.observations, axis=0, ddof=1) if density is not None else np.ones(1)
    predicted = pm_model.compile_fn(pm_model[f"{name}_predicted"], inputs=free, mode="FAST_RUN",
                                    on_unused_input="ignore")  # fmt: skip
    posterior = group_dataset(idata, "posterior")
    table = np.column_stack([posterior[n].values.reshape(-1) for n in names])
    picks = table[np.linspace(0, len(table) - 1, min(n_draws, len(table))).astype(int)]
    width = bounds[:, 1] - bounds[:, 0]
    singular, flat = [], []
    for theta in picks:
        columns = []
        for j in range(len(names)):
            h = step * width[j]
            up, down = theta.copy(), theta.copy()
            up[j] = min(theta[j] + h, bounds[j, 1] - 1e-12 * width[j])
            down[j] = max(theta[j] - h, bounds[j, 0] + 1e-12 * width[j])
            f_up = predicted(dict(zip(names, up, strict=True)))
            f_down = predicted(dict(zip(names, down, strict=True)))
            columns.append((f_up - f_down) / (up[j] - down[j]) * width[j])
        jacobian = np.column_stack(columns) / scatter[:, None]
        if not np.all(np.isfinite(jacobian)):
            continue  # a draw at the edge of the forward model's range
        values = np.linalg.svd(jacobian, compute_uv=False)
        values = np.concatenate([values, np.zeros(len(names) - values.size)])
        singular.append(values.tolist())
        flat.append(int(np.sum(values < 1.0)))
    one_to_one = bool(singular) and max(flat) == 0
    n_levels = len(scatter)
    if not singular:
        text = "identifiability unknown: the forward model gave NaN around every draw checked"
    elif one_to_one:
        text = (
            f"one-to-one at the {len(singular)} draws checked: every direction of the "
            f"{len(names)} parameters moves the {n_levels} predicted values by more than the "
            "measured scatter across the prior box, so the posterior is a population estimate"
        )
    else:
        text = (
            f"NOT one-to-one: at the {len(singular)} draws checked, {min(flat)}–{max(flat)} of "
            f"the {len(names)} parameter directions move the {n_levels} predicted values by "
            "less than the measured scatter across the whole prior box; along them the "
            "marginals are set by the prior box, so read the posterior as a population range "
            "of parameter sets that reproduce the measured population, not as the population"
        )
    return {
        "parameters": names,
        "n_parameters": len(names),
        "n_levels": n_levels,
        "singular_values": singular,
        "flat_directions": flat,
        "one_to_one": one_to_one,
        "text": text,
    }


def _uniform_bounds(pm_model: pm.Model, rv) -> tuple[float, float]:
    """Lower and upper bound of a ``pm.Uniform`` free variable."""
    low, high = rv.owner.inputs[-2:]
    return float(pm_model.compile_fn(low, inputs=[], on_unused_input="ignore")({})), float(
        pm_model.compile_fn(high, inputs=[], on_unused_input="ignore")({})
    )


def population_predictive(
    idata: xr.DataTree,
    model: JointModel,
    names: Sequence[str],
    amplitudes_m: np.ndarray,
    *,
    channels: Sequence[str] = ("frequency_hz",),
    n_draws: int = 400,
    seed: int = 0,
) -> xr.Dataset:
    """Backbones of new assemblies from a hierarchical posterior, noise included.

    Each of ``n_draws`` posterior draws gives a new assembly
    ``θ = {p}_population · exp(log_spread · z)``, ``z ~ N(0, 1)``, its
    backbone at ``amplitudes_m`` and the measurement noise of that draw
    (``{channel}_noise`` and its amplitude slope, taken about the geometric mean
    of ``amplitudes_m``, times the backbone's value for a channel with relative
    noise). The backbone is what the likelihood compared the measurements
    with: the single-harmonic balance plus its truncation error, i.e. the
    harmonic balance with the harmonics the model's truncation correction used
    (attribute ``hierarchical_options``; posteriors without it: single-harmonic,
    absolute noise). Returns a Dataset with one variable per channel, dims
    ``(sample, amplitude)``.
    """
    posterior = group_dataset(idata, "posterior")
    rng = np.random.default_rng(seed)

    def flat(name: str) -> np.ndarray:
        da = posterior[name]
        rest = [d for d in da.dims if d not in SAMPLE_DIMS]
        return da.transpose(*SAMPLE_DIMS, *rest).values.reshape(-1, *[da.sizes[d] for d in rest])

    population = np.column_stack([flat(f"{n}{POPULATION_SUFFIX}") for n in names])
    spread = flat("log_spread")
    picks = np.linspace(0, len(population) - 1, min(n_draws, len(population))).astype(int)
    theta = population[picks] * np.exp(spread[picks] * rng.standard_normal(spread[picks].shape))
    amplitudes_m = np.asarray(amplitudes_m, dtype=float)
    options = json.loads(idata.attrs.get("hierarchical_options", "{}"))
    harmonics = options.get("truncation")
    method = {"method": "multi", "harmonics": harmonics} if harmonics else {"method": "single"}
    hb = backbone(model, amplitudes_m, parameters=theta, names=list(names), **method)
    relative = np.log(amplitudes_m) - np.mean(np.log(amplitudes_m))
    data = {}
    for channel in channels:
        noise = flat(f"{channel}_noise")[picks][:, None]
        if f"{channel}_noise_slope" in posterior:
            noise = noise * np.exp(flat(f"{channel}_noise_slope")[picks][:, None] * relative)
        clean = getattr(hb, channel)
        if channel in options.get("relative_noise", ()):
            noise = noise * np.abs(clean)
        data[channel] = (("sample", "amplitude"), clean + noise * rng.standard_normal(clean.shape))
    return xr.Dataset(
        data,
        coords={"amplitude": amplitudes_m},
        attrs={"parameters": json.dumps(list(names)), "n_draws": len(picks)},
    )
