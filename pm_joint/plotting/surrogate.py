"""Figure of a surrogate against the curves of its dataset (the paper's Fig. 17)."""

from __future__ import annotations

import numpy as np
from matplotlib.figure import Figure

from surrogates.dataset import BackboneDataset
from surrogates.runtime import MASK_CHANNEL, SurrogateRuntime

__all__ = ["plot_surrogate_check"]


def plot_surrogate_check(
    runtime: SurrogateRuntime, dataset: BackboneDataset, n_curves: int = 6
) -> Figure:
    """``n_curves`` curves of the dataset (dots) against the surrogate's prediction (lines).

    The curves come from the test split when the dataset has splits (else from
    all of it). On the amplitude grid a dot is drawn where the curve has a
    backbone (and was observed), a line where the surrogate predicts one.
    """
    pool = np.flatnonzero(dataset.partition == "test")
    pool = pool if pool.size else np.arange(len(dataset))
    rows = pool[np.linspace(0, pool.size - 1, min(n_curves, pool.size)).astype(int)]
    predicted = runtime.predict(dataset.X[rows])
    spec = dataset.spec
    f = spec.channel_index("frequency_hz")
    if spec.representation == "amplitude_grid":
        mask = spec.channel_index(MASK_CHANNEL)
        amplitude = np.broadcast_to(spec.amplitudes_m, (2, rows.size, spec.n_levels))
        shown = (dataset.Y[rows, :, mask] >= 0.5) & dataset.observed[rows]
        truth = np.where(shown, dataset.Y[rows, :, f], np.nan)
        line = np.where(predicted[..., mask] >= 0.5, predicted[..., f], np.nan)
    else:
        a = spec.channel_index("amplitude_m")
        amplitude = np.stack([dataset.Y[rows, :, a], predicted[..., a]])
        truth, line = dataset.Y[rows, :, f], predicted[..., f]
    fig = Figure(figsize=(6, 4.5))
    ax = fig.subplots()
    for k in range(rows.size):
        dots = ax.plot(1e3 * amplitude[0, k], truth[k], "o", ms=3)[0]
        ax.plot(1e3 * amplitude[1, k], line[k], "-", color=dots.get_color())
    ax.set(xlabel="amplitude (mm)", ylabel="frequency (Hz)",
           title="test curves (dots) vs surrogate (lines)")  # fmt: skip
    fig.tight_layout()
    return fig
