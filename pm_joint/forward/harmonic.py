"""Single-harmonic balance as a native, differentiable pytensor graph.

The describing functions are the catalogue's own (:mod:`identification.effects`:
each effect writes them once against an array namespace), evaluated with the
pytensor namespace, so this graph and the numpy backbone of
:mod:`identification.analytical.harmonic` come from the same source.
:class:`HarmonicBalanceGraph` gives it the forward-model interface; points are
an amplitude grid.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import pytensor.tensor as pt
from numpy.typing import ArrayLike

from identification.checks import positive_vector
from identification.effects import get_effect
from identification.effects.base import pytensor_namespace
from identification.model import JointModel
from pm_joint.forward.base import checked_names

__all__ = ["HarmonicBalanceGraph", "describing_graph", "harmonic_backbone_graph"]


def describing_graph(
    effect: str, a: Any, omega: Any, **shape: Any
) -> tuple[pt.TensorVariable, pt.TensorVariable]:
    """``(k_eq, c_eq)`` of a catalogue effect per unit coefficient, as pytensor graphs.

    The pytensor twin of :meth:`identification.effects.Effect.describing`, from
    the same describing-function parts; ``shape`` takes the effect's shape
    parameters (defaults from the catalogue). Outputs broadcast ``a`` against ``omega``.
    """
    spec = get_effect(effect)
    unknown = set(shape) - set(spec.shape)
    if unknown:
        raise ValueError(f"effect {effect!r} has no shape parameter(s) {sorted(unknown)}")
    a, omega = (pt.as_tensor_variable(v).astype("float64") for v in (a, omega))
    shape = {
        n: pt.as_tensor_variable(shape.get(n, default)).astype("float64")
        for n, default in spec.defaults.items()
    }
    k_part, c_part = spec.describing_parts(pytensor_namespace(), a, omega, **shape)
    zero = pt.zeros_like(a * omega)
    return (
        zero if k_part is None else zero + k_part,
        zero if c_part is None else zero + c_part,
    )


def harmonic_backbone_graph(
    model: JointModel,
    theta: Any,
    names: Sequence[str] | None,
    amplitudes_m: ArrayLike,
    *,
    pointwise: bool = False,
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
    pointwise
        Pair the amplitudes with θ's rows instead of evaluating every row at every
        amplitude: θ ``(n_amp, len(names))``, one amplitude per row, output
        ``(n_amp, 3)``. A hierarchical model scores each curve at its own points this
        way, instead of every curve at every curve's points.

    Returns
    -------
    TensorVariable
        ``(..., n_amp, 3)`` (pointwise: ``(n_amp, 3)``), columns
        :data:`BACKBONE_COLUMNS`; NaN frequency and damping where there is no
        backbone, and for whole rows whose shape parameters are not > 0.
    """
    names = checked_names(model, names)
    amplitudes = positive_vector(amplitudes_m, "amplitudes_m")
    theta = pt.as_tensor_variable(theta).astype("float64")
    if theta.ndim == 0 or theta.type.shape[-1] not in (None, len(names)):
        raise ValueError(
            f"θ must have a last axis of {len(names)} parameters ({', '.join(names)}), "
            f"got shape {theta.type.shape}"
        )
    # Parameters get a trailing axis to broadcast against the amplitude grid (pointwise:
    # each row already stands at its own amplitude).
    grid_axis = () if pointwise else (None,)
    value = {
        name: theta[(..., names.index(name), *grid_axis)] if name in names else pt.constant(v)
        for name, v in model.parameters.items()
    }
    a = pt.constant(amplitudes)
    xp = pytensor_namespace()
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
        terms.append((value[term.effect], get_effect(term.effect), shape))

    # ω² = K + K₂ ω² (K₂ from x·ẋ² only): stiffness parts first, then damping at ω.
    stiffness = per_omega_squared = damping = pt.as_tensor_variable(0.0)
    for coefficient, effect, shape in terms:
        if effect.stiffness is not None:
            stiffness = stiffness + coefficient * effect.stiffness(xp, a, **shape)
        if effect.stiffness_per_omega_squared is not None:
            k2 = effect.stiffness_per_omega_squared(xp, a, **shape)
            per_omega_squared = per_omega_squared + coefficient * k2
    denominator = 1.0 - per_omega_squared
    ok = (denominator > 0) & (stiffness > 0)
    for positive in positive_shapes:
        ok = ok & positive
    # Stand-ins on failed points keep every intermediate finite (no invalid-value
    # warnings, no 0·NaN in the gradient); the outputs there are NaN below.
    omega = pt.sqrt(pt.switch(ok, stiffness / pt.switch(ok, denominator, 1.0), 1.0))
    for coefficient, effect, shape in terms:
        if effect.damping is not None:
            damping = damping + coefficient * effect.damping(xp, a, omega, **shape)
    frequency_hz = pt.switch(ok, omega / (2.0 * np.pi), np.nan)
    damping_ratio = pt.switch(ok, damping / (2.0 * omega), np.nan)
    return pt.stack(pt.broadcast_arrays(a, frequency_hz, damping_ratio), axis=-1)


class HarmonicBalanceGraph:
    """Single-harmonic backbone as a callable with the forward-model interface.

    Not a pytensor ``Op`` (hence the name): calling it builds :func:`harmonic_backbone_graph`,
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
        self.parameter_names = checked_names(model, names)
        self.amplitudes_m = positive_vector(amplitudes_m, "amplitudes_m")
        self.n_points = self.amplitudes_m.size

    def __call__(self, theta: Any) -> pt.TensorVariable:
        return harmonic_backbone_graph(self.model, theta, self.parameter_names, self.amplitudes_m)

    def __repr__(self) -> str:
        return (
            f"HarmonicBalanceGraph({self.model!r}, names={list(self.parameter_names)}, "
            f"n_points={self.n_points})"
        )
