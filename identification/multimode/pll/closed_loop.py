"""The PLL of a virtual phase-resonance test on a model of N modes, with multi-point sensors.

:func:`simulate_modal_pll` runs the one-mode PLL's loop
(:mod:`identification.analytical.pll.closed_loop`, whose conventions for phases,
detector, controller, level schedule and lock detection hold unchanged, and whose
:class:`~identification.analytical.pll.config.PLLConfig` sets the test) on a
:class:`~identification.multimode.model.ModalModel`; :func:`modal_pll_backbones`
runs it on many parameter sets on numba threads. The numba core is
:mod:`identification.multimode.pll.kernel`.

Conventions beyond the one-mode loop
------------------------------------
Excitation
    ``u(t) = A sin θ`` is the base acceleration (modal force ``−Γ_m u``), or, with
    ``drive`` given, a force (per unit modal mass) at a driving point whose shapes
    are ``drive`` (modal force ``drive_m u``).
Lock
    The loop locks the phase of the target mode's coordinate ``η_t`` (what a modal
    filter of the sensors gives; default) or of one sensor's response
    ``y_s = Σ_m φ_sm η_m`` (``lock_sensor``), at phase resonance of the target mode:
    ``η_t`` lags its modal force by 90°. A sensor lock also sees the other modes'
    fundamentals, so it holds a point slightly off the target mode's phase resonance.
Backbone point
    Over the measured periods: the target mode's fundamental amplitude ``|Q_t|``
    (m), the mean frequency, the damping ratio from the power balance of the target
    mode ``|w_t| |U| / (2 ω² |Q_t|)`` (``U`` the fundamental of ``u``; with one mode
    and ``Γ = 1`` the one-mode PLL's ``|Q_b| / (2|Q|)``), and every mode's Fourier
    coefficients ``[C0, C1, S1, C2, S2, C3, S3]`` in ``θ`` — the layout of
    :attr:`identification.multimode.solve.ModalSolution.coefficients`, whose
    phase-resonant backbone also has the target's fundamental at ``a cos θ``.
Sensors
    ``sensors`` is the mode-shape matrix at the sensors (sensors × modes); the
    recorded responses are ``y_s = Σ_m φ_sm η_m`` in the configured sensing
    (relative displacement, velocity or acceleration).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, fields

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.harmonic import CoefficientTable
from identification.analytical.pll import loop
from identification.analytical.pll.closed_loop import LoopBackbone, LoopSamples, backbone_result
from identification.analytical.pll.config import PLLConfig
from identification.analytical.pll.integrator import RK4_STABLE_STEP, linear_coefficients
from identification.analytical.pll.loop import (
    HARMONICS,
    N_RESULTS,
    OMEGA_INITIAL,
    REFERENCE,
    SENSING_INDEX,
    TARGET,
)
from identification.checks import positive_vector
from identification.multimode.balance import ModalArrays, modal_arrays
from identification.multimode.model import ModalModel
from identification.multimode.pll import kernel
from identification.multimode.pll.kernel import CHANNELS, N_COEFFICIENTS, PARTICIPATION_HARMONICS

__all__ = [
    "ModalPLLResult",
    "ModalPLLTimeSeries",
    "modal_pll_backbones",
    "simulate_modal_pll",
]


@dataclass(frozen=True, eq=False)
class ModalPLLTimeSeries(LoopSamples):
    """Samples of a virtual phase-resonance test of N modes (``fs`` Hz, SI units).

    The loop's channels (:class:`~identification.analytical.pll.closed_loop.LoopSamples`)
    and the modal state in place of the one relative coordinate: ``eta``,
    ``eta_dot``, ``eta_ddot`` are ``(N, n_samples)``; ``sensors`` is
    ``(n_sensors, n_samples)``, ``y_s = Σ_m φ_sm η_m`` in the configured sensing.
    ``base_acceleration`` is the excitation ``u`` (a force per unit modal mass when
    the test drives a point).
    """

    eta: np.ndarray
    eta_dot: np.ndarray
    eta_ddot: np.ndarray
    sensors: np.ndarray


@dataclass(frozen=True, eq=False)
class ModalPLLResult(LoopBackbone):
    """Backbone points of the target mode and every mode's participation, per hold.

    The loop's points (:class:`~identification.analytical.pll.closed_loop.LoopBackbone`)
    of the target mode: ``level`` is the excitation amplitude (m/s², or N/kg at a
    driving point), ``amplitude_m`` the fundamental amplitude of the target mode's
    coordinate ``|Q_t|`` (m), ``damping_ratio`` the power balance of the target mode
    ``|w_t| |U| / (2 ω² |Q_t|)``, ``phase_error_deg`` that of the locked signal.

    Attributes
    ----------
    mode
        The target mode (from 1).
    coefficients
        ``(…, N, 7)`` Fourier coefficients ``[C0, C1, S1, C2, S2, C3, S3]`` of every
        modal coordinate in the oscillator phase ``θ`` (m).
    time_series
        The samples (single runs with ``record=True``), else None.
    """

    mode: int
    coefficients: np.ndarray
    time_series: ModalPLLTimeSeries | None = field(default=None, repr=False)

    @property
    def participation_amplitude_m(self) -> np.ndarray:
        """``(…, N, 3)``: amplitude ``√(C_k² + S_k²)`` of every mode at harmonics k = 1–3 (m)."""
        return np.hypot(self.coefficients[..., 1::2], self.coefficients[..., 2::2])

    @property
    def participation_phase_deg(self) -> np.ndarray:
        """``(…, N, 3)``: phase of every mode's harmonic k against k × the target's fundamental.

        Harmonic k of mode m is ``|P| cos(kθ + φ)``; reported is ``φ − k φ_t1``
        (deg, wrapped to (−180, 180]), independent of the origin of ``θ``.
        """
        phase = np.arctan2(-self.coefficients[..., 2::2], self.coefficients[..., 1::2])
        target = phase[..., self.mode - 1, None, :1]
        orders = np.arange(1, PARTICIPATION_HARMONICS + 1)
        relative = phase - orders * target
        return np.degrees(np.angle(np.exp(1j * relative)))


# --------------------------------------------------------------------------
# Arrays for the kernel.


@dataclass(frozen=True)
class KernelArrays:
    """A model's arrays as the kernel takes them, leading axis the parameter set."""

    modal: np.ndarray  # (B, N, 3): ω², 2ζω, w
    shapes: np.ndarray  # (B, J, N)
    el_int: np.ndarray  # (E, 3): catalogue index, joint, hysteretic
    el_float: np.ndarray  # (B, E, 3): coefficient, p0, p1
    cp_int: np.ndarray  # (C, 1 + N): equation, powers
    cp_coef: np.ndarray  # (B, C)


