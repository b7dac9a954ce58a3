"""The ONNX backbone surrogate as a forward model: :class:`SurrogateOp` and its pytensor twin.

Points are the surrogate's grid: its excitation levels (m/s²), or its response
amplitudes (m; ``"amplitude_grid"``, :mod:`surrogates.runtime`). The Op runs the
exported network on onnxruntime; its gradient is the backpropagation through
:func:`surrogate_graph`, the same network rebuilt in pytensor from the ONNX
initializers. On the amplitude grid the value channels are finite at every
point, also where the model has no backbone: that is the mask channel's to
say (:meth:`SurrogateOp.has_backbone`), so the likelihood sees a probability
rather than a NaN there.
"""

from __future__ import annotations

import itertools
import os
import weakref
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import pytensor
import pytensor.tensor as pt
from onnx import numpy_helper
from pytensor.gradient import pullback

from pm_joint.forward.base import BACKBONE_COLUMNS, BackboneOp
from surrogates.runtime import MASK_CHANNEL, SurrogateRuntime

__all__ = ["SurrogateGraph", "SurrogateOp", "surrogate_channel_graph", "surrogate_graph"]


class SurrogateOp(BackboneOp):
    """The ONNX backbone surrogate as a pytensor Op.

    Points are the surrogate's excitation levels (m/s²), increasing, or its
    response amplitudes in m (the amplitude column is then the grid itself, and
    :meth:`has_backbone` gives the mask channel's probabilities). Parameter
    vectors outside the surrogate's training box, or not finite, give NaN rows
    (counted in :attr:`n_failed`) instead of an error, so a sampler that
    proposes one mid-chain just rejects it. The gradient is the exact
    backpropagation through :func:`surrogate_graph` (float64; the forward pass
    runs in float32 on onnxruntime, so values and gradient agree to ~1e-6).
    Picklable (the runtime keeps the ONNX bytes and rebuilds its session), for
    multi-process chains.

    Parameters
    ----------
    runtime
        A :class:`~surrogates.runtime.SurrogateRuntime` or the folder to load one from.
    names
        Order of θ; must be a permutation of the runtime's parameter names
        (default: the runtime's order).
    """

    def __init__(self, runtime: SurrogateRuntime | str | os.PathLike, names=None) -> None:
        super().__init__()
        if isinstance(runtime, str | os.PathLike):
            runtime = SurrogateRuntime.load(Path(runtime))
        self.runtime = runtime
        expected = tuple(runtime.parameter_names)
        names = expected if names is None else tuple(names)
        missing = [n for n in expected if n not in names]
        unexpected = [n for n in names if n not in expected]
        if missing or unexpected or len(names) != len(expected):
            raise ValueError(
                f"names {list(names)} do not match the surrogate's parameters {list(expected)}: "
                f"missing {missing}, not in the surrogate {unexpected}"
            )
        self.parameter_names = names
        self.n_points = runtime.spec.n_levels
        #: The excitation levels (m/s²) of an excitation-level surrogate, else None.
        self.levels = runtime.levels
        #: The response amplitudes (m) of an amplitude-grid surrogate, else None.
        self.amplitudes_m = runtime.amplitudes_m
        #: Columns of θ in the runtime's parameter order.
        self._order = np.array([names.index(n) for n in expected])

    def _backbones(self, flat: np.ndarray) -> np.ndarray:
        spec = self.runtime.spec
        parameters = flat[:, self._order]
        usable = np.isfinite(parameters).all(axis=1)
        usable[usable] = ~spec.outside_box(parameters[usable])
        out = np.full((flat.shape[0], self.n_points, 3), np.nan)
        if self.amplitudes_m is not None:
            out[usable, :, 0] = self.amplitudes_m
        if usable.any():
            predicted = self.runtime.predict(parameters[usable], extrapolate="allow")
            for channel, values in zip(spec.channels, np.moveaxis(predicted, -1, 0), strict=True):
                if channel in BACKBONE_COLUMNS:
                    out[usable, :, BACKBONE_COLUMNS.index(channel)] = values
        return out

    def has_backbone(self, theta: Any) -> pt.TensorVariable:
        """Probability that the model has a backbone point at each grid amplitude.

        ``(..., n_points)``, a pytensor graph (:func:`surrogate_channel_graph`, so
        it is differentiable) of the mask channel of an amplitude-grid surrogate.

        Raises
        ------
        ValueError
            For a surrogate without the mask channel (excitation levels).
        """
        theta = pt.as_tensor_variable(theta)
        return surrogate_channel_graph(self.runtime, theta[..., self._order], MASK_CHANNEL)

    def pullback(self, inputs, outputs, cotangents):
        (theta,) = inputs
        graph = surrogate_graph(self.runtime, theta[..., self._order])
        return [pullback(graph, theta, cotangents[0])]

    def __repr__(self) -> str:
        return f"SurrogateOp({self.runtime!r}, names={list(self.parameter_names)})"


