"""Periodic solutions of a ModalModel by multi-harmonic balance: three problems, one solver.

All three balance the residual of :mod:`identification.multimode.balance`; they
differ in which entries of the state ``y = [Q, ω, ξ, A_c, A_s]`` are unknown:

``forced_response``
    The base-excited steady state at a given excitation frequency and level:
    every coefficient of every mode is unknown.
``phase_resonance``
    The backbone a phase-locked test holds on one mode: that mode's
    fundamental is prescribed as ``a cos θ`` and the base acceleration is the
    pure sine ``A sin θ`` (90° ahead of it); ``ω`` and ``A`` are unknown. With one
    mode this is the backbone of :func:`identification.analytical.harmonic.backbone`
    (``method="multi"``), and its damping ratio ``Γ A / (2 ω² a)`` the power balance.
``nonlinear_modes``
    Nonlinear modes by the extended periodic motion concept (Krack, M. 2015,
    "Nonlinear modal analysis of nonconservative systems: extension of the periodic
    motion concept", Computers & Structures 154, 59–71): no excitation, a negative
    viscous term ``−ξ η̇`` on every (unit-mass) mode makes the damped motion
    periodic; the mode's fundamental is prescribed as ``a cos θ`` (its amplitude
    sets the point on the branch, its zero sine part the phase), ``ω`` and ``ξ``
    are unknown, and ``ξ / (2ω)`` is the modal damping ratio. (NLvib prescribes a
    mass-weighted norm of the whole fundamental instead; prescribing one mode's
    fundamental keeps the amplitude a measurable modal amplitude.)

Newton's method runs batched over parameter sets with the Jacobian of
:func:`~identification.multimode.balance.evaluate`, unknowns scaled by their
typical size (amplitude, ω, ω² a); a set that converges is frozen, so an answer
does not depend on the rest of the batch. Amplitude grids are walked in order,
each amplitude starting from the previous one's solution (natural continuation);
:mod:`identification.multimode.continuation` follows a branch through turning
points.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from identification.checks import positive_vector
from identification.multimode.balance import (
    HarmonicGrid,
    ModalArrays,
    StateLayout,
    default_time_samples,
    evaluate,
    harmonic_grid,
    modal_arrays,
)
from identification.multimode.model import ModalModel

__all__ = [
    "HarmonicSettings",
    "ModalSolution",
    "energy_shares",
    "forced_response",
    "newton",
    "nonlinear_modes",
    "phase_resonance",
]


@dataclass(frozen=True)
class HarmonicSettings:
    """Settings of a multi-harmonic balance.

    Attributes
    ----------
    harmonics
        Highest harmonic ``H`` (harmonics ``0..H`` are balanced).
    n_time
        AFT samples per period; None: :func:`~identification.multimode.balance.
        default_time_samples`.
    tol
        Converged when every residual is below ``tol`` times the problem's scale
        (``ω² a`` for the backbones, ``|Γ A|`` for a forced response).
    max_iter
        Newton iterations per point.
    """

    harmonics: int = 5
    n_time: int | None = None
    tol: float = 1e-10
    max_iter: int = 50

    def grid(self, model: ModalModel) -> HarmonicGrid:
        n_time = self.n_time or default_time_samples(model, self.harmonics)
        return harmonic_grid(self.harmonics, n_time)


@dataclass(frozen=True)
class ModalSolution:
    """Periodic solutions, ``(n_sets, n_points)`` or ``(n_points,)`` for one model.

    Attributes
    ----------
    problem
        ``"forced_response"``, ``"phase_resonance"`` or ``"nonlinear_modes"``.
    mode
        The mode whose fundamental is prescribed (numbered from 1); None for a forced response.
    amplitude_m
        That mode's fundamental amplitude; a forced response gives mode 1's ``√(C₁² + S₁²)``.
    frequency_hz
        Fundamental frequency of the periodic solution (Hz).
    damping_ratio
        ``Γ A / (2 ω² a)`` (phase resonance), ``ξ / (2 ω)`` (nonlinear modes); NaN for a
        forced response.
    base_acceleration
        ``(…, 2)``: ``A_c, A_s`` of the base acceleration ``A_c cos kθ + A_s sin kθ`` (m/s²).
    coefficients
        ``(…, N, 2H+1)`` modal Fourier coefficients ``[C0, C1, S1, …, CH, SH]``.
    energy_share
        ``(…, N)``: each mode's share of the period-averaged linear modal energy
        (:func:`energy_shares`).
    converged
        False where Newton did not converge; the numbers there are NaN.
    harmonics, n_time
        Highest harmonic and AFT samples of the balance.
    """

    problem: str
    mode: int | None
    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    base_acceleration: np.ndarray
    coefficients: np.ndarray
    energy_share: np.ndarray
    converged: np.ndarray
    harmonics: int
    n_time: int


def energy_shares(
    coefficients: np.ndarray, omega: np.ndarray, modal_omega: np.ndarray
) -> np.ndarray:
    """Each mode's share of ``Σ_m E_m``, ``E_m = ⟨½ η̇_m² + ½ ω_m² η_m²⟩`` over a period.

    Parameters
    ----------
    coefficients
        ``(…, N, 2H+1)`` modal Fourier coefficients.
    omega
        ``(…)`` fundamental angular frequency (rad/s).
    modal_omega
        ``(…, N)`` linear angular frequencies of the modes.
    """
    n_harmonics = (coefficients.shape[-1] - 1) // 2
    orders = np.arange(1, n_harmonics + 1)
    power = coefficients[..., 1::2] ** 2 + coefficients[..., 2::2] ** 2  # (…, N, H)
    w = np.asarray(omega)[..., None, None] * orders
    energy = 0.25 * np.sum((w**2 + modal_omega[..., None] ** 2) * power, axis=-1)
    energy += 0.5 * modal_omega**2 * coefficients[..., 0] ** 2
    total = np.sum(energy, axis=-1, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return energy / total


# --------------------------------------------------------------------------
# Newton's method, batched over parameter sets.


def newton(
    arrays: ModalArrays,
    grid: HarmonicGrid,
    y: np.ndarray,
    free: np.ndarray,
    residual_scale: np.ndarray,
    unknown_scale: np.ndarray,
    *,
    forcing_harmonic: int = 1,
    tol: float = 1e-10,
    max_iter: int = 50,
) -> tuple[np.ndarray, np.ndarray]:
    """Solve the balance for the entries ``free`` of ``y`` (``(B, n_state)``, updated in place).

    ``residual_scale`` (``(B,)``) sets the convergence test ``max |R| ≤ tol · scale``;
    ``unknown_scale`` (``(B, n_free)``) the typical size of each unknown (column
    scaling of the Newton step). A step never takes away more than half of ``ω``.
    Returns ``y`` and the ``(B,)`` convergence flags.
    """
    layout = StateLayout(arrays.n_modes, grid.size)
    active = np.ones(y.shape[0], dtype=bool)
    converged = np.zeros(y.shape[0], dtype=bool)
    omega_column = np.flatnonzero(free == layout.omega)
    for iteration in range(max_iter + 1):
        sets = np.flatnonzero(active)
        if sets.size == 0:
            break
        residual, jacobian = evaluate(arrays.take(sets), grid, y[sets], forcing_harmonic)
        with np.errstate(invalid="ignore"):
            worst = np.max(np.abs(residual), axis=1) / residual_scale[sets]
        done = worst <= tol
        failed = ~np.isfinite(worst)
        converged[sets[done]] = True
        active[sets[done | failed]] = False
        going = ~(done | failed)
        if iteration == max_iter or not going.any():
            break
        sets = sets[going]
        scale = unknown_scale[sets]
        step, solved = _solve(jacobian[going][:, :, free] * scale[:, None, :], -residual[going])
        active[sets[~solved]] = False
        step = step * scale
        if omega_column.size:
            omega = y[sets, layout.omega]
            d_omega = step[:, omega_column[0]]
            step *= np.minimum(1.0, 0.5 * omega / np.maximum(-d_omega, 1e-300))[:, None]
        y[np.ix_(sets[solved], free)] += step[solved]
    return y, converged


def _solve(matrix: np.ndarray, rhs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched ``matrix · z = rhs``; a singular case gives NaN and False (not an abort)."""
    try:
        return np.linalg.solve(matrix, rhs[..., None])[..., 0], np.ones(rhs.shape[0], dtype=bool)
    except np.linalg.LinAlgError:
        out = np.full_like(rhs, np.nan)
        ok = np.zeros(rhs.shape[0], dtype=bool)
        for b in range(rhs.shape[0]):
            try:
                out[b] = np.linalg.solve(matrix[b], rhs[b])
                ok[b] = np.isfinite(out[b]).all()
            except np.linalg.LinAlgError:
                pass
        return out, ok


