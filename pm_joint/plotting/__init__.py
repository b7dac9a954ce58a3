"""Every figure pm_joint draws, on bare matplotlib Figures (no pyplot state, any backend).

:mod:`~pm_joint.plotting.posterior` (the paper's Figs. 19–22),
:mod:`~pm_joint.plotting.backbones` (measured and analytical backbones, Fig. 12),
:mod:`~pm_joint.plotting.validation` (identified model against its record, Figs. 9–10),
:mod:`~pm_joint.plotting.surrogate` (surrogate against its dataset, Fig. 17);
:func:`~pm_joint.plotting.files.save_png` writes any of them atomically.
"""

from pm_joint.plotting.backbones import plot_analytical_backbones, plot_measured_backbones
from pm_joint.plotting.files import save_png
from pm_joint.plotting.posterior import (
    plot_correlation,
    plot_level_pdfs,
    plot_pairs,
    plot_predictive_backbones,
    plot_trace_rank,
)
from pm_joint.plotting.surrogate import plot_surrogate_check
from pm_joint.plotting.validation import plot_validation_figure

__all__ = [
    "plot_analytical_backbones",
    "plot_correlation",
    "plot_level_pdfs",
    "plot_measured_backbones",
    "plot_pairs",
    "plot_predictive_backbones",
    "plot_surrogate_check",
    "plot_trace_rank",
    "plot_validation_figure",
    "save_png",
]
