"""Accuracy of a backbone surrogate on held-out curves (the paper's Table 5 metrics).

The metrics are plain numpy so they apply to any predictor (the torch
:class:`~surrogates.train.Surrogate` or the onnxruntime
:class:`~surrogates.runtime.SurrogateRuntime`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from surrogates.runtime import SurrogateSpec

__all__ = ["PAPER_TABLE5", "backbone_metrics"]

#: Paper Table 5: training-set size → (MSE, MAE, MAPE) on its test set.
PAPER_TABLE5 = {
    200: (2.82e-5, 0.00282, 0.774),
    300: (2.72e-5, 0.00274, 0.924),
    400: (2.42e-5, 0.00271, 1.502),
    500: (1.21e-5, 0.00239, 0.729),
}

_MM_PER_M = 1e3


def backbone_metrics(
    predicted: np.ndarray, observed: np.ndarray, spec: SurrogateSpec
) -> dict[str, Any]:
    """Errors of predicted backbones against observed ones.

    Parameters
    ----------
    predicted, observed
        ``(n, n_levels, n_channels)`` in physical units (channels of ``spec``).
    spec
        The surrogate's spec (channel names and order).

    Returns
    -------
    dict
        ``channels``: per channel, in its physical unit, ``mse``, ``mae``,
        ``mape_pct`` and ``max_ape_pct`` (over nonzero observations) and
        ``pearson``; ``pearson``: the paper's figure, one coefficient over all
        values flattened with amplitudes in mm (note that across channels of
        different magnitude this is close to 1 by construction, so the
        per-channel coefficients are the stricter test, ``pearson_min_channel``
        their minimum); ``mse_amplitude_mm2`` and ``mae_amplitude_mm``, the
        paper's MSE and MAE, when an amplitude channel is predicted.
    """
    predicted = spec.check_backbones(predicted, "predicted backbones")
    observed = spec.check_backbones(observed, "observed backbones")
    if predicted.shape != observed.shape:
        raise ValueError(f"predicted {predicted.shape} and observed {observed.shape} differ")
    per_channel = {}
    for index, name in enumerate(spec.channels):
        p, o = predicted[..., index].ravel(), observed[..., index].ravel()
        nonzero = o != 0
        ape = 100.0 * np.abs((p[nonzero] - o[nonzero]) / o[nonzero])
        per_channel[name] = {
            "mse": float(np.mean((p - o) ** 2)),
            "mae": float(np.mean(np.abs(p - o))),
            "mape_pct": float(ape.mean()) if ape.size else float("nan"),
            "max_ape_pct": float(ape.max()) if ape.size else float("nan"),
            "pearson": _pearson(p, o),
        }
    in_paper_units = np.ones(spec.n_channels)
    metrics: dict[str, Any] = {"n_curves": int(observed.shape[0]), "channels": per_channel}
    if "amplitude_m" in spec.channels:
        in_paper_units[spec.channel_index("amplitude_m")] = _MM_PER_M
        amplitude = per_channel["amplitude_m"]
        metrics["mse_amplitude_mm2"] = amplitude["mse"] * _MM_PER_M**2
        metrics["mae_amplitude_mm"] = amplitude["mae"] * _MM_PER_M
    metrics["pearson"] = _pearson(
        (predicted * in_paper_units).ravel(), (observed * in_paper_units).ravel()
    )
    metrics["pearson_min_channel"] = min(c["pearson"] for c in per_channel.values())
    return metrics


def _pearson(a: np.ndarray, b: np.ndarray) -> float:
    if np.ptp(a) == 0 or np.ptp(b) == 0:
        return float("nan")  # undefined for a constant series
    return float(np.corrcoef(a, b)[0, 1])
