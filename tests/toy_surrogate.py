"""A toy exported surrogate for tests that need one without training: an ONNX
graph written by hand with :mod:`onnx.helper` and its sidecar.

The graph is linear: ``backbones = (parameters @ weights).reshape(n, levels, 2)``,
so that with ``parameters = (k, c)`` the amplitude at level ℓ is ``c · a_ℓ`` and
the frequency ``k · f_ℓ``: a backbone whose shape the test chooses.
"""

import json
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

from identification.artifacts import sha256_bytes
from surrogates.runtime import FORMAT, FORMAT_VERSION, MODEL_FILE, SIDECAR_FILE, SurrogateSpec


def linear_graph(weights: np.ndarray, n_levels: int, n_channels: int) -> bytes:
    """ONNX bytes of ``x (batch, n_params) → (x @ weights).reshape(batch, levels, channels)``."""
    n_params = weights.shape[0]
    graph = helper.make_graph(
        [
            helper.make_node("MatMul", ["parameters", "weights"], ["flat"]),
            helper.make_node("Reshape", ["flat", "shape"], ["backbones"]),
        ],
        "toy_surrogate",
        [helper.make_tensor_value_info("parameters", TensorProto.FLOAT, ["batch", n_params])],
        [
            helper.make_tensor_value_info(
                "backbones", TensorProto.FLOAT, ["batch", n_levels, n_channels]
            )
        ],
        initializer=[
            numpy_helper.from_array(weights.astype(np.float32), "weights"),
            numpy_helper.from_array(np.array([-1, n_levels, n_channels], np.int64), "shape"),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8  # read by every onnxruntime of the last years
    onnx.checker.check_model(model)
    return model.SerializeToString()


def amplitude_frequency_weights(amplitudes_m, frequencies_hz) -> np.ndarray:
    """Weights for parameters ``(k, c)``: amplitude ``c · a_ℓ``, frequency ``k · f_ℓ``."""
    n = len(amplitudes_m)
    weights = np.zeros((2, 2 * n))
    weights[1, 0::2] = amplitudes_m
    weights[0, 1::2] = frequencies_hz
    return weights


def write_surrogate(folder: Path, spec: SurrogateSpec, weights: np.ndarray) -> Path:
    """Write ``surrogate.onnx`` and a sidecar that describes it (with its hash)."""
    folder.mkdir(parents=True, exist_ok=True)
    graph = linear_graph(weights, spec.n_levels, spec.n_channels)
    (folder / MODEL_FILE).write_bytes(graph)
    sidecar = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        **spec.to_dict(),
        "onnx": {"file": MODEL_FILE, "sha256": sha256_bytes(graph)},
    }
    (folder / SIDECAR_FILE).write_text(json.dumps(sidecar, indent=2))
    return folder
