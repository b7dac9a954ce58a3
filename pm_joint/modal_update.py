"""``pm-joint update`` of an N-mode ModalModel on a campaign's per-mode backbones.

The N-mode twin of :func:`pm_joint.pipeline.update_backbones`: the same samplers
(:func:`~pm_joint.inference.sample`, defaults from
:data:`~pm_joint.sampler_defaults.SAMPLER_DEFAULTS` on the forward model
``modal_harmonic``, or ``modal_surrogate`` on its surrogate), the same convergence
verdict, the same posterior file and
attributes; the models are those of :mod:`pm_joint.inference.modal`.
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from typing import Any

import xarray as xr

from identification.measurements.backbone import BackboneSet
from identification.multimode.model import ModalModel
from pm_joint.analysis import attach_loo, convergence_verdict
from pm_joint.inference import continue_sampling, sample, save_posterior
from pm_joint.inference.modal import (
    MODAL_FORWARD,
    MODAL_SURROGATE_FORWARD,
    build_modal_model,
    draws_outside_box,
    modal_hierarchical_model,
    posterior_mode,
)
from pm_joint.inference.storage import attach_density, stored_density
from pm_joint.inference.traces import earlier_trace
from pm_joint.report_folder import report
from pm_joint.sampler_defaults import GRADIENT_SAMPLERS, run_settings, sampler_reason
from surrogates.modal import ModalSurrogate

__all__ = ["DENSITY_ATTR_MODE", "mode_report", "update_modes"]

#: Attribute of a saved N-mode posterior holding mode m's likelihood density (``.format(m)``).
DENSITY_ATTR_MODE = "pm_joint_density_mode{}"


def update_modes(
    model: ModalModel,
    measured: Mapping[int, BackboneSet],
    out: str | os.PathLike,
    *,
    population: str = "matching",
    names: Sequence[str] | None = None,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    sampler: str | None = None,
    draws: int | None = None,
    tune: int | None = None,
    chains: int = 2,
    seed: int = 0,
    trace: str | os.PathLike | None = None,
    resume: bool = False,
    progressbar: bool = True,
    surrogate: ModalSurrogate | None = None,
) -> xr.DataTree:
    """Update ``model`` on each mode's backbones; saves the posterior (netCDF) to ``out``.

    ``population`` ``"matching"`` (:func:`~pm_joint.inference.modal.build_modal_model`) or
    ``"hierarchical"`` (:func:`~pm_joint.inference.modal.modal_hierarchical_model`, with
    its LOO); each mode's backbone from ``surrogate`` where given (forward model
    ``modal_surrogate``; the hierarchical posterior then records the share of its draws
    outside the surrogate's training box, attribute ``outside_surrogate_box``), else from
    the N-mode harmonic balance (``modal_harmonic``);
    ``trace``/``resume`` as for one mode. The posterior carries its convergence verdict
    (attribute ``convergence``), the sampler and why, and each mode's likelihood density
    (attributes :data:`DENSITY_ATTR_MODE`).
    """
    forward = MODAL_FORWARD if surrogate is None else MODAL_SURROGATE_FORWARD
    sampler, draws, tune = run_settings(population, forward, sampler, draws, tune)
    earlier_run = earlier_trace(trace, resume)
    if population == "hierarchical":
        pm_model = modal_hierarchical_model(
            model, measured, names, channels=channels, surrogate=surrogate
        )
    else:
        pm_model = build_modal_model(model, measured, names=names, channels=channels,
                                     native_graph=sampler in GRADIENT_SAMPLERS,
                                     surrogate=surrogate)  # fmt: skip
    if earlier_run:
        idata = continue_sampling(pm_model, trace, draws=draws, sampler=sampler)
    else:
        # Population matching's chains start at the posterior's mode (posterior_mode).
        start = posterior_mode(pm_model) if population != "hierarchical" else None
        idata = sample(
            pm_model, sampler=sampler, draws=draws, tune=tune, chains=chains, random_seed=seed,
            trace=trace, progressbar=progressbar, initvals=start,
        )  # fmt: skip
    idata.attrs["convergence"] = json.dumps(convergence_verdict(idata).to_dict())
    idata.attrs["modes"] = json.dumps(sorted(measured))
    if population == "hierarchical":
        attach_loo(idata, pm_model)
        idata.attrs["varying_parameters"] = json.dumps(list(pm_model.varying))
        if surrogate is not None:
            idata.attrs["outside_surrogate_box"] = draws_outside_box(idata, surrogate)
    else:
        # No identifiability check as for one mode: its Jacobian compiles each mode's graph
        # again (minutes for the loop of the N-mode graph).
        for m, density in pm_model.backbone_densities.items():
            attach_density(idata, density, attribute=DENSITY_ATTR_MODE.format(m))
    reason = sampler_reason(population, forward, sampler)
    idata.attrs["sampler_reason"] = reason
    metadata = {
        "forward": forward,
        "sampler": sampler,
        "sampler_reason": reason,
        "population_model": pm_model.population_model,
        "modal_model": model.name or "ModalModel",
    }
    save_posterior(idata, out, metadata=metadata)
    return idata


def mode_report(
    idata: xr.DataTree, measured: Mapping[int, BackboneSet], mode: int, out: str | os.PathLike
) -> dict[str, Any]:
    """The one-mode report folder (:func:`pm_joint.report_folder.report`) of ``mode``'s
    potential ``backbone_mode{m}``: its measured backbones under the density stored with
    the draws; returns the report's content."""
    density = stored_density(idata, DENSITY_ATTR_MODE.format(mode))
    return report(idata, measured[mode], density=density, out=out, name=f"backbone_mode{mode}")
