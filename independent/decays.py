"""Ring-downs and forced steady states: scipy's DOP853 on forces written as plain Python.

Tests that check pm-joint's extraction, identification or criticism need data that the code under
test did not make. This module shares nothing with pm-joint (no catalogue kernels, no numba, no
harmonic balance): forces are Python callables of ``(x, v)`` written in each test, and the
equations are integrated by :func:`scipy.integrate.solve_ivp` with dense output, then sampled as a
data acquisition would (fixed rate, optional noise).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from scipy.integrate import solve_ivp

Force = Callable[[float, float], float]


def free_decay(
    force: Force,
    x0_m: float,
    v0_m_s: float,
    *,
    fs_hz: float = 10_000.0,
    duration_s: float = 1.0,
    rtol: float = 1e-10,
) -> dict[str, np.ndarray]:
    """Ring-down of ``ẍ + force(x, ẋ) = 0`` from ``(x0, v0)``, sampled at ``fs_hz``.

    Returns the time (s), displacement (m), velocity (m/s) and acceleration (m/s²), the last
    from the equation of motion (not from differencing).
    """

    def rhs(_, state):
        x, v = state
        return [v, -force(x, v)]

    t = np.arange(round(duration_s * fs_hz)) / fs_hz
    solution = solve_ivp(
        rhs, (0.0, t[-1]), [x0_m, v0_m_s], method="DOP853", t_eval=t, rtol=rtol, atol=1e-14
    )
    if not solution.success:
        raise RuntimeError(f"free decay did not integrate: {solution.message}")
    x, v = solution.y
    a = -np.array([force(xi, vi) for xi, vi in zip(x, v, strict=True)])
    return {"time_s": t, "displacement_m": x, "velocity_m_s": v, "acceleration_m_s2": a}


def forced_steady_state(
    force: Force,
    excitation: Callable[[float], float],
    period_s: float,
    *,
    fs_hz: float = 10_000.0,
    settle_periods: int = 400,
    record_periods: int = 50,
    rtol: float = 1e-10,
) -> dict[str, np.ndarray]:
    """Steady response of ``ẍ + force(x, ẋ) = excitation(t)`` after ``settle_periods`` periods.

    The last ``record_periods`` periods are sampled at ``fs_hz`` (time restarts at 0 there).
    The caller makes sure the transient has died out (light damping needs many periods).
    """

    def rhs(t, state):
        x, v = state
        return [v, excitation(t) - force(x, v)]

    t_settle = settle_periods * period_s
    first = solve_ivp(rhs, (0.0, t_settle), [0.0, 0.0], method="DOP853", rtol=rtol, atol=1e-14)
    if not first.success:
        raise RuntimeError(f"settling did not integrate: {first.message}")
    n = round(record_periods * period_s * fs_hz)
    t = t_settle + np.arange(n) / fs_hz
    second = solve_ivp(
        rhs, (t_settle, t[-1]), first.y[:, -1], method="DOP853", t_eval=t, rtol=rtol, atol=1e-14
    )
    if not second.success:
        raise RuntimeError(f"recording did not integrate: {second.message}")
    x, v = second.y
    return {
        "time_s": t - t_settle,
        "displacement_m": x,
        "velocity_m_s": v,
        "excitation": np.array([excitation(ti) for ti in t]),
    }


def hilbert_backbone(
    time_s: np.ndarray, displacement_m: np.ndarray, band_hz: tuple[float, float]
) -> tuple[np.ndarray, np.ndarray]:
    """The field's model-free backbone of a free decay: the Hilbert transform of its fundamental.

    The fundamental is band-passed (4th-order Butterworth, zero phase), its analytic signal
    (:func:`scipy.signal.hilbert`) gives the instantaneous amplitude and frequency, both averaged
    over a period; ten periods at each end (the filter's and the transform's end effects) are
    dropped. Returns the amplitude (m) and frequency (Hz), in time order.
    """
    from scipy import signal

    fs_hz = (time_s.size - 1) / (time_s[-1] - time_s[0])
    sos = signal.butter(4, band_hz, btype="bandpass", fs=fs_hz, output="sos")
    analytic = signal.hilbert(signal.sosfiltfilt(sos, displacement_m))
    frequency = np.gradient(np.unwrap(np.angle(analytic)), time_s) / (2 * np.pi)
    period = round(fs_hz / np.median(frequency))
    kernel = np.ones(period) / period
    amplitude = np.convolve(np.abs(analytic), kernel, mode="same")
    frequency = np.convolve(frequency, kernel, mode="same")
    inside = slice(10 * period, -10 * period)
    return amplitude[inside], frequency[inside]
