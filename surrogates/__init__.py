"""Learned forward models: backbone surrogates (torch to train, onnxruntime to run).

The runtime names are imported eagerly and need no torch; the training and
export names load torch on first access, so that ``import surrogates`` stays
light in sampler worker processes.
"""

from __future__ import annotations

import importlib
from typing import Any

from surrogates.runtime import CHANNEL_UNITS, SurrogateRuntime, SurrogateSpec

__all__ = [
    "CHANNEL_UNITS",
    "NetConfig",
    "Surrogate",
    "SurrogateRuntime",
    "SurrogateSpec",
    "TrainingConfig",
    "backbone_metrics",
    "export_surrogate",
    "table5_study",
    "train_surrogate",
]

_LAZY = {
    "NetConfig": "surrogates.nets",
    "Surrogate": "surrogates.train",
    "TrainingConfig": "surrogates.train",
    "train_surrogate": "surrogates.train",
    "export_surrogate": "surrogates.export",
    "backbone_metrics": "surrogates.evaluate",
    "table5_study": "surrogates.evaluate",
}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'surrogates' has no attribute {name!r}")