# --------------------------------------------------------------------------
# The problems.


#: Sub-steps tried, in turn, where a step along the amplitudes fails.
_REFINEMENTS = (4, 16)


def _mode_index(model: ModalModel, mode: int) -> int:
    if isinstance(mode, bool) or not isinstance(mode, int | np.integer):
        raise ValueError(f"mode must be an integer, got {mode!r}")
    if not 1 <= mode <= model.n_modes:
        raise ValueError(f"mode must be 1..{model.n_modes} (modes count from 1), got {mode}")
    return int(mode) - 1


def _backbone_problem(
    model: ModalModel,
    amplitudes_m: ArrayLike,
    mode: int,
    unknown: int,
    problem: str,
    settings: HarmonicSettings,
    parameters: ArrayLike | None,
    names: Sequence[str] | None,
) -> ModalSolution:
    """Walk the amplitudes of a backbone problem (``unknown``: the extra unknown's column)."""
    a = positive_vector(amplitudes_m, "amplitudes_m")
    target = _mode_index(model, mode)
    arrays = modal_arrays(model, parameters, names)
    grid = settings.grid(model)
    layout = StateLayout(model.n_modes, grid.size)
    fundamental = (layout.coefficient(target, 1), layout.coefficient(target, 2))
    free = np.array(
        [i for i in range(layout.n_coefficients) if i not in fundamental] + [layout.omega, unknown]
    )
    if unknown == layout.forcing_sin and np.any(arrays.participation[:, target] == 0):
        raise ValueError(
            f"mode {mode} has no base participation: no phase-resonant forcing holds it"
        )
    n_sets = arrays.n_sets
    w_t = arrays.omega[:, target]
    # Linear start: the mode alone at its linear frequency, with its linear damping.
    y = np.zeros((n_sets, layout.n_state))
    y[:, layout.omega] = w_t
    linear_damping = 2.0 * arrays.zeta[:, target] * w_t
    if unknown == layout.xi:
        y[:, layout.xi] = linear_damping
    else:
        y[:, layout.forcing_sin] = linear_damping * w_t / arrays.participation[:, target]

    def solve_at(sets: np.ndarray, start: np.ndarray, amplitude: np.ndarray):
        """Newton for the sets ``sets`` at their amplitudes, from ``start`` (updated)."""
        start[:, fundamental[0]] = amplitude
        start[:, fundamental[1]] = 0.0
        unknown_scale = np.repeat(amplitude[:, None], free.size, axis=1)
        unknown_scale[:, -2] = w_t[sets]
        unknown_scale[:, -1] = w_t[sets] * (1.0 if unknown == layout.xi else w_t[sets] * amplitude)
        return newton(
            arrays.take(sets), grid, start, free, w_t[sets] ** 2 * amplitude, unknown_scale,
            tol=settings.tol, max_iter=settings.max_iter,
        )  # fmt: skip

    out = np.full((n_sets, a.size, layout.n_state), np.nan)
    converged = np.zeros((n_sets, a.size), dtype=bool)
    every = np.arange(n_sets)
    previous_a = np.full(n_sets, a[0])
    # The converged state before the last one, per set (NaN: none yet).
    earlier = np.full_like(y, np.nan)
    earlier_a = np.full(n_sets, np.nan)
    for i, amplitude in enumerate(a):
        # Predictor: the secant through the last two solutions where there are two,
        # else the last solution scaled to the new amplitude.
        start = y.copy()
        start[:, : layout.n_coefficients] *= (amplitude / previous_a)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            secant = (
                y + (y - earlier) * ((amplitude - previous_a) / (previous_a - earlier_a))[:, None]
            )
        has_secant = np.isfinite(secant).all(axis=1)
        start[has_secant] = secant[has_secant]
        solved, ok = solve_at(every, start, np.full(n_sets, amplitude))
        # Where the step failed (a branch bending at an internal resonance), walk from
        # the last solution in smaller steps.
        retry = np.flatnonzero(~ok)
        for pieces in _REFINEMENTS:
            if retry.size == 0:
                break
            state, alive = y[retry].copy(), np.ones(retry.size, dtype=bool)
            steps = previous_a[retry, None] + np.outer(amplitude - previous_a[retry],
                                                       np.arange(pieces + 1) / pieces)  # fmt: skip
            for j in range(1, pieces + 1):
                live = np.flatnonzero(alive)
                state[live, : layout.n_coefficients] *= (steps[live, j] / steps[live, j - 1])[
                    :, None
                ]
                state[live], alive[live] = solve_at(retry[live], state[live], steps[live, j])
            solved[retry[alive]], ok[retry[alive]] = state[alive], True
            retry = retry[~alive]
        out[ok, i] = solved[ok]
        converged[:, i] = ok
        earlier[ok] = y[ok]
        earlier_a[ok] = previous_a[ok]
        earlier_a[ok & (i == 0)] = np.nan
        y[ok] = solved[ok]
        previous_a[ok] = amplitude
    return _solution(problem, mode, arrays, grid, out, converged, a, parameters is None)


