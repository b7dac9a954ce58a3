"""Derivatives and integrals of sampled signals without the frequency bias of the basic rules.

:func:`~identification.sindy.kinematics.sensor_kinematics` derives the kinematics by
central differences (gain ``sin θ / θ`` on a sinusoid, ``θ = ωh`` the phase step per
sample) and integrates by the trapezoidal rule (gain ``(θ/2) cot(θ/2)``). Both fall
short by ``θ²/6`` and ``θ²/12``: an identified stiffness ``ẍ/x`` then reads the
frequency low by ``θ²/24`` (velocity sensor) to ``θ²/6`` (displacement sensor), a few
tenths of a percent at a tenth of the Nyquist frequency, which the modal equations of
:mod:`.modal_identify` carry into a phase drift over a long decay.

:func:`unbiased_kinematics` divides each channel by its rule's gain. Both gains are
even functions of ``θ``, hence power series in ``w = sin²(θ/2)``, and ``4w`` is the
symbol of the negated second difference ``−Δ²``; so the inverse gain is the symmetric
filter ``Σ_j b_j (−Δ²/4)^j`` (:data:`SERIES_TERMS` terms, its residual gain error of
order ``w^SERIES_TERMS``). With

    A(w) = arcsin(√w)/√w,   B(w) = 1/√(1 − w),

the central difference's inverse gain is ``θ / sin θ = A·B`` and the trapezoidal rule's
is ``tan(θ/2)/(θ/2) = B/A``. The filters are linear and time-invariant, so they commute
with the band-pass the channels already passed; the few samples at each end the filter
cannot reach keep their values (they lie in the trimmed edges, ``Kinematics.valid``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from identification.measurements.signals import Kinematics

__all__ = [
    "SERIES_TERMS",
    "central_difference_inverse_gain",
    "trapezoid_inverse_gain",
    "unbiased_kinematics",
]

#: Terms of each inverse-gain series: the residual relative gain error is below 1e-7 up
#: to θ = 0.5 (a twelfth of the sampling rate), hence far below 1e-5 at the modes.
SERIES_TERMS = 7


def _series_a(n: int) -> np.ndarray:
    """Taylor coefficients in ``w`` of ``arcsin(√w)/√w``."""
    return np.array([math.comb(2 * k, k) / (4**k * (2 * k + 1)) for k in range(n)])


def _series_b(n: int) -> np.ndarray:
    """Taylor coefficients in ``w`` of ``1/√(1 − w)``."""
    return np.array([math.comb(2 * k, k) / 4**k for k in range(n)])


def _product(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    return np.convolve(p, q)[: p.size]


def _quotient(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Taylor coefficients of ``p/q`` (``q[0] ≠ 0``)."""
    out = np.zeros(p.size)
    for k in range(p.size):
        out[k] = (p[k] - np.dot(out[:k], q[k:0:-1])) / q[0]
    return out


#: Coefficients ``b_j`` of the inverse gains as series in ``w = sin²(θ/2)``.
_DIFFERENCE_SERIES = _product(_series_a(SERIES_TERMS), _series_b(SERIES_TERMS))
_TRAPEZOID_SERIES = _quotient(_series_b(SERIES_TERMS), _series_a(SERIES_TERMS))


def _inverse_gain(theta: np.ndarray, series: np.ndarray) -> np.ndarray:
    w = np.sin(np.asarray(theta, dtype=float) / 2) ** 2
    return np.polynomial.polynomial.polyval(w, series)


def central_difference_inverse_gain(theta: np.ndarray) -> np.ndarray:
    """The series' approximation of ``θ / sin θ`` (for checks against the closed form)."""
    return _inverse_gain(theta, _DIFFERENCE_SERIES)


def trapezoid_inverse_gain(theta: np.ndarray) -> np.ndarray:
    """The series' approximation of ``tan(θ/2)/(θ/2)`` (for checks against the closed form)."""
    return _inverse_gain(theta, _TRAPEZOID_SERIES)


def _apply(values: np.ndarray, series: np.ndarray, times: int) -> np.ndarray:
    """``values`` through the filter ``Σ_j b_j (−Δ²/4)^j``, ``times`` times."""
    out = np.asarray(values, dtype=float)
    for _ in range(times):
        term, total = out, series[0] * out
        for b in series[1:]:
            # −Δ²/4 has symbol sin²(θ/2); its ends (unreachable) are left at zero.
            nxt = np.zeros_like(term)
            nxt[1:-1] = -(term[2:] - 2.0 * term[1:-1] + term[:-2]) / 4.0
            term = nxt
            total = total + b * term
        reach = series.size - 1
        out = np.concatenate([out[:reach], total[reach:-reach], out[-reach:]])
    return out


def unbiased_kinematics(kinematics: Kinematics, quantity: str) -> Kinematics:
    """``sensor_kinematics``'s output with every derived channel's rule gain divided out.

    Parameters
    ----------
    kinematics
        :func:`~identification.sindy.kinematics.sensor_kinematics` of one signal.
    quantity
        The signal's quantity, which says which channels were derived and how:
        displacement (velocity one central difference, acceleration two), velocity
        (acceleration one central difference, displacement one trapezoidal integral),
        acceleration (velocity one integral, displacement two). The base acceleration
        is one central difference of the base velocity.

    Returns
    -------
    Kinematics
        The same record with the derived channels corrected; the measured one untouched.
    """
    diff, trap = _DIFFERENCE_SERIES, _TRAPEZOID_SERIES
    k = kinematics
    if quantity == "displacement":
        changes = {"velocity": _apply(k.velocity, diff, 1),
                   "acceleration": _apply(k.acceleration, diff, 2)}  # fmt: skip
    elif quantity == "velocity":
        changes = {"displacement": _apply(k.displacement, trap, 1),
                   "acceleration": _apply(k.acceleration, diff, 1)}  # fmt: skip
    elif quantity == "acceleration":
        changes = {"velocity": _apply(k.velocity, trap, 1),
                   "displacement": _apply(k.displacement, trap, 2)}  # fmt: skip
    else:
        raise ValueError(f"unknown quantity {quantity!r}")
    if np.any(k.base_acceleration):
        changes["base_acceleration"] = _apply(k.base_acceleration, diff, 1)
    return dataclasses.replace(k, **changes)