def kernel_arrays(arrays: ModalArrays, drive: np.ndarray | None) -> KernelArrays:
    n_sets, n_modes = arrays.n_sets, arrays.n_modes
    modal = np.empty((n_sets, n_modes, 3))
    modal[..., 0] = arrays.omega**2
    modal[..., 1] = 2.0 * arrays.zeta * arrays.omega
    modal[..., 2] = -arrays.participation if drive is None else drive
    n_elements = len(arrays.effects)
    el_int = np.zeros((n_elements, 3), dtype=np.int64)
    el_float = np.zeros((n_sets, n_elements, 3))
    for e, effect in enumerate(arrays.effects):
        el_int[e] = effect.index, arrays.element_joints[e], int(effect.hysteretic)
        el_float[:, e, 0] = arrays.element_coefficients[:, e]
        el_float[:, e, 1:] = effect.shape_values(**arrays.element_shapes[e])
    cp_int = np.concatenate([arrays.coupling_modes[:, None], arrays.coupling_powers], axis=1)
    return KernelArrays(
        modal=modal,
        shapes=np.ascontiguousarray(arrays.joint_shapes),
        el_int=el_int,
        el_float=el_float,
        cp_int=np.ascontiguousarray(cp_int, dtype=np.int64),
        cp_coef=np.ascontiguousarray(arrays.coupling_coefficients),
    )