class SurrogateGraph:
    """The surrogate's network as a native pytensor graph, with the forward-model interface.

    Not a pytensor ``Op`` (as :class:`~pm_joint.forward.harmonic.HarmonicBalanceGraph`):
    calling it builds :func:`surrogate_graph`, so a gradient sampler compiles
    the network with the rest of the model (nutpie's numba backend, PyMC's
    NUTS) instead of calling onnxruntime through a Python Op once per
    evaluation. Values equal :class:`SurrogateOp`'s up to onnxruntime's float32
    rounding. There is no box check: the caller's priors keep θ inside the
    training box (:func:`~pm_joint.inference.build_model` checks its bounds
    against it).

    Parameters
    ----------
    runtime, names
        As :class:`SurrogateOp`, which :attr:`op` is (the onnxruntime twin, for
        values outside a graph).
    """

    def __init__(self, runtime: SurrogateRuntime | str | os.PathLike, names=None) -> None:
        self.op = SurrogateOp(runtime, names)
        self.runtime = self.op.runtime
        self.parameter_names = self.op.parameter_names
        self.n_points = self.op.n_points
        self.levels = self.op.levels
        self.amplitudes_m = self.op.amplitudes_m

    def __call__(self, theta: Any) -> pt.TensorVariable:
        theta = pt.as_tensor_variable(theta)
        return surrogate_graph(self.runtime, theta[..., self.op._order])

    def has_backbone(self, theta: Any) -> pt.TensorVariable:
        """As :meth:`SurrogateOp.has_backbone` (already a native graph)."""
        return self.op.has_backbone(theta)

    def __repr__(self) -> str:
        return f"SurrogateGraph({self.runtime!r}, names={list(self.parameter_names)})"


# The ONNX surrogate rebuilt in pytensor from its initializers.


def surrogate_graph(runtime: SurrogateRuntime, theta: Any) -> pt.TensorVariable:
    """The surrogate's ONNX graph as a float64 pytensor graph, in the common layout.

    The ONNX nodes are translated one by one (the exported surrogate uses
    Gemm/MatMul, Elu, Relu, Reshape, 1-D Conv, Transpose, Sigmoid and elementwise
    arithmetic), with the weights read from the initializers, so pytensor can
    backpropagate through the network. Values equal onnxruntime's up to its
    float32 rounding.

    Parameters
    ----------
    runtime
        The surrogate.
    theta
        ``(..., n_params)`` in the runtime's parameter order.

    Returns
    -------
    TensorVariable
        ``(..., n_levels, 3)``, columns :data:`BACKBONE_COLUMNS`, NaN for a
        channel the surrogate does not predict; on the amplitude grid the
        amplitude column is the grid. No box check here (that is
        :class:`SurrogateOp`'s job).
    """
    spec = runtime.spec
    theta = pt.as_tensor_variable(theta).astype("float64")
    flat = _network_graph(runtime, theta)
    columns = []
    for c in BACKBONE_COLUMNS:
        if c in spec.channels:
            columns.append(flat[..., spec.channels.index(c)])
        elif c == "amplitude_m" and runtime.amplitudes_m is not None:
            columns.append(pt.zeros_like(flat[..., 0]) + runtime.amplitudes_m)
        else:
            columns.append(pt.full_like(flat[..., 0], np.nan))
    backbone = pt.stack(columns, axis=-1)
    return backbone.reshape((*[theta.shape[i] for i in range(theta.ndim - 1)], spec.n_levels, 3))


