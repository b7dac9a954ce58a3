"""Local fits of several decaying, chirping modes at once, over a window of one sensor's signal.

The one-mode window model of :mod:`identification.measurements.local_fit` summed over modes:

    s(τ) = m₀ + m₁τ + Σ_m Σ_{k ∈ K_m} Re S_{m,k} e^{−kσ_m τ} e^{ik(ω_m τ + β_m τ²/2)}

each mode ``m`` with its own frequency ``ω_m``, drift ``β_m`` and decay rate ``σ_m`` at the
window's centre, and its own set of harmonic orders ``K_m``. All amplitudes and the ``3M``
nonlinear parameters are fitted together by Gauss–Newton with step halving, as the one-mode
fit is. Why one joint fit and not a band-pass per mode followed by the one-mode analysis: a
mode's harmonics lie in the other modes' bands (mode 1's 2nd harmonic sits on mode 2 near
1:2), which a band-pass cannot give back to their mode, and a band-pass's start transient
takes the largest amplitudes of a decay away; the joint fit measures every component where
it is and leaves a collision explicit.

Two components a window cannot tell apart (frequencies closer than :data:`LOCK_RESOLUTION`
over the window's length, e.g. mode 1's ``k``-th harmonic and mode 2 near ``k``:1) are
fitted as one: :func:`component_orders` gives the colliding order to the higher mode alone
(its fundamental), and :mod:`identification.measurements.decay_modes` attributes the
content afterwards.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["LOCK_RESOLUTION", "ComponentsFit", "Lock", "component_orders", "fit_components"]

#: Two frequencies closer than this many ``1/T`` (``T`` the window's length) collide: a
#: window of a few periods separates them only through an ill-conditioned fit.
LOCK_RESOLUTION = 1.5
#: Gauss–Newton iterations per window at most.
_MAX_ITERATIONS = 40
#: Relative change of the residual sum of squares that ends the iterations.
_TOLERANCE = 1e-12


@dataclass(frozen=True)
class Lock:
    """Order ``order`` of mode ``lower`` collides with the fundamental of mode ``upper``
    (modes numbered from 0 in order of frequency)."""

    lower: int
    order: int
    upper: int


def component_orders(
    frequencies_hz: Sequence[float], harmonics: int, window_s: float
) -> tuple[tuple[tuple[int, ...], ...], tuple[Lock, ...]]:
    """Harmonic orders each mode is fitted with, and the locked collisions.

    Mode ``m`` (frequencies in increasing order) gets orders ``1..harmonics`` less those
    that collide with a component of a lower mode already kept; a lower mode's order that
    collides with a higher mode's fundamental is given to the higher mode (a
    :class:`Lock`), and that higher mode keeps its fundamental alone, as its own harmonics
    fall on the lower mode's.
    """
    resolution = LOCK_RESOLUTION / window_s
    orders: list[list[int]] = []
    locks: list[Lock] = []
    for m, f in enumerate(frequencies_hz):
        mine = list(range(1, harmonics + 1))
        for lower in range(m):
            for k in list(orders[lower]):
                if k > 1 and abs(k * frequencies_hz[lower] - f) < resolution:
                    orders[lower].remove(k)
                    locks.append(Lock(lower, k, m))
                    mine = [1]
        kept = [
            k for k in mine
            if k == 1 or not any(abs(j * frequencies_hz[low] - k * f) < resolution
                                 for low in range(m) for j in orders[low])
        ]  # fmt: skip
        orders.append(kept)
    return tuple(tuple(o) for o in orders), tuple(locks)


@dataclass(frozen=True)
class ComponentsFit:
    """One window's fit of several modes (see the module notes).

    ``omega``, ``beta``, ``sigma``: per mode (rad/s, rad/s², 1/s); ``phasors[m]`` and
    ``phasor_standard_error[m]``: ``S_{m,k}`` for ``k`` in ``orders[m]``.
    """

    centre_s: float
    orders: tuple[tuple[int, ...], ...]
    omega: np.ndarray
    beta: np.ndarray
    sigma: np.ndarray
    phasors: tuple[np.ndarray, ...]
    phasor_standard_error: tuple[np.ndarray, ...]
    nonlinear_standard_error: np.ndarray
    mean: float
    mean_standard_error: float
    residual_rms: float
    n_samples: int
    converged: bool


def _columns(tau, nonlinear, orders):
    """Basis ``[1, τ, per mode: E cos kφ…, E sin kφ…]`` and each mode's cos/sin blocks."""
    blocks, parts = [np.ones_like(tau), tau], []
    for (omega, beta, sigma), k in zip(nonlinear.reshape(-1, 3), orders, strict=True):
        k = np.asarray(k, dtype=float)
        phase = np.outer(omega * tau + 0.5 * beta * tau**2, k)
        envelope = np.exp(-np.outer(tau, k) * sigma)
        cos, sin = envelope * np.cos(phase), envelope * np.sin(phase)
        blocks += [cos, sin]
        parts.append((cos, sin, k))
    return np.column_stack(blocks), parts