def linearisation(arrays: ModalArrays, k: KernelArrays):
    """Per-set stiffness matrix, damping matrix, friction-slope matrix and Jenkins bound at rest.

    Each element's small-amplitude stiffness, viscous damping and damping slope are
    the one-mode integrator's (:func:`~identification.analytical.pll.integrator.
    linear_coefficients` of that element alone), spread over the modes by
    ``φ_j φ_jᵀ``.
    """
    stiffness = np.zeros((arrays.n_sets, arrays.n_modes, arrays.n_modes))
    idx = np.arange(arrays.n_modes)
    stiffness[:, idx, idx] = k.modal[..., 0]
    damping = np.zeros_like(stiffness)
    damping[:, idx, idx] = k.modal[..., 1]
    slope = np.abs(damping)
    jenkins = np.zeros(arrays.n_sets)
    for e, effect in enumerate(arrays.effects):
        phi = arrays.joint_shapes[:, arrays.element_joints[e], :]
        outer = phi[:, :, None] * phi[:, None, :]
        c = k.el_float[:, e, 0]
        if effect.hysteretic:
            table = CoefficientTable(
                np.zeros(0, dtype=np.int64), np.zeros((arrays.n_sets, 0)),
                np.zeros((arrays.n_sets, 0, 2)), k.el_float[:, e], True,
            )  # fmt: skip
            jenkins += np.abs(c * k.el_float[:, e, 1]) * np.sum(phi**2, axis=1)
        else:
            table = CoefficientTable(
                np.array([effect.index]), c[:, None], k.el_float[:, e, None, 1:],
                np.zeros((arrays.n_sets, 3)), False,
            )  # fmt: skip
        k_e, d_e, s_e = linear_coefficients(table)
        stiffness += k_e[:, None, None] * outer
        damping += d_e[:, None, None] * outer
        slope += s_e[:, None, None] * outer
    return stiffness, damping, slope, jenkins


def modal_control(
    arrays: ModalArrays, k: KernelArrays, config: PLLConfig, target: int, what: str
) -> np.ndarray:
    """Per-set gains, frequency range and sub-steps, ``(n_sets, N_CONTROL)``.

    As the one-mode loop's: gains designed at the target mode's small-amplitude
    frequency and viscous damping (joint elements' linear parts included).
    """
    stiffness, damping, slope, jenkins = linearisation(arrays, k)
    # |λ|² ≤ ‖C‖|λ| + ‖K‖ for the linearisation λ²x + λCx + Kx = 0 (the one-mode bound
    # with matrix norms; the Jenkins spring counted once more, as there).
    norm_k = np.max(np.abs(np.linalg.eigvalsh(stiffness)), axis=1) + jenkins
    norm_c = np.max(np.abs(np.linalg.eigvalsh(slope)), axis=1)
    largest = 0.5 * norm_c + np.sqrt(0.25 * norm_c**2 + norm_k)
    n_sub = np.maximum(1, np.ceil(largest / config.fs / RK4_STABLE_STEP)).astype(np.int64)

    def too_stiff(n: int) -> str:
        return (
            f"model {what!r} needs {n} RK4 sub-steps per sample (more than "
            f"max_substeps = {config.max_substeps}) to stay stable: a friction coefficient "
            "over its v_reg or a Jenkins stiffness is too stiff; raise v_reg or fs"
        )

    return loop.control_vector(
        config, stiffness[:, target, target], damping[:, target, target], n_sub, too_stiff
    )


@dataclass(frozen=True)
class _Setup:
    """Everything a run needs besides the levels."""

    arrays: KernelArrays
    lock: np.ndarray
    target: int
    control: np.ndarray
    settings: np.ndarray
    sensors: np.ndarray


