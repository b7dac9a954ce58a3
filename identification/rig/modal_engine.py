"""The two-mode lab rig's test engine: the lab's PLL around the N-mode PLL simulator's integrator.

The structure is a :class:`~identification.multimode.model.ModalModel`, advanced by
the N-mode PLL simulator's modal equations and RK4 step
(:func:`identification.multimode.pll.kernel.accelerations` and ``advance``: joint
elements on joint coordinates built from the modes, polynomial modal couplings,
Jenkins anchors moved after each sub-step). Around it runs the lab rig's loop
(:mod:`identification.rig.lab`, whose conventions hold unchanged): the base
acceleration ``a_base = a_coil − ω_c v_base`` with the distorted coil acceleration
``A(t)(sin θ + Σ d_k sin(kθ + ψ_k))``, a multiply-and-low-pass phase detector on
what the sensors deliver (noise and gain drift included) behind a PI controller,
the natural-frequency drift (every mode's stiffness times ``(1 + δ(t))²``), the
phase offset of an uncompensated sensing chain.

The controller's response channel is a weighted sum of panel channels minus the
same weight of the base channel: the centre point for the bending mode (as on the
one-mode rig), the difference of two side points for a torsion mode (the bending
mode and the base cancel there, as a lab's modal lock would make them).

The shaker-structure interaction of the one-mode lab rig (the structure's restoring
force pushing the armature back) is not modelled here: with several modes it is a
sum over modes weighted by their participation, left out rather than guessed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from identification.analytical.pll import loop as pll_loop
from identification.analytical.pll.config import PLLConfig
from identification.multimode.balance import modal_arrays
from identification.multimode.model import ModalModel
from identification.multimode.pll.closed_loop import kernel_arrays, modal_control
from identification.multimode.pll.kernel import ACC, N_WORK, V, X, accelerations, advance
from identification.rig import lab_loop
from identification.rig.conditions import Controller, Drift, Shaker

__all__ = ["ModalLabSeries", "free_decay", "run_modal_lab"]

# Settings vector of the kernel: the loop's, then the shaker's centring and the response
# channel's base weight.
_CENTRING, _WEIGHT_SUM, _N_SETTINGS = range(lab_loop.N_LOOP_SETTINGS, lab_loop.N_LOOP_SETTINGS + 3)
#: Channels recorded besides the modal coordinates and velocities (then η, η̇ of every mode).
CHANNELS = lab_loop.LOOP_CHANNELS


@dataclass(frozen=True, eq=False)
class ModalLabSeries(lab_loop.LabChannels):
    """The engine's true signals of one record: the loop's
    (:class:`~identification.rig.lab_loop.LabChannels`) and ``eta``, ``eta_dot``, the
    ``(N, n)`` modal coordinates and velocities.
    """

    eta: np.ndarray
    eta_dot: np.ndarray


@numba.njit(cache=True)
def _modal_lab_kernel(modal0, shapes, el_int, el_float, cp_int, cp_coef, weights, distortion,
                      coil_m_s2, settings, sensed, out):  # fmt: skip
    """Run the whole schedule; fills ``out`` and returns the samples done.

    ``weights`` (N,) are the modal velocities' weights in the controller's response
    channel, ``sensed`` (2, n) the noise that channel and the base channel carry.
    """
    dt = settings[lab_loop.DT]
    n_sub = int(settings[lab_loop.N_SUB])
    ramp = int(settings[lab_loop.RAMP])
    delta0, delta1 = settings[lab_loop.DELTA0], settings[lab_loop.DELTA1]
    x_max, centring, weight_sum = (
        settings[lab_loop.X_MAX],
        settings[_CENTRING],
        settings[_WEIGHT_SUM],
    )
    n = modal0.shape[0]
    n_channels = len(CHANNELS)
    modal = modal0.copy()
    work = np.zeros((N_WORK, n))
    xa = np.zeros(el_int.shape[0])
    fa = np.zeros(el_int.shape[0])
    forcing = np.empty(3)
    filters = np.zeros((4, int(settings[lab_loop.ORDER])))
    vb = 0.0
    theta = 0.0
    omega = settings[lab_loop.OMEGA_INITIAL]
    integral = omega
    control_on = False
    a_from = 0.0
    h = dt / n_sub
    n_total = out.shape[1]
    for k in range(n_total):
        hold, in_hold, a_from, a_to, amplitude, fraction, panel_gain, base_gain = lab_loop.schedule(
            settings, coil_m_s2, k, n_total, a_from
        )
        stiffening = (1.0 + delta0 + (delta1 - delta0) * fraction) ** 2
        for m in range(n):
            modal[m, 0] = modal0[m, 0] * stiffening
        a_base = lab_loop.coil(amplitude, theta, distortion) - centring * vb
        accelerations(modal, shapes, el_int, el_float, cp_int, cp_coef, work, X, V, xa, fa,
                       a_base, ACC)  # fmt: skip
        relative = 0.0
        for m in range(n):
            if not (abs(work[X, m]) <= x_max and np.isfinite(work[ACC, m])):
                return k
            relative += weights[m] * work[V, m]

        # What the sensors deliver to the controller.
        base = base_gain * vb + sensed[1, k]
        response = panel_gain * (relative + weight_sum * vb) + sensed[0, k] - weight_sum * base
        error, control_on, integral, omega = lab_loop.track(
            settings, filters, response, base, theta, hold, in_hold, control_on, integral, omega
        )

        lab_loop.record_loop(out, 0, k, vb, a_base, omega, theta, amplitude, error)
        for m in range(n):
            out[n_channels + m, k] = work[X, m]
            out[n_channels + n + m, k] = work[V, m]

        # One RK4 sub-step at a time: the base velocity (centred) is a state of its own,
        # so the modal equations' excitation at each stage is its stage derivative.
        for j in range(n_sub):
            coils = np.empty(3)
            for i in range(3):
                part = (j + 0.5 * i) / n_sub
                level = lab_loop.ramp_level(a_from, a_to, in_hold + part, ramp)
                coils[i] = lab_loop.coil(level, theta + omega * dt * part, distortion)
            k1 = coils[0] - centring * vb
            k2 = coils[1] - centring * (vb + 0.5 * h * k1)
            k3 = coils[1] - centring * (vb + 0.5 * h * k2)
            k4 = coils[2] - centring * (vb + h * k3)
            if j > 0:
                accelerations(modal, shapes, el_int, el_float, cp_int, cp_coef, work, X, V,
                               xa, fa, k1, ACC)  # fmt: skip
            forcing[0], forcing[1], forcing[2] = k1, 0.5 * (k2 + k3), k4
            advance(modal, shapes, el_int, el_float, cp_int, cp_coef, work, xa, fa, h, forcing)
            vb += h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
        theta += omega * dt
    return n_total


def _structure(model: ModalModel, fs: float):
    """The kernel's arrays of one model and its RK4 sub-steps per sample."""
    arrays = modal_arrays(model)
    k = kernel_arrays(arrays, None)
    control = modal_control(arrays, k, PLLConfig(fs=fs), 0, model.name or "modal rig")
    return k, int(control[0, pll_loop.N_SUB])


