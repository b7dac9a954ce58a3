"""Figures without pyplot's global state, written to PNG files atomically."""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from identification.artifacts import atomic_write_bytes

__all__ = ["DPI", "new_axes", "save_collection", "save_png"]

#: Resolution of the report's figures.
DPI = 120


def new_axes(n: int = 1, figsize: tuple[float, float] = (7, 4.5)) -> tuple[Figure, np.ndarray]:
    """A bare Figure with ``n`` axes in a row (no pyplot: no global state, any backend)."""
    fig = Figure(figsize=figsize, layout="constrained")
    axes = fig.subplots(1, n, squeeze=False)[0]
    return fig, axes


def save_png(fig: Figure, path: str | os.PathLike, dpi: int = DPI) -> Path:
    """Write ``fig`` as PNG; a reader never sees a half-written file."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return atomic_write_bytes(path, buffer.getvalue())


def save_collection(collection: Any, path: str | os.PathLike) -> Path:
    """Save an arviz PlotCollection's figure and free it (arviz draws through pyplot)."""
    import matplotlib.pyplot as plt

    fig = collection.get_viz("figure")
    try:
        return save_png(fig, path)
    finally:
        plt.close(fig)