def _setup(
    model: ModalModel,
    mode: int,
    sensors: ArrayLike | None,
    lock_sensor: int | None,
    drive: ArrayLike | None,
    config: PLLConfig,
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
) -> _Setup:
    n = model.n_modes
    if isinstance(mode, bool) or not isinstance(mode, int | np.integer) or not 1 <= mode <= n:
        raise ValueError(f"mode must be an integer in 1..{n} (modes count from 1), got {mode!r}")
    target = int(mode) - 1
    shapes = np.eye(n) if sensors is None else np.asarray(sensors, dtype=float)
    if shapes.ndim != 2 or shapes.shape[1] != n or not np.all(np.isfinite(shapes)):
        raise ValueError(
            f"sensors must be a finite (n_sensors, {n}) mode-shape matrix, got shape {shapes.shape}"
        )
    if lock_sensor is None:
        lock = np.eye(n)[target]
    else:
        integer = isinstance(lock_sensor, int | np.integer) and not isinstance(lock_sensor, bool)
        if not integer or not 0 <= lock_sensor < len(shapes):
            raise ValueError(
                f"lock_sensor must be a sensor index in 0..{len(shapes) - 1}, got {lock_sensor!r}"
            )
        lock = shapes[lock_sensor].copy()
        if lock[target] == 0.0:
            raise ValueError(f"sensor {lock_sensor} does not see mode {mode} (its shape is 0)")
    if drive is not None:
        drive = np.asarray(drive, dtype=float)
        if drive.shape != (n,) or not np.all(np.isfinite(drive)):
            raise ValueError(f"drive must be the {n} finite shapes of the driving point")
    arrays = modal_arrays(model, parameters, names)
    k = kernel_arrays(arrays, drive)
    weight = k.modal[:, target, 2]
    if np.any(weight == 0.0):
        raise ValueError(f"mode {mode} is not excited (its modal excitation weight is 0)")
    if len(set(np.sign(weight))) > 1:
        raise ValueError(f"the sign of mode {mode}'s excitation weight differs between sets")
    control = modal_control(arrays, k, config, target, model.name or f"{n}-mode model")
    loop.check_timing(config, control)
    settings = loop.settings_vector(config)
    # The one-mode settings assume the modal force −u (base excitation, Γ = 1): where
    # the locked signal's target weight times the excitation weight is positive, the
    # force is in phase with u, 180° from that assumption.
    if lock[target] * weight[0] > 0:
        settings[TARGET] -= np.pi
        settings[REFERENCE] -= np.pi
    return _Setup(k, lock, target, control, settings, shapes)


def _result(mode: int, excitation: np.ndarray, out: np.ndarray, n_modes: int, series=None):
    """The loop's backbone points of the target mode, and every mode's coefficients."""
    points = backbone_result(excitation, out)
    coefficients = out[..., N_RESULTS:].reshape(*out.shape[:-1], n_modes, N_COEFFICIENTS)
    shared = {f.name: getattr(points, f.name) for f in fields(LoopBackbone)}
    return ModalPLLResult(**shared, mode=mode, coefficients=coefficients.copy(), time_series=series)


