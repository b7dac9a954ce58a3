"""Numbers of a posterior, arviz-style: DataTrees in, tables and dicts out, no figures.

:mod:`~pm_joint.analysis.summaries` (summary, correlation, sampler facts) and
:mod:`~pm_joint.analysis.levels` (measured against sampled values at the
likelihood's amplitude levels, the paper's PDFs per level).
"""

from pm_joint.analysis.levels import checked_predictions, level_pdfs, predicted_values, thin_rows
from pm_joint.analysis.summaries import (
    CI_PROB,
    SAMPLE_DIMS,
    correlation_matrix,
    default_var_names,
    group_dataset,
    resolve_var_names,
    sampler_info,
    summarize,
)

__all__ = [
    "CI_PROB",
    "SAMPLE_DIMS",
    "checked_predictions",
    "correlation_matrix",
    "default_var_names",
    "group_dataset",
    "level_pdfs",
    "predicted_values",
    "resolve_var_names",
    "sampler_info",
    "summarize",
    "thin_rows",
]
