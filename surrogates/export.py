"""Exporting a trained surrogate as one ONNX graph with a JSON sidecar.

The graph is :class:`~surrogates.nets.PhysicalSurrogate`: FFNN + decoder with
the parameter scaling and the backbone un-scaling inside, so it takes physical
parameters ``(batch, n_params)`` and returns physical backbones ``(batch,
n_levels, n_channels)``, float32, with a dynamic batch axis. It is exported with
``torch.onnx.export``'s dynamo exporter (torch's default). The sidecar carries
everything a user needs to trust and use the graph (see
:mod:`surrogates.runtime`, which reads the pair back): the grid, the scalers,
the network sizes, the data counts (which measured curves were training data)
and the test figures beside the baselines.
"""

from __future__ import annotations

import json
import sys
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import torch

from identification.artifacts import (
    atomic_write_bytes,
    atomic_write_text,
    sha256_bytes,
    sha256_json,
    versions,
)
from surrogates.runtime import (
    FORMAT,
    FORMAT_VERSION,
    MASK_CHANNEL,
    MODEL_FILE,
    SIDECAR_FILE,
    SurrogateRuntime,
)
from surrogates.train import Surrogate

__all__ = ["export_surrogate", "onnx_bytes"]

INPUT_NAME = "parameters"
OUTPUT_NAME = "backbones"


def onnx_bytes(surrogate: Surrogate, opset: int | None = None) -> bytes:
    """The surrogate's :class:`~surrogates.nets.PhysicalSurrogate` as a serialised ONNX graph."""
    model = surrogate.model.cpu().eval()
    # A batch of 2: the exporter specialises an axis whose example size is 1.
    example = torch.as_tensor(
        np.repeat(surrogate.spec.bounds.mean(axis=1)[None], 2, axis=0), dtype=torch.float32
    )
    program = torch.onnx.export(
        model,
        (example,),
        input_names=[INPUT_NAME],
        output_names=[OUTPUT_NAME],
        dynamic_shapes=({0: torch.export.Dim("batch")},),
        opset_version=opset,
        dynamo=True,
        verbose=False,
    )
    return program.model_proto.SerializeToString()


def export_surrogate(
    surrogate: Surrogate,
    folder: str | Path,
    *,
    opset: int | None = None,
    check_tolerance: float = 1e-5,
) -> Path:
    """Write ``folder/surrogate.onnx`` and its sidecar ``folder/surrogate.json``.

    Both files are written atomically, the graph first: a crash in between
    leaves a sidecar whose hash no longer matches, which the runtime refuses.
    After writing, the exported pair is loaded back with
    :class:`~surrogates.runtime.SurrogateRuntime` and must reproduce the torch
    model at the box's low and high corners and its centre to ``check_tolerance``
    (relative to each channel's spread), else ValueError.

    Returns
    -------
    Path
        The folder.
    """
    folder = Path(folder)
    graph = onnx_bytes(surrogate, opset)
    opset_used = next(
        o.version for o in onnx.load_from_string(graph).opset_import if o.domain in ("", "ai.onnx")
    )
    sidecar = _sidecar(surrogate, graph, opset_used)
    # The graph hash covers the network; this one covers the sidecar's own fields
    # (box, grid, scalers), so that widening the box in the JSON is noticed.
    sidecar["content_sha256"] = sha256_json(sidecar)
    atomic_write_bytes(folder / MODEL_FILE, graph)
    atomic_write_text(folder / SIDECAR_FILE, json.dumps(sidecar, indent=2) + "\n")
    _check_round_trip(surrogate, SurrogateRuntime.load(folder), check_tolerance)
    return folder


def _sidecar(surrogate: Surrogate, graph: bytes, opset: int) -> dict[str, Any]:
    spec = surrogate.spec
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        **spec.to_dict(),
        "onnx": {
            "file": MODEL_FILE,
            "sha256": sha256_bytes(graph),
            "opset": opset,
            "input": {"name": INPUT_NAME, "shape": ["batch", spec.n_params], "dtype": "float32"},
            "output": {
                "name": OUTPUT_NAME,
                "shape": ["batch", spec.n_levels, spec.n_channels],
                "dtype": "float32",
                "layout": "levels x channels",
            },
        },
        # Folded into the graph already; recorded so the mapping can be audited.
        "scalers": {
            "input": {
                "kind": "min-max to [0, 1] over bounds",
                "low": spec.bounds[:, 0].tolist(),
                "high": spec.bounds[:, 1].tolist(),
            },
            "head": {
                "degree": surrogate.model.head_degree,
                # Lower at grid points with too few training rows (grid points x channels).
                "carried_degree": None
                if surrogate.head_carried_degree is None
                else surrogate.head_carried_degree.tolist(),
                "kind": "per (level, channel) polynomial in the box-scaled parameters, added "
                "in physical units; the networks learn its residual (degree 0: no head)",
            },
            "output": {
                "kind": f"standardise per {surrogate.config.output_scaling}"
                + (" the head's residual" if surrogate.model.head_degree else ""),
                "offset": surrogate.output_offset.tolist(),
                "scale": surrogate.output_scale.tolist(),
            },
        },
        "training": {
            "n_train": surrogate.n_train,
            "n_validation": surrogate.n_validation,
            "seed": surrogate.config.seed,
            "config": surrogate.config.to_dict(),
            "epochs": {stage: len(records) for stage, records in surrogate.history.items()},
            "best_epochs": surrogate.best_epochs,
            "train_seconds": surrogate.train_seconds,
            "network": surrogate.sizes,
            "data": surrogate.data,
            # From the split that stopped training early: not an independent figure.
            "validation_metrics": surrogate.metrics,
        },
        # The independent figures: the test split, beside the baselines (None when the
        # surrogate was trained on bare arrays, without a test split).
        "test": surrogate.test_report,
        # torch's own version string names its build (e.g. +cu132); metadata's does not.
        "versions": {
            **versions("pm-joint", "onnx"),
            "torch": torch.__version__,
            "platform": sys.platform,
        },
    }


def _check_round_trip(surrogate: Surrogate, runtime: SurrogateRuntime, tolerance: float) -> None:
    bounds = surrogate.spec.bounds
    probe = np.vstack([bounds.T, bounds.mean(axis=1)])
    expected, actual = surrogate.predict(probe), runtime.predict(probe)
    spread = np.ptp(expected, axis=(0, 1)) + np.abs(expected).max(axis=(0, 1)) * 1e-6
    # A probability's spread is its range, 1: at three probes a confident mask may vary by
    # 1e-3 only, and float32 rounding (~1e-7) would then read as a mismatch.
    probability = np.array([c == MASK_CHANNEL for c in surrogate.spec.channels])
    spread[probability] = 1.0
    error = np.abs(actual - expected).max(axis=(0, 1)) / spread
    if np.any(error > tolerance):
        raise ValueError(
            f"{runtime.source}: the exported graph differs from the torch model by "
            f"{error.max():.3g} of a channel's spread (tolerance {tolerance})"
        )
