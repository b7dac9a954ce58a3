"""Figure of a surrogate against the curves of its dataset (the paper's Fig. 17)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from surrogates.dataset import BackboneDataset
from surrogates.runtime import SurrogateRuntime

__all__ = ["plot_surrogate_check"]


def plot_surrogate_check(
    runtime: SurrogateRuntime, dataset: BackboneDataset, n_curves: int = 6
) -> Figure:
    """``n_curves`` curves of the dataset (dots) against the surrogate's prediction (lines)."""
    rows = np.linspace(0, len(dataset) - 1, n_curves).astype(int)
    predicted = runtime.predict(dataset.X[rows])
    a, f = dataset.spec.channel_index("amplitude_m"), dataset.spec.channel_index("frequency_hz")
    fig = Figure(figsize=(6, 4.5))
    ax = fig.subplots()
    for k, row in enumerate(rows):
        line = ax.plot(1e3 * dataset.Y[row, :, a], dataset.Y[row, :, f], "o", ms=3)[0]
        ax.plot(1e3 * predicted[k, :, a], predicted[k, :, f], "-", color=line.get_color())
    ax.set(xlabel="amplitude (mm)", ylabel="frequency (Hz)",
           title="dataset curves (dots) vs surrogate (lines)")  # fmt: skip
    fig.tight_layout()
    return fig
