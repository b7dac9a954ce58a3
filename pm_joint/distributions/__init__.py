"""The backbone likelihood: the measured population's density and its PyMC distribution.

:mod:`~pm_joint.distributions.density` fits the joint density of the measured
backbone values at amplitude levels (numpy, scipy); :mod:`~pm_joint.distributions.
backbone_amplitude` writes the same density as a pytensor graph and puts it into a
``pm.Model``; :mod:`~pm_joint.distributions.families` ranks scipy.stats families for
one-dimensional samples (the marginals, and the paper's PDFs per amplitude level), and
:mod:`~pm_joint.distributions.family_choice` chooses each marginal's family for few
samples (the normal unless another is clearly better).
"""

from pm_joint.distributions.backbone_amplitude import (
    BackboneAmplitude,
    NanCounter,
    interpolate_backbone,
    logp_graph,
)
from pm_joint.distributions.density import (
    CHANNELS,
    BackboneDensity,
    amplitude_levels,
    level_marks,
)
from pm_joint.distributions.families import (
    CANDIDATES,
    UNBOUNDED_CANDIDATES,
    DistributionFit,
    distances,
    fit_best,
    fit_family,
)
from pm_joint.distributions.family_choice import choose_family, normal_margin_aicc

__all__ = [
    "CANDIDATES",
    "CHANNELS",
    "UNBOUNDED_CANDIDATES",
    "BackboneAmplitude",
    "BackboneDensity",
    "DistributionFit",
    "NanCounter",
    "amplitude_levels",
    "choose_family",
    "distances",
    "fit_best",
    "fit_family",
    "interpolate_backbone",
    "level_marks",
    "logp_graph",
    "normal_margin_aicc",
]
