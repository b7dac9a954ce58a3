"""Figures of a validation: measured against simulated signals (the paper's Figs. 9–10).

Drawing only: the caller passes matplotlib axes (of a ``matplotlib.figure.Figure``
or of pyplot) and writes the figure; nothing here imports matplotlib.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from identification.sindy.validation import Validation


def plot_validation(
    validation: Validation,
    axes: Sequence[Any],
    *,
    channel: str = "velocity",
    zoom_s: tuple[float, float] | None = None,
) -> None:
    """Draw the paper's Fig. 9 (velocity) or Fig. 10 (acceleration) on three matplotlib axes.

    ``axes``: overall comparison, zoomed comparison (``zoom_s``, default ten
    periods around the largest measured value), error over the whole record.
    """
    if channel not in ("velocity", "acceleration"):
        raise ValueError(f"channel must be 'velocity' or 'acceleration', got {channel!r}")
    if len(axes) != 3:
        raise ValueError(f"need 3 axes (overall, zoom, error), got {len(axes)}")
    t = validation.t
    measured = getattr(validation, f"measured_{channel}")
    predicted = getattr(validation, f"predicted_{channel}")
    unit = "m/s" if channel == "velocity" else "m/s²"
    if zoom_s is None:
        peak = t[np.argmax(np.abs(measured))]
        period = 10 * _dominant_period(t, measured)
        zoom_s = (peak - period / 2, peak + period / 2)
    window = (t >= zoom_s[0]) & (t <= zoom_s[1])
    for ax, mask in ((axes[0], slice(None)), (axes[1], window)):
        ax.plot(t[mask], measured[mask], label="measured")
        ax.plot(t[mask], predicted[mask], "--", label="SINDy model")
        ax.set_ylabel(f"{channel} ({unit})")
        ax.legend(loc="upper right")
    stats = getattr(validation, channel)
    axes[2].plot(t, predicted - measured)
    axes[2].set_ylabel(f"error ({unit})")
    axes[2].set_xlabel("time (s)")
    axes[2].set_title(f"mean {stats.mean:.3g}, max {stats.max_abs:.3g}, RMSE {stats.rmse:.3g} "
                      f"{unit}", fontsize="small")  # fmt: skip


def _dominant_period(t: np.ndarray, values: np.ndarray) -> float:
    """Period (s) of the strongest non-zero frequency of ``values``."""
    spectrum = np.abs(np.fft.rfft(values))
    frequencies = np.fft.rfftfreq(values.size, t[1] - t[0])
    return 1.0 / frequencies[1 + np.argmax(spectrum[1:])]