def _jacobian(tau, linear, parts, basis):
    """Model derivatives: the basis, then ∂/∂ω_m, ∂/∂β_m, ∂/∂σ_m per mode."""
    columns, start = [basis], 2
    for cos, sin, k in parts:
        h = k.size
        a, b = linear[start : start + h], linear[start + h : start + 2 * h]
        start += 2 * h
        quadrature = ((-sin * a + cos * b) * k).sum(axis=1)
        in_phase = ((cos * a + sin * b) * k).sum(axis=1)
        columns += [tau * quadrature, 0.5 * tau**2 * quadrature, -tau * in_phase]
    return np.column_stack(columns)


def fit_components(
    time_s: np.ndarray,
    values: np.ndarray,
    centre_s: float,
    starts: np.ndarray,
    orders: Sequence[Sequence[int]],
) -> ComponentsFit:
    """Fit the module's model to one window's samples.

    Parameters
    ----------
    time_s, values
        The window's samples.
    centre_s
        The window's centre (s).
    starts
        ``(M, 3)``: starting ``ω`` (rad/s), ``β`` (rad/s²), ``σ`` (1/s) per mode.
    orders
        Harmonic orders of each mode (:func:`component_orders`).

    Raises
    ------
    ValueError
        Too few samples for the model, or a singular fit.
    """
    tau = np.asarray(time_s, dtype=float) - centre_s
    y = np.asarray(values, dtype=float)
    orders = tuple(tuple(int(k) for k in o) for o in orders)
    n_linear = 2 + 2 * sum(len(o) for o in orders)
    n_params = n_linear + 3 * len(orders)
    if y.size <= 2 * n_params:
        raise ValueError(f"a window of {y.size} samples is too short for {n_params} parameters")
    nonlinear = np.asarray(starts, dtype=float).reshape(-1).copy()
    basis, parts = _columns(tau, nonlinear, orders)
    linear = np.linalg.lstsq(basis, y, rcond=None)[0]
    rss = float(np.sum((y - basis @ linear) ** 2))
    converged = False
    for _ in range(_MAX_ITERATIONS):
        jac = _jacobian(tau, linear, parts, basis)
        norms = np.linalg.norm(jac, axis=0)
        norms[norms == 0] = 1.0
        step = np.linalg.lstsq(jac / norms, y - basis @ linear, rcond=None)[0] / norms
        for _halving in range(30):
            trial_nonlinear = nonlinear + step[n_linear:]
            trial = _columns(tau, trial_nonlinear, orders)
            trial_linear = linear + step[:n_linear]
            trial_rss = float(np.sum((y - trial[0] @ trial_linear) ** 2))
            if trial_rss <= rss:
                break
            step = 0.5 * step
        else:
            converged = True  # no step lowers the residual: at the optimum to rounding
            break
        done = rss - trial_rss <= _TOLERANCE * rss
        nonlinear, linear, rss = trial_nonlinear, trial_linear, trial_rss
        basis, parts = trial
        if done:
            converged = True
            break
    jac = _jacobian(tau, linear, parts, basis)
    try:
        covariance = rss / max(y.size - n_params, 1) * np.linalg.inv(jac.T @ jac)
    except np.linalg.LinAlgError:
        raise ValueError("singular window fit (the window is flat or too short)") from None
    se = np.sqrt(np.clip(np.diag(covariance), 0.0, None))
    phasors, phasor_se, start = [], [], 2
    for o in orders:
        h = len(o)
        cos, sin = slice(start, start + h), slice(start + h, start + 2 * h)
        phasors.append(linear[cos] - 1j * linear[sin])
        phasor_se.append(np.sqrt(0.5 * (se[cos] ** 2 + se[sin] ** 2)))
        start += 2 * h
    nonlinear = nonlinear.reshape(-1, 3)
    return ComponentsFit(
        centre_s=float(centre_s),
        orders=orders,
        omega=nonlinear[:, 0].copy(),
        beta=nonlinear[:, 1].copy(),
        sigma=nonlinear[:, 2].copy(),
        phasors=tuple(phasors),
        phasor_standard_error=tuple(phasor_se),
        nonlinear_standard_error=se[n_linear:].reshape(-1, 3),
        mean=float(linear[0]),
        mean_standard_error=float(se[0]),
        residual_rms=math.sqrt(rss / y.size),
        n_samples=int(y.size),
        converged=converged,
    )
