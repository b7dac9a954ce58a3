"""Figures of backbone curves: the measured set, and the model's analytical backbones over it."""

from __future__ import annotations

from collections.abc import Mapping

from matplotlib.figure import Figure

from identification.measurements.backbone import Backbone, BackboneSet

__all__ = ["plot_analytical_backbones", "plot_measured_backbones"]


def plot_measured_backbones(measured: BackboneSet) -> Figure:
    """Frequency and damping ratio against amplitude of every measured curve."""
    fig = Figure(figsize=(10, 4))
    measured.plot(fig.subplots(1, 2))
    fig.tight_layout()
    return fig


def plot_analytical_backbones(measured: BackboneSet, curves: Mapping[str, Backbone]) -> Figure:
    """The model's analytical backbones over the measured curves (the paper's Fig. 12).

    ``curves`` maps a label (e.g. ``"harmonic balance"``, ``"PLL"``) to a
    backbone; the first is drawn as a line, the second as dots.
    """
    fig = Figure(figsize=(10, 4))
    ax_f, ax_d = fig.subplots(1, 2)
    for b in measured:
        ax_f.plot(b.amplitude_mm, b.frequency_hz, color="0.75", lw=0.8)
        ax_d.plot(b.amplitude_mm, 100 * b.damping_ratio, color="0.75", lw=0.8)
    for (label, b), style in zip(curves.items(), ("-", "o"), strict=False):
        ax_f.plot(b.amplitude_mm, b.frequency_hz, style, label=label, ms=3)
        ax_d.plot(b.amplitude_mm, 100 * b.damping_ratio, style, label=label, ms=3)
    ax_f.set(xlabel="amplitude (mm)", ylabel="frequency (Hz)", title="measured (grey) vs model")
    ax_d.set(xlabel="amplitude (mm)", ylabel="damping ratio (%)")
    ax_f.legend()
    fig.tight_layout()
    return fig
