"""Numbers of a posterior, arviz-style: DataTrees in, tables and dicts out, no figures.

:mod:`~pm_joint.analysis.summaries` (summary, correlation, sampler facts) and
:mod:`~pm_joint.analysis.levels` (measured against sampled values at the
likelihood's amplitude levels, the paper's PDFs per level),
:mod:`~pm_joint.analysis.convergence` (the convergence verdict every report opens
with) and :mod:`~pm_joint.analysis.population` (LOO, identifiability, new
assemblies of the hierarchical population).
"""

from pm_joint.analysis.convergence import (
    ESS_MIN,
    RHAT_MAX,
    ConvergenceVerdict,
    convergence_verdict,
)
from pm_joint.analysis.levels import (
    UnmovedDraws,
    checked_predictions,
    level_pdfs,
    predicted_values,
    thin_rows,
)
from pm_joint.analysis.population import (
    attach_loo,
    identifiability,
    loo,
    population_predictive,
)
from pm_joint.analysis.summaries import (
    CI_PROB,
    SAMPLE_DIMS,
    correlation_matrix,
    default_var_names,
    group_dataset,
    resolve_var_names,
    sampler_info,
    summarize,
    unmoved_components,
)

__all__ = [
    "CI_PROB",
    "ESS_MIN",
    "RHAT_MAX",
    "SAMPLE_DIMS",
    "ConvergenceVerdict",
    "UnmovedDraws",
    "attach_loo",
    "checked_predictions",
    "convergence_verdict",
    "correlation_matrix",
    "default_var_names",
    "group_dataset",
    "identifiability",
    "level_pdfs",
    "loo",
    "population_predictive",
    "predicted_values",
    "resolve_var_names",
    "sampler_info",
    "summarize",
    "thin_rows",
    "unmoved_components",
]
