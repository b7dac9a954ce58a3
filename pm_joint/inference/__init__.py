"""Stochastic updating in PyMC: the models, their sampling and their posteriors on disk.

:mod:`~pm_joint.inference.models` builds the ``pm.Model`` objects (the paper's
population matching and the hierarchical model), :mod:`~pm_joint.inference.sampling`
samples them, :mod:`~pm_joint.inference.storage` keeps posteriors (netCDF files and
zarr traces) with the likelihood they were sampled with.
"""

from pm_joint.inference.models import (
    HIERARCHICAL,
    POPULATION_MATCHING,
    amplitudes_within_surrogate,
    build_model,
    hierarchical_model,
    uniform_priors,
)
from pm_joint.inference.sampling import (
    GRADIENT_SAMPLERS,
    HIERARCHICAL_TARGET_ACCEPT,
    POPULATION_MODELS,
    SAMPLER_DEFAULTS,
    SAMPLERS,
    continue_sampling,
    sample,
)
from pm_joint.inference.storage import (
    attach_density,
    load_posterior,
    posterior_sha256,
    save_posterior,
    stored_density,
)

__all__ = [
    "GRADIENT_SAMPLERS",
    "HIERARCHICAL",
    "HIERARCHICAL_TARGET_ACCEPT",
    "POPULATION_MATCHING",
    "POPULATION_MODELS",
    "SAMPLERS",
    "SAMPLER_DEFAULTS",
    "amplitudes_within_surrogate",
    "attach_density",
    "build_model",
    "continue_sampling",
    "hierarchical_model",
    "load_posterior",
    "posterior_sha256",
    "sample",
    "save_posterior",
    "stored_density",
    "uniform_priors",
]
