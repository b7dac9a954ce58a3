"""``microslip``: a Jenkins element, partial slip in the joint.

A spring ``k_t`` in series with a slider of slip force ``F_s``: softening and
damping that rise with amplitude. The one hysteretic effect of the catalogue:
its force depends on the loading history, so its feature needs the whole path
(:func:`jenkins_path`) and the integrators carry the element's state through
:func:`jenkins_force`.
"""

from collections.abc import Mapping
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike

from identification.effects.base import (
    ArrayNamespace,
    Effect,
    FitScale,
    HiddenScenario,
    ShapeParameter,
)

__all__ = ["EFFECT", "jenkins_force", "jenkins_path"]


@numba.njit(cache=True)
def jenkins_force(x: float, x_anchor: float, f_anchor: float, k_t: float, f_s: float) -> float:
    """Force of a Jenkins element at displacement ``x``.

    The element last had force ``f_anchor`` at displacement ``x_anchor``; from
    there it loads elastically with stiffness ``k_t`` until the slider carries
    ``±f_s``. Exact for a monotonic path between anchor and ``x`` (the return
    mapping of rate-independent plasticity), so a time integrator moves the
    anchor to the accepted state after each step.
    """
    f = f_anchor + k_t * (x - x_anchor)
    if f > f_s:
        return f_s
    if f < -f_s:
        return -f_s
    return f


@numba.njit(cache=True)
def jenkins_path(x: np.ndarray, k_t: float, f_s: float) -> np.ndarray:
    """Jenkins force along a displacement history ``x`` (starting unstressed)."""
    out = np.empty_like(x)
    x_anchor = 0.0
    f_anchor = 0.0
    for i in range(x.size):
        f_anchor = jenkins_force(x[i], x_anchor, f_anchor, k_t, f_s)
        x_anchor = x[i]
        out[i] = f_anchor
    return out


@numba.njit(cache=True)
def _force(x: float, v: float, p0: float, p1: float) -> float:
    # Virgin loading curve from the unstressed state; history-dependent use goes
    # through `jenkins_force` with the integrator's anchor state.
    return jenkins_force(x, 0.0, 0.0, p0, p1)


def _path_feature(x: ArrayLike, v: ArrayLike, k_t: float, F_s: float) -> np.ndarray:
    # The feature is the element force along the measured path.
    return jenkins_path(np.ascontiguousarray(x, dtype=float), float(k_t), float(F_s))


# Describing function: the Masing / elastic-perfectly-plastic loop (Caughey's
# bilinear hysteresis). Below the slip amplitude a_s = F_s/k_t the element sticks
# (k_eq = k_t). Above it, with cos φ* = 1 − 2 a_s / a: k_eq = k_t (φ* − ½ sin 2φ*)/π,
# and the dissipated energy per cycle 4 F_s (a − a_s) gives c_eq = 4 F_s (a − a_s)/(π a² ω).


def _slip(xp: ArrayNamespace, a: Any, k_t: Any, F_s: Any) -> tuple[Any, Any, Any]:
    """Slip amplitude a_s, slipping mask and slip angle φ*."""
    a_s = F_s / k_t
    slipping = a > a_s
    # Sticking points get cos φ* = 0 (and a stand-in amplitude): the branch they
    # do not use stays finite, with finite gradients, away from arccos(±1).
    cos_phi = xp.where(slipping, 1.0 - 2.0 * a_s / xp.where(slipping, a, 1.0), 0.0)
    return a_s, slipping, xp.arccos(cos_phi)


def _stiffness(xp: ArrayNamespace, a: Any, k_t: Any, F_s: Any, **_: Any) -> Any:
    _, slipping, phi = _slip(xp, a, k_t, F_s)
    return xp.where(slipping, k_t * (phi - 0.5 * xp.sin(2.0 * phi)) / np.pi, k_t)


def _damping(xp: ArrayNamespace, a: Any, omega: Any, k_t: Any, F_s: Any, **_: Any) -> Any:
    a_s, slipping, _ = _slip(xp, a, k_t, F_s)
    return xp.where(slipping, 4.0 * F_s * (a - a_s) / (np.pi * a * a * omega), 0.0)


def _shape_grid(scale: FitScale) -> dict[str, np.ndarray]:
    # The linear solve fits the coefficient, so only the slip amplitude F_s/k_t
    # matters: let the slip onset fall anywhere in the test.
    a_lo, a_hi = scale.amplitude_m
    k_ref = 0.1 * scale.stiffness
    return {"k_t": np.array([k_ref]), "F_s": k_ref * np.geomspace(a_lo / 2, a_hi, 16)}


def _shape_bounds(scale: FitScale) -> dict[str, tuple[float, float]]:
    a_lo, a_hi = scale.amplitude_m
    k = scale.stiffness
    return {"k_t": (1e-4 * k, 10 * k), "F_s": (1e-5 * k * a_lo, 100 * k * a_hi)}


def _fitted_reading(coefficient: float, shape: Mapping[str, float], scale: FitScale) -> str:
    k_t, f_s = shape["k_t"], shape["F_s"]
    share = coefficient * k_t / scale.stiffness
    share = f"the stuck joint carries {100 * share:.2g} % of the stiffness"
    onset = f_s / k_t
    if onset < scale.amplitude_m[0]:
        return (
            f" (slipping over the whole test, from {1e3 * onset:.2g} mm: it acts as "
            f"macroslip friction here; {share})"
        )
    return f" (slip from about {1e3 * onset:.2g} mm; {share})"


def _stuck_stiffness(coefficient: Any, shape: Mapping[str, Any]) -> Any:
    # Stuck, the element is its spring k_t.
    return coefficient * shape["k_t"]


def _written_term(shape: Mapping[str, float], precision: int) -> str:
    return f"Jenkins(x; k_t={shape['k_t']:.{precision}g}, F_s={shape['F_s']:.{precision}g})"


def _lab_truth(k0: float) -> dict[str, float]:
    # The lab rig's joint: stuck, it carries 6 % of the stiffness; it slips from 0.2 mm.
    k_t = 0.06 * k0
    return {"coefficient": 1.0, "k_t": k_t, "F_s": k_t * 2e-4}


EFFECT = Effect(
    name="microslip",
    term="Jenkins(x; k_t, F_s)",
    units="1",
    reading="partial slip in the joint: softening and damping that rises with amplitude",
    force=_force,
    shape_parameters=(ShapeParameter("k_t", 1e5, "1/s²"), ShapeParameter("F_s", 1.0, "m/s²")),
    stiffness=_stiffness,
    damping=_damping,
    hysteretic=True,
    path_feature=_path_feature,
    stuck_stiffness=_stuck_stiffness,
    written_term=_written_term,
    shape_grid=_shape_grid,
    shape_bounds=_shape_bounds,
    fitted_reading=_fitted_reading,
    coefficient_sign=1,
    hidden_scenario=HiddenScenario(
        truth=_lab_truth,
        description=(
            "a Jenkins element softens by up to 2.6 % from 0.2 mm and lifts the damping from "
            "0.3 % to 1.25 %"
        ),
        key_channel="frequency_hz",
        on_hardening_base=True,
    ),
)
