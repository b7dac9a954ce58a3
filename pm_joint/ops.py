"""Forward models as pytensor Ops: ONNX surrogate, harmonic balance, PLL simulator.

Every forward model maps a parameter vector θ of shape ``(..., n_params)``
(leading batch axes allowed) to a backbone tensor of shape ``(..., n_points, 3)``
with the columns :data:`BACKBONE_COLUMNS`: amplitude (m), frequency (Hz),
damping ratio. NaN marks a channel the model does not give (a surrogate trained
without damping, a PLL level that did not lock) and a parameter vector the
model cannot evaluate: the forward models never raise on a bad θ mid-chain,
the likelihood turns NaN into ``logp = -inf``. Each one exposes
``parameter_names`` (the order of θ) and ``n_points``.

:class:`SurrogateOp`
    The exported ONNX surrogate on onnxruntime; points are its excitation
    levels. Gradient: backpropagation through :func:`surrogate_graph`, the
    same network rebuilt in pytensor from the ONNX initializers.
:class:`HarmonicBalanceOp`
    Builds :func:`harmonic_backbone_graph`, the single-harmonic backbone as a
    native pytensor graph (pytensor differentiates it; NUTS works); points are
    an amplitude grid.
:class:`PLLOp`
    The time-domain PLL simulator as a black box (no gradient); points are its
    excitation levels.

:func:`forward_model` picks one by name, so one PyMC model switches between
them with one argument.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import onnx
import pytensor.tensor as pt
from numpy.typing import ArrayLike
from onnx import numpy_helper
from pytensor.gradient import pullback
from pytensor.graph.basic import Apply
from pytensor.graph.op import Op
from pytensor.graph.replace import _vectorize_node
from scipy import special

from identification.analytical.pll import PLLConfig, pll_backbones
from identification.checks import positive_vector
from identification.effects import CATALOGUE
from identification.model import JointModel
from surrogates.runtime import SurrogateRuntime

__all__ = [
    "BACKBONE_COLUMNS",
    "FORWARD_KINDS",
    "HarmonicBalanceOp",
    "PLLOp",
    "SurrogateOp",
    "dawson",
    "describing_graph",
    "forward_model",
    "harmonic_backbone_graph",
    "surrogate_graph",
]

#: Columns of the common backbone layout, ``(..., n_points, 3)``.
BACKBONE_COLUMNS = ("amplitude_m", "frequency_hz", "damping_ratio")
#: Names :func:`forward_model` accepts.
FORWARD_KINDS = ("surrogate", "harmonic", "pll")


def _checked_names(model: JointModel, names: Sequence[str] | None) -> tuple[str, ...]:
    """``names`` (default: all of the model's) validated against the model."""
    names = tuple(model.parameter_names if names is None else names)
    unknown = [n for n in names if n not in model.parameter_names]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the model has {model.parameter_names}")
    if not names or len(set(names)) != len(names):
        raise ValueError(f"parameter names must be non-empty and unique: {list(names)}")
    return names


# --------------------------------------------------------------------------
# Python Ops: θ (..., n_params) → backbone (..., n_points, 3), batch in perform.


class _BackboneOp(Op):
    """Shared plumbing of the Python forward Ops.

    Subclasses set ``parameter_names`` and ``n_points`` and implement
    ``_backbones(flat) -> (n, n_points, 3)`` on a ``(n, n_params)`` float64
    array. Rows that cannot be evaluated are NaN and counted in ``n_failed``
    (per process: each sampler process has its own copy of the Op). The last
    three single-vector results are remembered: Metropolis-type samplers score
    every proposal against the current point, which is one of them.
    """

    parameter_names: tuple[str, ...]
    n_points: int

    def __init__(self) -> None:
        self.n_evaluated = 0
        self.n_failed = 0
        self._recent: dict[bytes, np.ndarray] = {}

    @property
    def n_params(self) -> int:
        return len(self.parameter_names)

    def make_node(self, theta: Any) -> Apply:
        theta = pt.as_tensor_variable(theta)
        if theta.ndim == 0:
            raise ValueError(
                f"{type(self).__name__}: θ must have a last axis of {self.n_params} parameters "
                f"({', '.join(self.parameter_names)}), got a scalar"
            )
        width = theta.type.shape[-1]
        if width is not None and width != self.n_params:
            raise ValueError(
                f"{type(self).__name__}: θ has {width} parameters on its last axis, expected "
                f"{self.n_params} ({', '.join(self.parameter_names)})"
            )
        theta = pt.cast(theta, "float64")
        shape = (*theta.type.shape[:-1], self.n_points, len(BACKBONE_COLUMNS))
        return Apply(self, [theta], [pt.tensor(dtype="float64", shape=shape)])

    def perform(self, node: Apply, inputs: Sequence[np.ndarray], output_storage: list) -> None:
        (theta,) = inputs
        if theta.shape[-1] != self.n_params:
            raise ValueError(
                f"{type(self).__name__}: θ has {theta.shape[-1]} parameters on its last axis, "
                f"expected {self.n_params}"
            )
        flat = theta.reshape(-1, self.n_params)
        key = flat.tobytes() if flat.shape[0] == 1 else None
        out = self._recent.pop(key, None)
        if out is None:
            out = self._backbones(flat)
            self.n_evaluated += flat.shape[0]
            self.n_failed += int(np.isnan(out[..., 1]).all(axis=-1).sum())
        if key is not None:  # most recent last; three cover either evaluation order
            self._recent = {**dict(list(self._recent.items())[-2:]), key: out}
        # A copy: downstream Ops may work in place on their inputs.
        output_storage[0][0] = out.reshape(*theta.shape[:-1], self.n_points, 3).copy()

    def infer_shape(self, node: Apply, input_shapes: Sequence[tuple]) -> list[tuple]:
        return [(*input_shapes[0][:-1], self.n_points, len(BACKBONE_COLUMNS))]

    def _backbones(self, flat: np.ndarray) -> np.ndarray:
        raise NotImplementedError


def _vectorize_natively(op: Op, node: Apply, batched: Any) -> Apply:
    # Leading batch axes are native to these Ops: no Blockwise loop needed.
    return op.make_node(batched)


_vectorize_node.register(_BackboneOp)(_vectorize_natively)


class SurrogateOp(_BackboneOp):
    """The ONNX backbone surrogate as a pytensor Op.

    Points are the surrogate's excitation levels, in level order. Parameter
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
        self.levels = runtime.levels
        #: Columns of θ in the runtime's parameter order.
        self._order = np.array([names.index(n) for n in expected])

    def _backbones(self, flat: np.ndarray) -> np.ndarray:
        spec = self.runtime.spec
        parameters = flat[:, self._order]
        usable = np.isfinite(parameters).all(axis=1)
        usable[usable] = ~spec.outside_box(parameters[usable])
        out = np.full((flat.shape[0], self.n_points, 3), np.nan)
        if usable.any():
            predicted = self.runtime.predict(parameters[usable], extrapolate="allow")
            for channel, values in zip(spec.channels, np.moveaxis(predicted, -1, 0), strict=True):
                out[usable, :, BACKBONE_COLUMNS.index(channel)] = values
        return out

    def pullback(self, inputs, outputs, cotangents):
        (theta,) = inputs
        graph = surrogate_graph(self.runtime, theta[..., self._order])
        return [pullback(graph, theta, cotangents[0])]

    def __repr__(self) -> str:
        return f"SurrogateOp({self.runtime!r}, names={list(self.parameter_names)})"


class PLLOp(_BackboneOp):
    """The PLL phase-resonance simulator as a black-box pytensor Op (no gradient).

    Points are the excitation levels, in test order. Levels that did not lock
    are NaN; parameter vectors the simulator cannot run (non-finite values,
    shape parameters ≤ 0, a model too stiff for the sub-step limit, a
    diverging run) give NaN rows counted in :attr:`n_failed`, never an error.

    Parameters
    ----------
    model
        Template model; the named parameters are overridden by θ.
    names
        Order of θ, names of :attr:`JointModel.parameter_names` (None: all).
    levels
        Base-acceleration amplitudes of the holds (m/s²).
    config
        Test settings (:class:`~identification.analytical.pll.PLLConfig`).
    executor
        ``concurrent.futures``-style executor for large batches (e.g. a
        ``dask.distributed`` Client); default: serially in the calling process,
        which suits one sampler chain per core and forked chains. An executor
        that cannot be pickled keeps the Op from multi-process sampling.
    """

    def __init__(
        self,
        model: JointModel,
        names: Sequence[str] | None,
        levels: ArrayLike,
        config: PLLConfig | None = None,
        executor: Any = None,
    ) -> None:
        super().__init__()
        self.model = model
        self.parameter_names = _checked_names(model, names)
        self.levels = positive_vector(levels, "levels")
        self.n_points = self.levels.size
        self.config = PLLConfig() if config is None else config
        self.executor = executor
        self._is_shape = np.array(["." in n for n in self.parameter_names])

    def _backbones(self, flat: np.ndarray) -> np.ndarray:
        out = np.full((flat.shape[0], self.n_points, 3), np.nan)
        usable = np.isfinite(flat).all(axis=1) & (flat[:, self._is_shape] > 0).all(axis=1)
        rows = np.flatnonzero(usable)
        if rows.size == 0:
            return out
        try:
            out[rows] = self._simulate(flat[rows])
        except ValueError:
            # One set the simulator refuses (e.g. too stiff) must not cost the others.
            for row in rows:
                with contextlib.suppress(ValueError):
                    out[row] = self._simulate(flat[row : row + 1])[0]
        return out

    def _simulate(self, parameters: np.ndarray) -> np.ndarray:
        executor = self.executor or _SerialExecutor()
        result = pll_backbones(
            self.model, self.levels, parameters, self.parameter_names, self.config,
            executor=executor, chunk_size=None if self.executor else len(parameters),
            progress=False,
        )  # fmt: skip
        backbone = np.stack([result.amplitude_m, result.frequency_hz, result.damping_ratio], -1)
        backbone[~result.locked] = np.nan
        return backbone

    def __repr__(self) -> str:
        return (
            f"PLLOp({self.model!r}, names={list(self.parameter_names)}, "
            f"levels={self.levels.tolist()})"
        )


class _SerialExecutor:
    """``submit`` that runs the task at once: serial batches through ``pll_backbones``.

    Without an executor ``pll_backbones`` runs numba threads, which are not
    fork-safe in the sampler's worker processes.
    """

    def submit(self, fn: Callable, *args: Any) -> Future:
        future: Future = Future()
        future.set_result(fn(*args))
        return future


# --------------------------------------------------------------------------
# The ONNX surrogate rebuilt in pytensor from its initializers.


def surrogate_graph(runtime: SurrogateRuntime, theta: Any) -> pt.TensorVariable:
    """The surrogate's ONNX graph as a float64 pytensor graph, in the common layout.

    The ONNX nodes are translated one by one (the exported surrogate uses
    Gemm/MatMul, Elu, Relu, Reshape, 1-D Conv, Transpose and elementwise
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
        channel the surrogate does not predict. No box check here (that is
        :class:`SurrogateOp`'s job).
    """
    spec = runtime.spec
    theta = pt.as_tensor_variable(theta).astype("float64")
    proto = onnx.load_from_string(runtime.model_bytes)
    values: dict[str, Any] = {
        init.name: numpy_helper.to_array(init) for init in proto.graph.initializer
    }
    (graph_input,) = [i.name for i in proto.graph.input if i.name not in values]
    values[graph_input] = theta.reshape((-1, spec.n_params))
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
    flat = pt.as_tensor_variable(values[proto.graph.output[0].name]).astype("float64")
    columns = [
        flat[..., spec.channels.index(c)]
        if c in spec.channels
        else pt.full_like(flat[..., 0], np.nan)
        for c in BACKBONE_COLUMNS
    ]
    backbone = pt.stack(columns, axis=-1)
    return backbone.reshape((*[theta.shape[i] for i in range(theta.ndim - 1)], spec.n_levels, 3))


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
    kernel = weights.shape[2]
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
    "Identity": lambda inputs, _: [inputs[0]],
    "Constant": lambda _, attributes: [numpy_helper.to_array(attributes["value"])],
    "Reshape": _reshape,
    "Transpose": lambda inputs, attributes: [
        pt.as_tensor_variable(inputs[0]).transpose(*attributes["perm"])
    ],
    "Conv": _conv1d,
}


# --------------------------------------------------------------------------
# Harmonic balance as a native pytensor graph.


class _Dawson(Op):
    """Dawson's integral ``D(x)`` elementwise (scipy), with ``D'(x) = 1 − 2x D(x)``.

    pytensor has no Dawson function (nor erfi) and the Stribeck describing
    function needs it to machine precision, so scipy does the work.
    """

    __props__ = ()

    def make_node(self, x: Any) -> Apply:
        x = pt.as_tensor_variable(x).astype("float64")
        return Apply(self, [x], [x.type()])

    def perform(self, node, inputs, output_storage):
        output_storage[0][0] = np.asarray(special.dawsn(inputs[0]))

    def infer_shape(self, node, input_shapes):
        return [input_shapes[0]]

    def pullback(self, inputs, outputs, cotangents):
        (x,), (d,), (g,) = inputs, outputs, cotangents
        return [g * (1.0 - 2.0 * x * d)]


_vectorize_node.register(_Dawson)(_vectorize_natively)

#: Dawson's integral as a differentiable pytensor operation.
dawson = _Dawson()

#: Trapezoidal quadrature points of the tanh describing function (numpy tabulates
#: the same gain once; a graph keeps the sum, which is differentiable). The error
#: falls like exp(−400 x_s/a): below 1e-8 for amplitudes up to 20 x_s.
_QUADRATURE_POINTS = 256


@dataclass(frozen=True)
class _DescribingGraph:
    """Single-harmonic describing function of one effect, per unit coefficient.

    ``k_eq(a, ω) = stiffness(a) + stiffness_per_omega_squared(a) · ω²`` (affine
    in ω² for the whole catalogue, which makes the backbone frequency a closed
    form) and ``c_eq = damping(a, ω)``; None is zero. Shape parameters come as
    keywords named as in the catalogue.
    """

    stiffness: Callable | None = None
    stiffness_per_omega_squared: Callable | None = None
    damping: Callable | None = None


def _tanh_stiffness(a, x_s, **_):
    theta = 2.0 * np.pi * (np.arange(_QUADRATURE_POINTS) + 0.5) / _QUADRATURE_POINTS
    force = pt.tanh(a[..., None] * np.cos(theta) / x_s[..., None])
    return 2.0 * pt.mean(force * np.cos(theta), axis=-1) / a


def _stribeck_damping(a, omega, v_s, **_):
    b = a * omega / v_s
    return 4.0 * dawson(b) / (np.pi * a * omega * b)


def _slip_angle(a, k_t, F_s):
    """Masing loop (see ``effects._df_microslip``): slip amplitude, slipping mask, angle φ."""
    a_s = F_s / k_t
    slipping = a > a_s
    # Zero for sticking points keeps arccos away from ±1 there (finite gradients).
    phi = pt.arccos(pt.switch(slipping, 1.0 - 2.0 * a_s / a, 0.0))
    return a_s, slipping, phi


def _microslip_stiffness(a, k_t, F_s, **_):
    _, slipping, phi = _slip_angle(a, k_t, F_s)
    return pt.switch(slipping, k_t * (phi - 0.5 * pt.sin(2.0 * phi)) / np.pi, k_t)


def _microslip_damping(a, omega, k_t, F_s, **_):
    a_s, slipping, _ = _slip_angle(a, k_t, F_s)
    return pt.switch(slipping, 4.0 * F_s * (a - a_s) / (np.pi * a * a * omega), 0.0)


#: Every catalogue effect; even ones (x², ẋ², x·ẋ) have no single-harmonic signature.
_DESCRIBING_GRAPHS: dict[str, _DescribingGraph] = {
    "linear_stiffness": _DescribingGraph(stiffness=lambda a, **_: pt.ones_like(a)),
    "viscous_damping": _DescribingGraph(damping=lambda a, omega, **_: pt.ones_like(a)),
    "quadratic_stiffness": _DescribingGraph(),
    "cubic_stiffness": _DescribingGraph(stiffness=lambda a, **_: 0.75 * a**2),
    "abs_stiffness": _DescribingGraph(stiffness=lambda a, **_: 8.0 * a / (3.0 * np.pi)),
    "quadratic_damping": _DescribingGraph(
        damping=lambda a, omega, **_: 8.0 * a * omega / (3.0 * np.pi)
    ),
    "cubic_damping": _DescribingGraph(damping=lambda a, omega, **_: 0.75 * (a * omega) ** 2),
    "velocity_squared": _DescribingGraph(),
    "stiffness_damping_coupling": _DescribingGraph(),
    "displacement_velocity_squared": _DescribingGraph(
        stiffness_per_omega_squared=lambda a, **_: 0.25 * a**2
    ),
    "van_der_pol": _DescribingGraph(damping=lambda a, omega, **_: 0.25 * a**2),
    "coulomb_friction": _DescribingGraph(damping=lambda a, omega, **_: 4.0 / (np.pi * a * omega)),
    "stribeck_friction": _DescribingGraph(damping=_stribeck_damping),
    "tanh_saturation": _DescribingGraph(stiffness=_tanh_stiffness),
    "exponential": _DescribingGraph(stiffness=lambda a, x_s, **_: 2.0 * pt.i1(a / x_s) / a),
    "microslip": _DescribingGraph(stiffness=_microslip_stiffness, damping=_microslip_damping),
}


def describing_graph(
    effect: str, a: Any, omega: Any, **shape: Any
) -> tuple[pt.TensorVariable, pt.TensorVariable]:
    """``(k_eq, c_eq)`` of a catalogue effect per unit coefficient, as pytensor graphs.

    The pytensor mirror of :attr:`identification.effects.Effect.describing`;
    ``shape`` takes the effect's shape parameters (defaults from the catalogue).
    Outputs broadcast ``a`` against ``omega``.
    """
    if effect not in _DESCRIBING_GRAPHS:
        raise ValueError(f"unknown effect {effect!r}; the catalogue has: {', '.join(CATALOGUE)}")
    a, omega = (pt.as_tensor_variable(v).astype("float64") for v in (a, omega))
    shape = {
        n: pt.as_tensor_variable(shape.get(n, default)).astype("float64")
        for n, default in CATALOGUE[effect].defaults.items()
    }
    graph = _DESCRIBING_GRAPHS[effect]
    k_eq = c_eq = pt.zeros_like(a * omega)
    if graph.stiffness is not None:
        k_eq = k_eq + graph.stiffness(a, **shape)
    if graph.stiffness_per_omega_squared is not None:
        k_eq = k_eq + graph.stiffness_per_omega_squared(a, **shape) * omega**2
    if graph.damping is not None:
        c_eq = c_eq + graph.damping(a, omega, **shape)
    return k_eq, c_eq


def harmonic_backbone_graph(
    model: JointModel,
    theta: Any,
    names: Sequence[str] | None,
    amplitudes_m: ArrayLike,
) -> pt.TensorVariable:
    """Single-harmonic backbone of ``model`` as a native, differentiable pytensor graph.

    Mirrors ``identification.analytical.harmonic.backbone(..., method="single")``: with the
    describing functions summed over the model's terms (:func:`describing_graph`),
    ``ω² = Σ c_i k_eq,i(a, ω)`` and ``ζ = Σ c_i c_eq,i(a, ω) / (2ω)``. Every
    catalogue ``k_eq`` is affine in ω² (only ``x·ẋ²`` depends on ω), so
    ``ω² = K(a) / (1 − K₂(a))`` in closed form instead of the fixed-point
    iteration; where that iteration cannot settle (``K₂ ≥ 1``) or there is no
    positive stiffness, frequency and damping are NaN. (For ``K₂ ≤ −1`` the
    closed form still gives the backbone where the iteration gives up.)

    Parameters
    ----------
    model
        Template model; parameters not in ``names`` keep its values.
    theta
        ``(..., len(names))`` parameter values (a pytensor variable or array).
    names
        Order of θ, names of :attr:`JointModel.parameter_names` (None: all).
        Even terms (x², ẋ², x·ẋ) have no effect on a single-harmonic backbone,
        so their columns get zero gradient.
    amplitudes_m
        Fundamental amplitudes of the relative displacement (m), 1-D, > 0.

    Returns
    -------
    TensorVariable
        ``(..., n_amp, 3)``, columns :data:`BACKBONE_COLUMNS`; NaN frequency and
        damping where there is no backbone, and for whole rows whose shape
        parameters are not > 0.
    """
    names = _checked_names(model, names)
    amplitudes = positive_vector(amplitudes_m, "amplitudes_m")
    theta = pt.as_tensor_variable(theta).astype("float64")
    if theta.ndim == 0 or theta.type.shape[-1] not in (None, len(names)):
        raise ValueError(
            f"θ must have a last axis of {len(names)} parameters ({', '.join(names)}), "
            f"got shape {theta.type.shape}"
        )
    # Parameters get a trailing axis to broadcast against the amplitude grid.
    value = {
        name: theta[..., names.index(name), None] if name in names else pt.constant(v)
        for name, v in model.parameters.items()
    }
    a = pt.constant(amplitudes)
    positive_shapes = []
    terms = []
    for term in model.terms:
        shape = {}
        for shape_name, default in term.shape.items():
            key = f"{term.effect}.{shape_name}"
            if key not in value:  # v_reg, a numerical device the describing functions ignore
                shape[shape_name] = pt.constant(default)
                continue
            positive = value[key] > 0
            positive_shapes.append(positive)
            # A harmless stand-in keeps invalid rows finite; they become NaN below.
            shape[shape_name] = pt.switch(positive, value[key], default)
        terms.append((value[term.effect], term.effect, shape))

    # ω² = K + K₂ ω² (K₂ from x·ẋ² only): stiffness parts first, then damping at ω.
    stiffness = per_omega_squared = damping = pt.as_tensor_variable(0.0)
    for coefficient, effect, shape in terms:
        graph = _DESCRIBING_GRAPHS[effect]
        if graph.stiffness is not None:
            stiffness = stiffness + coefficient * graph.stiffness(a, **shape)
        if graph.stiffness_per_omega_squared is not None:
            k2 = graph.stiffness_per_omega_squared(a, **shape)
            per_omega_squared = per_omega_squared + coefficient * k2
    denominator = 1.0 - per_omega_squared
    ok = (denominator > 0) & (stiffness > 0)
    for positive in positive_shapes:
        ok = ok & positive
    # Stand-ins on failed points keep every intermediate finite (no invalid-value
    # warnings, no 0·NaN in the gradient); the outputs there are NaN below.
    omega = pt.sqrt(pt.switch(ok, stiffness / pt.switch(ok, denominator, 1.0), 1.0))
    for coefficient, effect, shape in terms:
        graph = _DESCRIBING_GRAPHS[effect]
        if graph.damping is not None:
            damping = damping + coefficient * graph.damping(a, omega, **shape)
    frequency_hz = pt.switch(ok, omega / (2.0 * np.pi), np.nan)
    damping_ratio = pt.switch(ok, damping / (2.0 * omega), np.nan)
    return pt.stack(pt.broadcast_arrays(a, frequency_hz, damping_ratio), axis=-1)


class HarmonicBalanceOp:
    """Single-harmonic backbone as a callable with the forward-Op interface.

    Not a pytensor ``Op``: calling it builds :func:`harmonic_backbone_graph`,
    a native graph that pytensor differentiates (so NUTS works) and compiles
    like any other. Points are the amplitude grid ``amplitudes_m``.

    Parameters
    ----------
    model
        Template model; parameters not in ``names`` keep its values.
    names
        Order of θ (None: all of the model's parameters).
    amplitudes_m
        Amplitude grid (m), 1-D, > 0.
    """

    def __init__(
        self, model: JointModel, names: Sequence[str] | None, amplitudes_m: ArrayLike
    ) -> None:
        self.model = model
        self.parameter_names = _checked_names(model, names)
        self.amplitudes_m = positive_vector(amplitudes_m, "amplitudes_m")
        self.n_points = self.amplitudes_m.size

    def __call__(self, theta: Any) -> pt.TensorVariable:
        return harmonic_backbone_graph(self.model, theta, self.parameter_names, self.amplitudes_m)

    def __repr__(self) -> str:
        return (
            f"HarmonicBalanceOp({self.model!r}, names={list(self.parameter_names)}, "
            f"n_points={self.n_points})"
        )


# --------------------------------------------------------------------------
# One switch for the PyMC model.


def forward_model(
    kind: str,
    model: JointModel | None,
    names: Sequence[str] | None = None,
    *,
    surrogate: SurrogateRuntime | str | os.PathLike | None = None,
    amplitudes_m: ArrayLike | None = None,
    levels: ArrayLike | None = None,
    config: PLLConfig | None = None,
) -> SurrogateOp | HarmonicBalanceOp | PLLOp:
    """The forward model called ``kind``, all with the same interface.

    Parameters
    ----------
    kind
        ``"surrogate"`` (needs ``surrogate``; ``model`` is not used),
        ``"harmonic"`` (needs ``amplitudes_m``) or ``"pll"`` (needs ``levels``;
        ``config`` optional).
    model
        The joint model (template of the named parameters).
    names
        Order of θ; default the surrogate's or the model's parameter names.

    Returns
    -------
    SurrogateOp | HarmonicBalanceOp | PLLOp
        Call it on θ ``(..., n_params)`` for a ``(..., n_points, 3)`` backbone.
    """
    needs = {"surrogate": "surrogate", "harmonic": "amplitudes_m", "pll": "levels"}
    if kind not in needs:
        raise ValueError(f"kind must be one of {FORWARD_KINDS}, got {kind!r}")
    given = {"surrogate": surrogate, "amplitudes_m": amplitudes_m, "levels": levels}
    if given[needs[kind]] is None:
        raise ValueError(f"forward model {kind!r} needs {needs[kind]}=")
    if kind == "surrogate":
        return SurrogateOp(surrogate, names)
    if not isinstance(model, JointModel):
        raise ValueError(f"forward model {kind!r} needs a JointModel, got {model!r}")
    if kind == "harmonic":
        return HarmonicBalanceOp(model, names, amplitudes_m)
    return PLLOp(model, names, levels, config)
