"""Learned forward models: backbone surrogates (torch to train, onnxruntime to run).

The runtime names are imported eagerly and need no torch; the dataset,
training and export names load their modules (and torch) on first access, so
that ``import surrogates`` stays light in sampler worker processes.
"""

from __future__ import annotations

import importlib
from typing import Any

from surrogates.runtime import CHANNEL_UNITS, SurrogateRuntime, SurrogateSpec

__all__ = [
    "CHANNEL_UNITS",
    "BackboneDataset",
    "NetConfig",
    "Surrogate",
    "SurrogateRuntime",
    "SurrogateSpec",
    "TrainingConfig",
    "add_measured",
    "backbone_metrics",
    "export_surrogate",
    "generate_dataset",
    "train_surrogate",
]

_LAZY = {
    "BackboneDataset": "surrogates.dataset",
    "add_measured": "surrogates.dataset",
    "generate_dataset": "surrogates.dataset",
    "NetConfig": "surrogates.nets",
    "Surrogate": "surrogates.train",
    "TrainingConfig": "surrogates.train",
    "train_surrogate": "surrogates.train",
    "export_surrogate": "surrogates.export",
    "backbone_metrics": "surrogates.evaluate",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'surrogates' has no attribute {name!r}")
