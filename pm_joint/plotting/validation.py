"""Figures of an identified model against its record (the paper's Figs. 9–10)."""

from __future__ import annotations

from matplotlib.figure import Figure

from identification.sindy import Validation, plot_validation

__all__ = ["plot_validation_figure"]


def plot_validation_figure(validation: Validation, channel: str = "velocity") -> Figure:
    """Measured against simulated ``channel`` (``"velocity"`` or ``"acceleration"``)."""
    fig = Figure(figsize=(10, 7))
    plot_validation(validation, fig.subplots(3, 1), channel=channel)
    fig.tight_layout()
    return fig