def surrogate_channel_graph(
    runtime: SurrogateRuntime, theta: Any, channel: str
) -> pt.TensorVariable:
    """One channel of the surrogate (e.g. the mask), ``(..., n_levels)``, as a pytensor graph.

    ``theta`` is ``(..., n_params)`` in the runtime's parameter order.
    """
    spec = runtime.spec
    if channel not in spec.channels:
        raise ValueError(f"the surrogate has no channel {channel!r}; it has {list(spec.channels)}")
    theta = pt.as_tensor_variable(theta).astype("float64")
    values = _network_graph(runtime, theta)[..., spec.channels.index(channel)]
    return values.reshape((*[theta.shape[i] for i in range(theta.ndim - 1)], spec.n_levels))


def _network_graph(runtime: SurrogateRuntime, theta: pt.TensorVariable) -> pt.TensorVariable:
    """The ONNX nodes translated: ``(n, n_params)`` → ``(n, n_levels, n_channels)`` float64."""
    proto = onnx.load_from_string(runtime.model_bytes)
    values: dict[str, Any] = {
        init.name: numpy_helper.to_array(init) for init in proto.graph.initializer
    }
    values.update(_shared_weights(runtime, values))
    (graph_input,) = [i.name for i in proto.graph.input if i.name not in values]
    values[graph_input] = theta.reshape((-1, runtime.spec.n_params))
    for node in proto.graph.node:
        translate = _ONNX_NODES.get(node.op_type)
        if translate is None:
            raise ValueError(
                f"{runtime.source}: ONNX node {node.name!r} of type {node.op_type} has no "
                f"pytensor translation (supported: {', '.join(sorted(_ONNX_NODES))})"
            )
        attributes = {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}
        inputs = [values[name] if name else None for name in node.input]
        outputs = translate(inputs, attributes)
        values.update(zip(node.output, outputs, strict=True))
    return pt.as_tensor_variable(values[proto.graph.output[0].name]).astype("float64")


#: The network's weights as shared variables, one set per runtime (see _shared_weights).
_WEIGHTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Numbers the runtimes' weight sets: the numba backend writes a compiled function's inputs
#: by their names, so two surrogates in one model (an N-mode model's, one per mode) must not
#: share them.
_RUNTIME_NUMBERS = itertools.count()


def _shared_weights(runtime: SurrogateRuntime, initializers: dict) -> dict[str, Any]:
    """The floating-point initializers as float64 shared variables, cached per runtime.

    Shared, not constants: a compiled function then takes the weights as inputs
    instead of embedding tens of thousands of numbers in its code (numba, as
    nutpie uses it, compiles such constants very slowly). Cached: the value and
    mask graphs of one runtime use the same variables, so pytensor merges the
    network they both evaluate into one.
    """
    if runtime not in _WEIGHTS:
        number = next(_RUNTIME_NUMBERS)
        _WEIGHTS[runtime] = {
            name: pytensor.shared(
                value.astype(np.float64), name=f"surrogate{number}.{name}", shape=value.shape
            )
            for name, value in initializers.items()
            if np.issubdtype(value.dtype, np.floating) and value.ndim > 0
        }
    return _WEIGHTS[runtime]


