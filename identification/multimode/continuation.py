"""A nonlinear mode followed along amplitude, and the internal resonances on the way.

Pseudo-arclength continuation of the extended-periodic-motion-concept balance
(:func:`~identification.multimode.solve.nonlinear_modes`) of one parameter set:
the prescribed amplitude ``a`` of the mode's fundamental joins ``ω``, ``ξ`` and
the other coefficients as unknowns, and the arclength condition closes the
system, so the branch is followed through the turning points an internal
resonance puts in it (where natural continuation in ``a`` stops).

An internal resonance shows as another mode's harmonic content growing: where a
mode other than the followed one takes more than ``share_threshold`` of the
period-averaged linear modal energy (:func:`~identification.multimode.solve.
energy_shares`), the branch reports an :class:`InternalResonance` naming the
mode, its dominant harmonic of the fundamental (``2`` for a 1:2 resonance,
``3`` for 1:3), the amplitude and frequency where it set in and its largest
share on the branch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from identification.multimode.balance import StateLayout, evaluate, modal_arrays
from identification.multimode.model import ModalModel
from identification.multimode.solve import HarmonicSettings, energy_shares, nonlinear_modes

__all__ = ["ContinuationSettings", "InternalResonance", "ModeBranch", "continue_nonlinear_mode"]


@dataclass(frozen=True)
class ContinuationSettings:
    """Step control of the pseudo-arclength continuation.

    Attributes
    ----------
    step
        First step, in units of the scaled unknowns (coefficients over the end
        amplitude, ω and ξ over the linear ω of the mode).
    min_step, max_step
        Bounds of the adapted step; the continuation stops below ``min_step``.
    max_points
        Most points on the branch.
    max_iter, tol
        Corrector iterations per point, and its convergence threshold
        (residual over ``ω² a``).
    share_threshold
        Energy share of another mode that flags an internal resonance.
    """

    step: float = 0.01
    min_step: float = 1e-7
    max_step: float = 0.05
    max_points: int = 2000
    max_iter: int = 12
    tol: float = 1e-10
    share_threshold: float = 0.05

    def __post_init__(self) -> None:
        if not 0 < self.min_step <= self.step <= self.max_step:
            raise ValueError("steps must satisfy 0 < min_step ≤ step ≤ max_step")
        if not 0 < self.share_threshold < 1:
            raise ValueError(f"share_threshold must be in (0, 1), got {self.share_threshold}")


@dataclass(frozen=True)
class InternalResonance:
    """Where another mode's content grows on a nonlinear-mode branch.

    Attributes
    ----------
    mode
        The mode that takes energy (numbered from 1).
    harmonic
        Its dominant harmonic of the branch's fundamental (``k`` of a ``1:k`` resonance).
    amplitude_m, frequency_hz
        Amplitude of the followed mode's fundamental and frequency where its share
        first exceeds the threshold.
    point
        Index of that point on the branch.
    peak_share
        The mode's largest energy share on the branch.
    """

    mode: int
    harmonic: int
    amplitude_m: float
    frequency_hz: float
    point: int
    peak_share: float

    def describe(self) -> str:
        """One line a report can print."""
        return (
            f"internal resonance: mode {self.mode} through harmonic {self.harmonic} "
            f"(1:{self.harmonic}) from amplitude {self.amplitude_m:.4g} at "
            f"{self.frequency_hz:.6g} Hz, up to {100 * self.peak_share:.3g} % of the energy"
        )


@dataclass(frozen=True)
class ModeBranch:
    """A nonlinear-mode branch: one entry per point, in continuation order.

    Attributes
    ----------
    mode
        The followed mode (from 1).
    amplitude_m, frequency_hz, damping_ratio
        Its fundamental amplitude, the frequency and ``ξ / (2ω)`` per point.
    coefficients
        ``(n_points, N, 2H+1)`` modal Fourier coefficients.
    energy_share
        ``(n_points, N)`` energy shares of the modes.
    turning_points
        Indices of the points where the amplitude turns back.
    internal_resonances
        What :class:`InternalResonance` records the branch found.
    stopped
        Why the continuation ended: ``"end amplitude"``, ``"step too small"``,
        ``"max points"`` or ``"amplitude below start"``.
    """

    mode: int
    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    coefficients: np.ndarray
    energy_share: np.ndarray
    turning_points: tuple[int, ...]
    internal_resonances: tuple[InternalResonance, ...]
    stopped: str


def continue_nonlinear_mode(
    model: ModalModel,
    start_amplitude_m: float,
    end_amplitude_m: float,
    *,
    mode: int = 1,
    settings: HarmonicSettings | None = None,
    continuation: ContinuationSettings | None = None,
) -> ModeBranch:
    """Follow nonlinear mode ``mode`` from ``start_amplitude_m`` until ``end_amplitude_m``.

    Parameters
    ----------
    model
        The model (one parameter set).
    start_amplitude_m, end_amplitude_m
        Fundamental amplitudes of the mode where the branch starts and ends (> 0).
    mode
        The followed mode (from 1).
    settings
        Harmonics and samples of the balance (``tol``/``max_iter`` of the first point);
        None: :class:`HarmonicSettings` defaults.
    continuation
        Step control and the internal-resonance threshold; None: the defaults.
    """
    settings = settings or HarmonicSettings()
    continuation = continuation or ContinuationSettings()
    if not 0 < start_amplitude_m < end_amplitude_m:
        raise ValueError("amplitudes must satisfy 0 < start_amplitude_m < end_amplitude_m")
    first = nonlinear_modes(model, [start_amplitude_m], mode=mode, settings=settings)
    if not first.converged[0]:
        raise ValueError(f"no nonlinear mode {mode} converged at the start amplitude")
    arrays = modal_arrays(model)
    grid = settings.grid(model)
    layout = StateLayout(model.n_modes, grid.size)
    target = mode - 1
    amplitude_index = layout.coefficient(target, 1)
    phase_index = layout.coefficient(target, 2)
    # Unknowns: every coefficient but the fixed phase (S1 of the mode = 0), then ω, ξ.
    free = np.array(
        [i for i in range(layout.n_coefficients) if i != phase_index] + [layout.omega, layout.xi]
    )
    a_column = int(np.flatnonzero(free == amplitude_index)[0])
    w_t = float(arrays.omega[0, target])
    scale = np.full(free.size, float(end_amplitude_m))
    scale[-2:] = w_t

    y = np.zeros(layout.n_state)
    y[: layout.n_coefficients] = first.coefficients[0].ravel()
    y[layout.omega] = 2.0 * np.pi * first.frequency_hz[0]
    y[layout.xi] = 2.0 * y[layout.omega] * first.damping_ratio[0]

    def system(u_scaled: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        state = y.copy()
        state[free] = u_scaled * scale
        residual, jacobian = evaluate(arrays, grid, state[None])
        norm = w_t**2 * max(abs(state[amplitude_index]), 1e-300)
        return residual[0] / norm, jacobian[0][:, free] * scale / norm, state

    u = y[free] / scale
    tangent = _tangent(system(u)[1], None, a_column)
    step = continuation.step
    points = [y.copy()]
    turning: list[int] = []
    stopped = "max points"
    while len(points) < continuation.max_points:
        predicted = u + step * tangent
        corrected, state, iterations = _correct(system, predicted, tangent, continuation)
        if corrected is None:
            step /= 2.0
            if step < continuation.min_step:
                stopped = "step too small"
                break
            continue
        _, jacobian, _ = system(corrected)
        new_tangent = _tangent(jacobian, tangent, a_column)
        if new_tangent[a_column] * tangent[a_column] < 0:
            turning.append(len(points))
        u, tangent, y = corrected, new_tangent, state
        points.append(state.copy())
        step = float(np.clip(step * (1.5 if iterations <= 3 else 0.7),
                             continuation.min_step, continuation.max_step))  # fmt: skip
        if state[amplitude_index] >= end_amplitude_m:
            stopped = "end amplitude"
            break
        if state[amplitude_index] < start_amplitude_m:
            stopped = "amplitude below start"
            break
    return _branch(arrays, grid, layout, mode, np.array(points), tuple(turning), stopped,
                   continuation.share_threshold)  # fmt: skip


def _tangent(jacobian: np.ndarray, previous: np.ndarray | None, a_column: int) -> np.ndarray:
    """Unit null vector of the ``n × (n+1)`` Jacobian, oriented along ``previous``.

    Without a previous tangent it points to growing amplitude.
    """
    n = jacobian.shape[1]
    guide = np.zeros(n)
    if previous is None:
        guide[a_column] = 1.0
    else:
        guide = previous
    bordered = np.vstack([jacobian, guide])
    rhs = np.zeros(n)
    rhs[-1] = 1.0
    tangent = np.linalg.solve(bordered, rhs)
    return tangent / np.linalg.norm(tangent)


def _correct(system, predicted, tangent, settings: ContinuationSettings):
    """Newton on the balance plus ``tangent · (u − predicted) = 0``; None if it fails."""
    u = predicted.copy()
    for iteration in range(settings.max_iter + 1):
        residual, jacobian, state = system(u)
        arclength = tangent @ (u - predicted)
        if not np.all(np.isfinite(residual)):
            return None, None, iteration
        if np.max(np.abs(residual)) <= settings.tol and abs(arclength) <= settings.tol:
            return u, state, iteration
        if iteration == settings.max_iter:
            break
        bordered = np.vstack([jacobian, tangent])
        try:
            u = u - np.linalg.solve(bordered, np.append(residual, arclength))
        except np.linalg.LinAlgError:
            return None, None, iteration
    return None, None, settings.max_iter


def _branch(arrays, grid, layout, mode, states, turning, stopped, threshold) -> ModeBranch:
    """The :class:`ModeBranch` of continuation states ``(n_points, n_state)``."""
    n_modes = arrays.n_modes
    coefficients = states[:, : layout.n_coefficients].reshape(len(states), n_modes, grid.size)
    omega = states[:, layout.omega]
    share = energy_shares(coefficients, omega, arrays.omega[0][None, :])
    amplitude = coefficients[:, mode - 1, 1]
    frequency = omega / (2.0 * np.pi)
    resonances = []
    for m in range(n_modes):
        if m == mode - 1:
            continue
        above = np.flatnonzero(share[:, m] > threshold)
        if above.size == 0:
            continue
        point = int(above[0])
        power = coefficients[point, m, 1::2] ** 2 + coefficients[point, m, 2::2] ** 2
        resonances.append(
            InternalResonance(
                mode=m + 1,
                harmonic=int(np.argmax(power)) + 1,
                amplitude_m=float(amplitude[point]),
                frequency_hz=float(frequency[point]),
                point=point,
                peak_share=float(share[:, m].max()),
            )
        )
    return ModeBranch(
        mode=mode,
        amplitude_m=amplitude,
        frequency_hz=frequency,
        damping_ratio=states[:, layout.xi] / (2.0 * omega),
        coefficients=coefficients,
        energy_share=share,
        turning_points=turning,
        internal_resonances=tuple(resonances),
        stopped=stopped,
    )