def _solution(
    problem: str,
    mode: int | None,
    arrays: ModalArrays,
    grid: HarmonicGrid,
    y: np.ndarray,
    converged: np.ndarray,
    amplitude: np.ndarray | None,
    squeeze: bool,
) -> ModalSolution:
    """The :class:`ModalSolution` of solved states ``y`` ``(n_sets, n_points, n_state)``."""
    layout = StateLayout(arrays.n_modes, grid.size)
    y = np.where(converged[..., None], y, np.nan)
    coefficients = y[..., : layout.n_coefficients].reshape(*y.shape[:2], arrays.n_modes, grid.size)
    omega = y[..., layout.omega]
    base = y[..., [layout.forcing_cos, layout.forcing_sin]]
    if amplitude is None:
        amplitude = np.hypot(coefficients[..., 0, 1], coefficients[..., 0, 2])
    else:
        amplitude = np.broadcast_to(amplitude, omega.shape)
    if problem == "nonlinear_modes":
        damping = y[..., layout.xi] / (2.0 * omega)
    elif problem == "phase_resonance":
        target = arrays.participation[:, mode - 1, None]
        damping = target * base[..., 1] / (2.0 * omega**2 * amplitude)
    else:
        damping = np.full(omega.shape, np.nan)
    share = energy_shares(coefficients, omega, arrays.omega[:, None, :])
    pick = (lambda z: z[0]) if squeeze else (lambda z: z)
    return ModalSolution(
        problem=problem,
        mode=mode,
        amplitude_m=pick(np.asarray(amplitude)),
        frequency_hz=pick(omega / (2.0 * np.pi)),
        damping_ratio=pick(damping),
        base_acceleration=pick(base),
        coefficients=pick(coefficients),
        energy_share=pick(share),
        converged=pick(converged),
        harmonics=grid.harmonics,
        n_time=grid.n_time,
    )


