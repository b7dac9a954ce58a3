"""pm-joint: stochastic model updating of nonlinear structural joints, as a PyMC plug-in.

``import pm_joint as pj`` reaches what a PyMC user needs::

    measured = pj.extract_backbones(pj.Campaign("campaign"))
    with pj.build_model(model, measured, forward="harmonic"):  # a pm.Model
        ...
    idata = pj.sample(pm_model, sampler="nuts")

The names load their modules (and PyMC, pytensor, ...) on first access, so
that ``import pm_joint`` itself stays cheap.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "BackboneAmplitude",
    "BackboneDensity",
    "BackboneSet",
    "Campaign",
    "JointModel",
    "Workspace",
    "build_model",
    "continue_sampling",
    "convergence_verdict",
    "criticize",
    "extract_backbones",
    "forward_model",
    "hierarchical_model",
    "identify",
    "load_posterior",
    "loo",
    "report",
    "sample",
    "save_posterior",
]

_LAZY = {
    "BackboneAmplitude": "pm_joint.distributions",
    "BackboneDensity": "pm_joint.distributions",
    "forward_model": "pm_joint.forward",
    "build_model": "pm_joint.inference",
    "hierarchical_model": "pm_joint.inference",
    "sample": "pm_joint.inference",
    "continue_sampling": "pm_joint.inference",
    "save_posterior": "pm_joint.inference",
    "load_posterior": "pm_joint.inference",
    "convergence_verdict": "pm_joint.analysis",
    "loo": "pm_joint.analysis",
    # The adapter from posterior draws to the criticism engine (model or DataTree).
    "criticize": "pm_joint.analysis.posterior",
    "report": "pm_joint.report_folder",
    "Workspace": "pm_joint.workspace",
    "JointModel": "identification.model",
    "BackboneSet": "identification.measurements.backbone",
    "extract_backbones": "identification.measurements.extraction",
    "Campaign": "identification.measurements.records",
    "identify": "identification.sindy",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'pm_joint' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