def simulate_modal_pll(
    model: ModalModel,
    excitation_m_s2: ArrayLike,
    *,
    mode: int = 1,
    sensors: ArrayLike | None = None,
    lock_sensor: int | None = None,
    drive: ArrayLike | None = None,
    config: PLLConfig | None = None,
    record: bool = False,
) -> ModalPLLResult:
    """Virtual phase-resonance test of ``mode`` of an N-mode model at stepped levels.

    Parameters
    ----------
    model
        The model (mass-normalised modal coordinates).
    excitation_m_s2
        Excitation amplitudes of the holds (base acceleration in m/s², or force
        per unit modal mass at the driving point), in test order, each > 0.
    mode
        The mode whose phase resonance the loop holds (from 1).
    sensors
        ``(n_sensors, N)`` mode shapes at the sensors; default the modal
        coordinates themselves (identity).
    lock_sensor
        Lock on this sensor's response (row of ``sensors``, from 0); default on
        the target mode's coordinate.
    drive
        ``(N,)`` shapes at a driving point: force excitation there instead of the base.
    config
        Test settings; default :class:`PLLConfig()`.
    record
        Keep the samples (:class:`ModalPLLTimeSeries`).
    """
    config = PLLConfig() if config is None else config
    excitation = positive_vector(excitation_m_s2, "excitation_m_s2")
    setup = _setup(model, mode, sensors, lock_sensor, drive, config)
    a = setup.arrays
    args = (a.modal[0], a.shapes[0], a.el_int, a.el_float[0], a.cp_int, a.cp_coef[0], setup.lock,
            setup.target, setup.control[0], setup.settings)  # fmt: skip
    n = model.n_modes
    out = np.empty((excitation.size, N_RESULTS + n * N_COEFFICIENTS))
    if not record:
        kernel.backbone(*args, excitation, out)
        return _result(mode, excitation, out, n)
    return _recorded_run(mode, args, setup, excitation, out, config.fs, n)


def _recorded_run(mode, args, setup, excitation, out, fs, n_modes) -> ModalPLLResult:
    """Level by level through the same kernel as :func:`kernel.backbone`, keeping the samples."""
    settings = setup.settings
    control = setup.control[0]
    run = None
    if control[OMEGA_INITIAL] > 0.0:
        state = kernel.initial_state(control[OMEGA_INITIAL], int(settings[HARMONICS]), n_modes,
                                     setup.arrays.el_int.shape[0])  # fmt: skip

        def run(a_from, a_to, buffer, row):
            kernel.run_level(*args, state, a_from, a_to, buffer, row)

    head = len(CHANNELS)
    recorded = loop.record_levels(run, excitation, out, head + 3 * n_modes, settings)
    samples = recorded.samples
    eta, eta_dot, eta_ddot = (samples[head + i * n_modes : head + (i + 1) * n_modes]
                              for i in range(3))  # fmt: skip
    sensed = (eta, eta_dot, eta_ddot)[int(settings[SENSING_INDEX])]
    series = ModalPLLTimeSeries(
        fs=fs,
        t=np.arange(samples.shape[1]) / fs,
        eta=eta,
        eta_dot=eta_dot,
        eta_ddot=eta_ddot,
        sensors=setup.sensors @ sensed,
        level_index=recorded.level_index,
        holds=recorded.holds,
        measurements=recorded.measurements,
        **dict(zip(CHANNELS, samples[:head], strict=True)),
    )
    return _result(mode, excitation, out, n_modes, series)


def modal_pll_backbones(
    model: ModalModel,
    excitation_m_s2: ArrayLike,
    parameters: ArrayLike,
    names: Sequence[str],
    *,
    mode: int = 1,
    sensors: ArrayLike | None = None,
    lock_sensor: int | None = None,
    drive: ArrayLike | None = None,
    config: PLLConfig | None = None,
) -> ModalPLLResult:
    """:func:`simulate_modal_pll` on many parameter sets of one model, on numba threads.

    ``parameters`` is ``(n_sets, len(names))`` with names from
    :attr:`ModalModel.parameter_names`; the other arguments are those of
    :func:`simulate_modal_pll`. Arrays of the result are ``(n_sets, n_levels)``, the
    same numbers as :func:`simulate_modal_pll` on each set.
    """
    config = PLLConfig() if config is None else config
    excitation = positive_vector(excitation_m_s2, "excitation_m_s2")
    setup = _setup(model, mode, sensors, lock_sensor, drive, config, parameters, names)
    a = setup.arrays
    n_sets, n = a.modal.shape[0], model.n_modes
    out = np.empty((n_sets, excitation.size, N_RESULTS + n * N_COEFFICIENTS))
    kernel.backbones_parallel(a.modal, a.shapes, a.el_int, a.el_float, a.cp_int, a.cp_coef,
                              setup.lock, setup.target, setup.control, setup.settings,
                              excitation, out)  # fmt: skip
    return _result(mode, excitation, out, n)