def phase_resonance(
    model: ModalModel,
    amplitudes_m: ArrayLike,
    *,
    mode: int = 1,
    settings: HarmonicSettings = HarmonicSettings(),
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
) -> ModalSolution:
    """Phase-resonant backbone of ``mode``: its fundamental ``a cos θ``, base ``A sin θ``.

    Parameters
    ----------
    model
        The model (template when ``parameters`` is given).
    amplitudes_m
        Fundamental amplitudes of the mode's coordinate, 1-D, > 0, walked in order.
    mode
        The mode held at phase resonance (from 1).
    settings
        Harmonics, samples and Newton settings.
    parameters, names
        Optional ``(n_sets, len(names))`` overrides (:attr:`ModalModel.parameter_names`).
    """
    layout = StateLayout(model.n_modes, 2 * settings.harmonics + 1)
    return _backbone_problem(model, amplitudes_m, mode, layout.forcing_sin, "phase_resonance",
                             settings, parameters, names)  # fmt: skip


def nonlinear_modes(
    model: ModalModel,
    amplitudes_m: ArrayLike,
    *,
    mode: int = 1,
    settings: HarmonicSettings = HarmonicSettings(),
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
) -> ModalSolution:
    """Nonlinear mode ``mode`` by the extended periodic motion concept, at the given amplitudes.

    The mode's fundamental is ``a cos θ``; ``ω`` and the negative damping ``ξ`` are
    solved for; ``damping_ratio = ξ / (2ω)``. Amplitudes are walked in order by
    natural continuation; use :func:`~identification.multimode.continuation.
    continue_nonlinear_mode` to follow a branch through an internal resonance.
    Parameters as :func:`phase_resonance`.
    """
    layout = StateLayout(model.n_modes, 2 * settings.harmonics + 1)
    return _backbone_problem(model, amplitudes_m, mode, layout.xi, "nonlinear_modes", settings,
                             parameters, names)  # fmt: skip