def run_modal_lab(
    model: ModalModel,
    coil_m_s2: np.ndarray,
    *,
    fs: float,
    ramp_samples: int,
    hold_samples: int,
    response_weights: np.ndarray,
    weight_sum: float,
    target_frequency_hz: float,
    target_damping_ratio: float,
    shaker: Shaker,
    controller: Controller,
    drift: Drift,
    position: float,
    sensed: np.ndarray,
) -> ModalLabSeries:
    """Simulate a stepped-level PLL test of ``model`` in the lab (see the module notes).

    ``coil_m_s2`` are the coil-acceleration amplitudes of the holds,
    ``response_weights`` the modal weights of the controller's response channel
    (panel sensors' weights times their shapes) and ``weight_sum`` the sum of the
    panel sensors' weights (the base they carry), ``sensed`` the ``(2, n)`` noise of
    that channel and of the base channel; ``position`` (0…1) places the record in
    its campaign for the drift. The loop's gains are designed at the locked mode's
    ``target_frequency_hz`` and ``target_damping_ratio``.
    """
    k, n_sub = _structure(model, fs)
    n = len(coil_m_s2) * (ramp_samples + hold_samples)
    settings = lab_loop.loop_settings(
        _N_SETTINGS, fs=fs, n_sub=n_sub, ramp_samples=ramp_samples, hold_samples=hold_samples,
        controller=controller, frequency_hz=target_frequency_hz,
        damping_ratio=target_damping_ratio, drift=drift, position=position,
    )  # fmt: skip
    settings[_CENTRING] = 2 * math.pi * shaker.centring_hz
    settings[_WEIGHT_SUM] = weight_sum
    n_modes = model.n_modes
    out = np.full((len(CHANNELS) + 2 * n_modes, n), np.nan)
    done = _modal_lab_kernel(
        k.modal[0], k.shapes[0], k.el_int, k.el_float[0], k.cp_int, k.cp_coef[0],
        np.ascontiguousarray(response_weights, dtype=float), shaker.harmonics_table(),
        np.asarray(coil_m_s2, dtype=float), settings, np.ascontiguousarray(sensed, dtype=float),
        out,
    )  # fmt: skip
    head = len(CHANNELS)
    return ModalLabSeries(
        fs, done == n, eta=out[head : head + n_modes], eta_dot=out[head + n_modes :],
        **dict(zip(CHANNELS, out[:head], strict=True)),
    )  # fmt: skip


@numba.njit(cache=True)
def _decay_kernel(modal, shapes, el_int, el_float, cp_int, cp_coef, n_sub, dt, out):
    """Free motion from the state in ``out[:, 0]`` (η then η̇); fills the rest of ``out``."""
    n = modal.shape[0]
    work = np.zeros((N_WORK, n))
    xa = np.zeros(el_int.shape[0])
    fa = np.zeros(el_int.shape[0])
    forcing = np.zeros(3)
    for m in range(n):
        work[X, m] = out[m, 0]
        work[V, m] = out[n + m, 0]
    h = dt / n_sub
    for k in range(1, out.shape[1]):
        for _ in range(n_sub):
            accelerations(modal, shapes, el_int, el_float, cp_int, cp_coef, work, X, V, xa, fa,
                           0.0, ACC)  # fmt: skip
            advance(modal, shapes, el_int, el_float, cp_int, cp_coef, work, xa, fa, h, forcing)
        for m in range(n):
            out[m, k] = work[X, m]
            out[n + m, k] = work[V, m]


def free_decay(
    model: ModalModel, eta0_m: np.ndarray, eta_dot0_m_s: np.ndarray, fs: float, n_samples: int
) -> tuple[np.ndarray, np.ndarray]:
    """Free motion of ``model`` from modal displacements and velocities ``(η, η̇)``, each (N, n).

    The N-mode PLL simulator's integrator with no excitation; hysteretic elements
    start unstressed at the initial state.
    """
    k, n_sub = _structure(model, fs)
    out = np.zeros((2 * model.n_modes, n_samples))
    out[:, 0] = np.concatenate([eta0_m, eta_dot0_m_s])
    _decay_kernel(k.modal[0], k.shapes[0], k.el_int, k.el_float[0], k.cp_int, k.cp_coef[0],
                  n_sub, 1.0 / fs, out)  # fmt: skip
    return out[: model.n_modes], out[model.n_modes :]