def _as_float64(value: Any) -> Any:
    """Initializers become float64 constants; pytensor variables pass through."""
    if isinstance(value, np.ndarray) and np.issubdtype(value.dtype, np.floating):
        return value.astype(np.float64)
    return value


def _binary(function: Callable) -> Callable:
    return lambda inputs, _: [function(_as_float64(inputs[0]), _as_float64(inputs[1]))]


def _gemm(inputs, attributes):
    a, b = (_as_float64(x) for x in inputs[:2])
    a = a.T if attributes.get("transA", 0) else a
    b = b.T if attributes.get("transB", 0) else b
    out = attributes.get("alpha", 1.0) * pt.dot(a, b)
    if len(inputs) > 2 and inputs[2] is not None:
        out = out + attributes.get("beta", 1.0) * _as_float64(inputs[2])
    return [out]


def _elu(inputs, attributes):
    x = inputs[0]
    # expm1 of the clipped argument: the unused branch must not overflow (NaN gradients).
    return [pt.switch(x > 0, x, attributes.get("alpha", 1.0) * pt.expm1(pt.minimum(x, 0.0)))]


def _reshape(inputs, attributes):
    shape = np.asarray(inputs[1])
    if not isinstance(inputs[1], np.ndarray) or np.any(shape == 0):
        raise ValueError(
            "ONNX Reshape: only constant target shapes without 0 entries are supported"
        )
    return [pt.as_tensor_variable(inputs[0]).reshape(tuple(int(s) for s in shape))]


def _conv1d(inputs, attributes):
    """1-D Conv (group 1, stride 1) as a sum of ``kernel_size`` matrix products."""
    x = pt.as_tensor_variable(inputs[0])
    weights = _as_float64(inputs[1])
    if weights.ndim != 3 or attributes.get("group", 1) != 1:
        raise ValueError("ONNX Conv: only 1-D convolutions with group = 1 are supported")
    if any(s != 1 for s in attributes.get("strides", [1])):
        raise ValueError("ONNX Conv: only stride 1 is supported")
    if attributes.get("auto_pad", b"NOTSET") not in (b"NOTSET", "NOTSET"):
        raise ValueError("ONNX Conv: auto_pad is not supported; explicit pads only")
    (dilation,) = attributes.get("dilations", [1])
    begin, end = attributes.get("pads", [0, 0])
    kernel = weights.type.shape[2] if hasattr(weights, "type") else weights.shape[2]
    padded = pt.pad(x, ((0, 0), (0, 0), (begin, end)))
    length = x.shape[2] + begin + end - dilation * (kernel - 1)
    out = sum(
        pt.tensordot(
            padded[:, :, k * dilation : k * dilation + length], weights[:, :, k], [[1], [1]]
        )
        for k in range(kernel)
    ).transpose(0, 2, 1)
    if len(inputs) > 2 and inputs[2] is not None:
        out = out + _as_float64(inputs[2])[None, :, None]
    return [out]


_ONNX_NODES: dict[str, Callable[[list, dict], list]] = {
    "Add": _binary(lambda a, b: a + b),
    "Sub": _binary(lambda a, b: a - b),
    "Mul": _binary(lambda a, b: a * b),
    "Div": _binary(lambda a, b: a / b),
    "MatMul": _binary(pt.matmul),
    "Gemm": _gemm,
    "Relu": lambda inputs, _: [pt.maximum(inputs[0], 0.0)],
    "Elu": _elu,
    "Tanh": lambda inputs, _: [pt.tanh(inputs[0])],
    "Sigmoid": lambda inputs, _: [pt.sigmoid(inputs[0])],
    "Identity": lambda inputs, _: [inputs[0]],
    "Constant": lambda _, attributes: [numpy_helper.to_array(attributes["value"])],
    "Reshape": _reshape,
    "Transpose": lambda inputs, attributes: [
        pt.as_tensor_variable(inputs[0]).transpose(*attributes["perm"])
    ],
    "Conv": _conv1d,
}
