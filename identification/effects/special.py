"""Special functions of the catalogue, one implementation per backend.

The describing functions are written once against an array namespace
(:mod:`identification.effects.base`); the few functions neither numpy nor
pytensor has in a usable form live here, each with a numpy version (fast, for
the fits) and a pytensor version (differentiable, for NUTS):

* the smoothed sign ``tanh(v / v_reg)`` of the friction forces (numba kernel);
* the describing gain of ``tanh``, :func:`tanh_gain` (a table) and
  :func:`tanh_gain_graph` (the quadrature the table was built from);
* Dawson's integral, ``scipy.special.dawsn`` and :func:`dawsn_graph` (an Op
  around scipy with its analytic derivative).

pytensor is imported only when a graph is asked for, so the numpy side (every
fit, simulation and SINDy run) does not pay for it.
"""

from __future__ import annotations

import functools
from typing import Any

import numba
import numpy as np
from scipy import interpolate, special

__all__ = [
    "DEFAULT_SIGN_VELOCITY",
    "TANH_QUADRATURE_POINTS",
    "dawsn",
    "dawsn_graph",
    "smooth_sign",
    "tanh_gain",
    "tanh_gain_graph",
]

#: Regularising velocity of the smoothed sign (tanh(v/v_reg)) in ``coulomb_friction`` and
#: ``stribeck_friction`` (m/s). Well below the velocities of a joint test
#: (1e-2 to 1e-1 m/s), so the smoothing only rounds the velocity reversals, and
#: large enough that an explicit 10 kHz integrator stays stable for friction
#: levels up to a few m/s² (the slope F/v_reg acts as a viscous damper).
DEFAULT_SIGN_VELOCITY = 1e-4

#: Dawson's integral ``D(x) = exp(−x²) ∫₀ˣ exp(t²) dt`` (numpy backend).
dawsn = special.dawsn


@numba.njit(cache=True, inline="always")
def smooth_sign(v, v_reg):
    """``tanh(v / v_reg)``: the sign of ``v``, rounded over ``|v| ≲ v_reg``."""
    return np.tanh(v / v_reg)


# --------------------------------------------------------------------------
# Describing gain of tanh: g(u) = (2/u)⟨tanh(u cos θ) cos θ⟩ over one cycle.

#: Where the tabulated tanh gain hands over to its series (below) and asymptote (above).
_TANH_SMALL, _TANH_LARGE = 1e-3, 1e3

#: Trapezoidal quadrature points of the pytensor tanh gain (the numpy side tabulates
#: the same gain once; a graph keeps the sum, which is differentiable). The error
#: falls like exp(−400/u): below 1e-8 for u = a/x_s up to 20.
TANH_QUADRATURE_POINTS = 256


@functools.cache
def _tanh_gain_spline() -> interpolate.BSpline:
    """Quintic spline of ln g over ln u on [_TANH_SMALL, _TANH_LARGE], built once.

    Each node is an exact periodic trapezoid sum: tanh(u cos θ) has its nearest
    complex singularity at distance ≈ π/(2u) from the real θ axis, so 40u + 256
    points put the quadrature error below 1e-16. The spline's own error is
    below 1e-12 (node spacing 0.013 in ln u).
    """
    log_u = np.linspace(np.log(_TANH_SMALL), np.log(_TANH_LARGE), 1200)
    gain = np.empty_like(log_u)
    for i, u in enumerate(np.exp(log_u)):
        n = 256 + int(40 * u)
        theta = 2.0 * np.pi * (np.arange(n) + 0.5) / n
        gain[i] = 2.0 * np.mean(np.tanh(u * np.cos(theta)) * np.cos(theta)) / u
    return interpolate.make_interp_spline(log_u, np.log(gain), k=5)


def tanh_gain(u: np.ndarray) -> np.ndarray:
    """Describing gain g(u) = (2/u)⟨tanh(u cos θ) cos θ⟩ of tanh, u = a/x_s > 0 (numpy).

    There is no elementary closed form, and a quadrature per call made tanh the
    slowest term of every harmonic-balance fit; g is one smooth curve of u, so
    it is tabulated once. Outside the table: the Taylor series 1 − u²/4 + u⁴/12
    (small u) and the asymptote 4/(πu) − π/(6u³) (large u; the tanh − sign
    correction near the zero crossings), both exact to rounding there.
    """
    u = np.asarray(u, float)
    gain = np.exp(_tanh_gain_spline()(np.log(np.clip(u, _TANH_SMALL, _TANH_LARGE))))
    gain = np.where(u < _TANH_SMALL, 1.0 - u**2 / 4.0 + u**4 / 12.0, gain)
    with np.errstate(divide="ignore", over="ignore"):
        return np.where(u > _TANH_LARGE, 4.0 / (np.pi * u) - np.pi / (6.0 * u**3), gain)


def tanh_gain_graph(u: Any) -> Any:
    """The tanh describing gain g(u) as a differentiable pytensor graph.

    A periodic trapezoid sum over :data:`TANH_QUADRATURE_POINTS` points (the
    definition of g, as the numpy table's nodes are computed); relative error
    about ``exp(−N · asinh(π/(2u)))``.
    """
    import pytensor.tensor as pt

    n = TANH_QUADRATURE_POINTS
    cos_theta = np.cos(2.0 * np.pi * (np.arange(n) + 0.5) / n)
    u = pt.as_tensor_variable(u)
    return 2.0 * pt.mean(pt.tanh(u[..., None] * cos_theta) * cos_theta, axis=-1) / u


# --------------------------------------------------------------------------
# Dawson's integral for pytensor.


def dawsn_graph(x: Any) -> Any:
    """Dawson's integral ``D(x)`` elementwise as a differentiable pytensor operation."""
    return _dawson_op()(x)


@functools.cache
def _dawson_op() -> Any:
    """The pytensor Op of Dawson's integral, built on first use (pytensor imported then)."""
    import pytensor.tensor as pt
    from pytensor.graph.basic import Apply
    from pytensor.graph.op import Op
    from pytensor.graph.replace import _vectorize_node

    class Dawson(Op):
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

    # Elementwise: leading batch axes need no Blockwise loop.
    _vectorize_node.register(Dawson)(lambda op, node, x: op.make_node(x))
    return Dawson()
