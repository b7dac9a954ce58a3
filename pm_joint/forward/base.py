"""Plumbing shared by the forward models: the backbone layout and the Python-Op base.

Every forward model maps a parameter vector θ of shape ``(..., n_params)``
(leading batch axes allowed) to a backbone tensor of shape ``(..., n_points, 3)``
with the columns :data:`BACKBONE_COLUMNS`. NaN marks a channel the model does
not give and a parameter vector the model cannot evaluate.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pytensor.tensor as pt
from pytensor.graph.basic import Apply
from pytensor.graph.op import Op
from pytensor.graph.replace import _vectorize_node

from identification.model import JointModel

__all__ = ["BACKBONE_COLUMNS", "BackboneOp", "checked_names"]

#: Columns of the common backbone layout, ``(..., n_points, 3)``.
BACKBONE_COLUMNS = ("amplitude_m", "frequency_hz", "damping_ratio")


def checked_names(model: JointModel, names: Sequence[str] | None) -> tuple[str, ...]:
    """``names`` (default: all of the model's) validated against the model."""
    names = tuple(model.parameter_names if names is None else names)
    unknown = [n for n in names if n not in model.parameter_names]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the model has {model.parameter_names}")
    if not names or len(set(names)) != len(names):
        raise ValueError(f"parameter names must be non-empty and unique: {list(names)}")
    return names


class BackboneOp(Op):
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


_vectorize_node.register(BackboneOp)(_vectorize_natively)