def forced_response(
    model: ModalModel,
    excitation_frequency_hz: ArrayLike,
    base_acceleration_m_s2: ArrayLike,
    *,
    forcing_harmonic: int = 1,
    start: ArrayLike | None = None,
    settings: HarmonicSettings = HarmonicSettings(),
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
) -> ModalSolution:
    """Steady state under the base acceleration ``A cos Ωt`` at each excitation frequency.

    Parameters
    ----------
    model
        The model (template when ``parameters`` is given).
    excitation_frequency_hz
        ``Ω / 2π``, 1-D, > 0, walked in order (each point starts from the last).
    base_acceleration_m_s2
        ``A`` (m/s²), scalar or one per frequency.
    forcing_harmonic
        ``k``: the excitation is harmonic ``k`` of the balance, whose fundamental is
        ``Ω / k`` (``k = 2`` admits the response at half the excitation frequency
        of a 1:2 internal resonance).
    start
        ``(N, 2H+1)`` modal coefficients to start the first point from (a branch
        other than the one Newton finds from rest); None: from rest.
    settings, parameters, names
        As :func:`phase_resonance`.
    """
    frequency = positive_vector(excitation_frequency_hz, "excitation_frequency_hz")
    level = np.broadcast_to(np.asarray(base_acceleration_m_s2, dtype=float), frequency.shape)
    if not np.all(np.isfinite(level)) or np.any(level == 0):
        raise ValueError("base_acceleration_m_s2 must be finite and non-zero")
    if (
        not isinstance(forcing_harmonic, int | np.integer)
        or not 1 <= forcing_harmonic <= settings.harmonics
    ):
        raise ValueError(
            f"forcing_harmonic must be an integer in 1..harmonics ({settings.harmonics}), "
            f"got {forcing_harmonic!r}"
        )
    arrays = modal_arrays(model, parameters, names)
    grid = settings.grid(model)
    layout = StateLayout(model.n_modes, grid.size)
    n_sets = arrays.n_sets
    y = np.zeros((n_sets, layout.n_state))
    if start is not None:
        start = np.asarray(start, dtype=float)
        if start.shape != (model.n_modes, grid.size):
            raise ValueError(
                f"start must have shape ({model.n_modes}, {grid.size}), got {start.shape}"
            )
        y[:, : layout.n_coefficients] = start.ravel()
    free = np.arange(layout.n_coefficients)
    out = np.full((n_sets, frequency.size, layout.n_state), np.nan)
    converged = np.zeros((n_sets, frequency.size), dtype=bool)
    for i, (f, level_i) in enumerate(zip(frequency, level, strict=True)):
        start_i = y.copy()
        start_i[:, layout.omega] = 2.0 * np.pi * f / forcing_harmonic
        start_i[:, layout.forcing_cos] = level_i
        scale = np.abs(level_i) * np.max(np.abs(arrays.participation), axis=1)
        typical = np.abs(level_i) / np.min(arrays.omega, axis=1) ** 2
        unknown_scale = np.repeat(typical[:, None], free.size, axis=1)
        solved, ok = newton(
            arrays, grid, start_i, free, scale, unknown_scale, forcing_harmonic=forcing_harmonic,
            tol=settings.tol, max_iter=settings.max_iter,
        )  # fmt: skip
        out[ok, i] = solved[ok]
        converged[:, i] = ok
        y[ok] = solved[ok]
    return _solution(
        "forced_response", None, arrays, grid, out, converged, None, parameters is None
    )
