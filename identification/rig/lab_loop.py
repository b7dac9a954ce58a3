"""The lab rig's loop, shared by its one-mode engine and its N-mode engine.

What the lab's test does whatever the structure it drives
(:mod:`identification.rig.lab` for the one-mode rig with an optional second mode,
:mod:`identification.rig.modal_engine` for a
:class:`~identification.multimode.model.ModalModel`): the layout of the loop's part
of the settings vector and its values from the controller, drift and schedule; the
fixed-time level schedule with its raised-cosine ramps and the gain drift on the
sensors; the distorted coil acceleration; the multiply-and-low-pass phase detector
behind the PI controller; the recorded loop channels and the record that holds
them. The conventions are those of :mod:`identification.rig.lab`.

The numba helpers are inlined into the engines' kernels, whose numba cache checks
only their own file: after editing them, ``make clean-cache``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from identification.analytical.pll.loop import ramp_level, wrap_angle
from identification.rig.conditions import Controller, Drift

__all__ = ["LOOP_CHANNELS", "LabChannels", "loop_settings"]

# Layout of the loop's part of a kernel's settings vector; each engine appends its own.
(
    DT, N_SUB, RAMP, HOLD, KP, KI, STAGE_ALPHA, ORDER, BASE_REFERENCE, TARGET, OMEGA_INITIAL,
    OMEGA_LOW, OMEGA_HIGH, DELTA0, DELTA1, GAIN0, GAIN1, GAIN_ON_PANEL, X_MAX, N_LOOP_SETTINGS,
) = range(20)  # fmt: skip
#: The loop's recorded channels, one row each (after the structure's).
LOOP_CHANNELS = (
    "base_velocity", "base_acceleration", "frequency_hz", "theta", "level", "phase_error_deg",
)  # fmt: skip
#: Largest displacement (m) of the structure's coordinates before a run counts as diverged.
_X_LIMIT = 0.05


@dataclass(frozen=True, eq=False)
class LabChannels:
    """The loop's true signals of one record (SI, ``fs`` samples per second).

    ``base_velocity``, ``base_acceleration`` the true base motion; ``frequency_hz`` and
    ``theta`` (rad, unwrapped) the oscillator; ``level`` the coil-acceleration
    amplitude ``A(t)`` (m/s²); ``phase_error_deg`` what the controller measured.
    ``completed`` is False when the run diverged (NaN from there).
    """

    fs: float
    completed: bool
    base_velocity: np.ndarray
    base_acceleration: np.ndarray
    frequency_hz: np.ndarray
    theta: np.ndarray
    level: np.ndarray
    phase_error_deg: np.ndarray

    @property
    def t(self) -> np.ndarray:
        return np.arange(self.theta.size) / self.fs


def loop_settings(
    n_settings: int,
    *,
    fs: float,
    n_sub: int,
    ramp_samples: int,
    hold_samples: int,
    controller: Controller,
    frequency_hz: float,
    damping_ratio: float,
    drift: Drift,
    position: float,
) -> np.ndarray:
    """A settings vector of ``n_settings`` with the loop's part filled.

    The loop's gains are designed at ``frequency_hz`` and ``damping_ratio`` (the
    locked mode's); ``position`` (0…1) places the record in its campaign for the drift.
    """
    gains = controller.gains(frequency_hz, damping_ratio)
    omega_initial = 2 * math.pi * (controller.initial_frequency_hz or frequency_hz)
    settings = np.zeros(n_settings)
    settings[DT], settings[N_SUB] = 1.0 / fs, n_sub
    settings[RAMP], settings[HOLD] = ramp_samples, hold_samples
    settings[KP], settings[KI] = gains.kp, gains.ki
    settings[STAGE_ALPHA] = -math.expm1(-gains.stage_bandwidth / fs)
    settings[ORDER] = controller.detector_order
    settings[BASE_REFERENCE] = 1.0 if controller.reference == "base" else 0.0
    # At phase resonance the relative velocity lags the base velocity by 90° and is
    # opposite to the coil's sin θ (it is in phase with −a_base).
    target = -0.5 * math.pi if controller.reference == "base" else math.pi
    settings[TARGET] = target + math.radians(controller.phase_offset_deg)
    settings[OMEGA_INITIAL] = omega_initial
    settings[OMEGA_LOW] = controller.frequency_limits[0] * omega_initial
    settings[OMEGA_HIGH] = controller.frequency_limits[1] * omega_initial
    settings[DELTA0], settings[DELTA1] = drift.frequency(position)
    settings[GAIN0], settings[GAIN1] = drift.gain(position)
    settings[GAIN_ON_PANEL] = 1.0 if drift.gain_channels == "panel" else 0.0
    settings[X_MAX] = _X_LIMIT
    return settings


@numba.njit(cache=True, inline="always")
def coil(amplitude, theta, distortion):
    """``A (sin θ + Σ d_k sin(kθ + ψ_k))``."""
    total = np.sin(theta)
    for h in range(distortion.shape[0]):
        total += distortion[h, 1] * np.sin(distortion[h, 0] * theta + distortion[h, 2])
    return amplitude * total


@numba.njit(cache=True, inline="always")
def _demodulate(filters, k, value, alpha):
    """One sample through the ``k``-th cascade of first-order low passes; its output."""
    for stage in range(filters.shape[1]):
        filters[k, stage] += alpha * (value - filters[k, stage])
        value = filters[k, stage]
    return value


@numba.njit(cache=True, inline="always")
def schedule(settings, coil_m_s2, k, n_total, a_from):
    """Where sample ``k`` stands in the fixed-time schedule of ``n_total`` samples.

    Returns ``(hold, in_hold, a_from, a_to, amplitude, fraction, panel_gain,
    base_gain)``: the hold approached or held and the sample within its ramp and
    hold, the ramp's end levels (``a_from`` carried from the last sample), the coil
    amplitude, the share of the run done (for the drift) and the gain drift on the
    panel and base channels.
    """
    ramp = int(settings[RAMP])
    per_hold = ramp + int(settings[HOLD])
    hold = k // per_hold
    in_hold = k - hold * per_hold
    if in_hold == 0 and hold > 0:
        a_from = coil_m_s2[hold - 1]
    a_to = coil_m_s2[hold]
    fraction = k / max(n_total - 1, 1)
    gain = settings[GAIN0] + (settings[GAIN1] - settings[GAIN0]) * fraction
    on_panel = settings[GAIN_ON_PANEL] > 0.0
    panel_gain = gain if on_panel else 1.0
    base_gain = 1.0 if on_panel else gain
    amplitude = ramp_level(a_from, a_to, in_hold, ramp)
    return hold, in_hold, a_from, a_to, amplitude, fraction, panel_gain, base_gain


@numba.njit(cache=True, inline="always")
def track(settings, filters, response, base, theta, hold, in_hold, control_on, integral, omega):
    """The phase detector and PI controller at one sample; ``(error, control_on, integral, ω)``.

    ``response`` and ``base`` are what the response and base channels deliver;
    ``filters`` the I and Q low-pass cascades of the response, then of the reference.
    The controller switches on at the first hold.
    """
    alpha = settings[STAGE_ALPHA]
    s, c = np.sin(theta), np.cos(theta)
    i_y = _demodulate(filters, 0, response * s, alpha)
    q_y = _demodulate(filters, 1, response * c, alpha)
    phase = np.arctan2(q_y, i_y)
    if settings[BASE_REFERENCE] > 0.0:
        i_r = _demodulate(filters, 2, base * s, alpha)
        q_r = _demodulate(filters, 3, base * c, alpha)
        phase -= np.arctan2(q_r, i_r)
    error = wrap_angle(phase - settings[TARGET])
    if in_hold == int(settings[RAMP]) and hold == 0:
        control_on = True
    if control_on:
        dt, omega_low, omega_high = settings[DT], settings[OMEGA_LOW], settings[OMEGA_HIGH]
        integral = min(max(integral + settings[KI] * error * dt, omega_low), omega_high)
        omega = min(max(integral + settings[KP] * error, omega_low), omega_high)
    return error, control_on, integral, omega


@numba.njit(cache=True, inline="always")
def record_loop(out, row, k, vb, a_base, omega, theta, amplitude, error):
    """The loop's channels (:data:`LOOP_CHANNELS`) of sample ``k``, from row ``row``."""
    out[row, k] = vb
    out[row + 1, k] = a_base
    out[row + 2, k] = omega / (2.0 * np.pi)
    out[row + 3, k] = theta
    out[row + 4, k] = amplitude
    out[row + 5, k] = np.degrees(error)
