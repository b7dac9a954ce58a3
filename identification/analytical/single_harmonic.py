"""Single-harmonic balance: the describing-function backbone.

With the catalogue's closed-form describing functions the balance reads
``ω² = Σ c_i k_eq,i(a, ω)`` and ``D = Σ c_i c_eq,i(a, ω) / (2ω)``. Vectorised
numpy over a :class:`~identification.analytical.coefficients.CoefficientTable`;
the math lives in small pure functions of ``(a, omega, coefficient arrays)`` so
that the pytensor graph of :mod:`pm_joint.forward` can mirror it. It also
gives the multi-harmonic balance (:mod:`~identification.analytical.multi_harmonic`)
its starting points.
"""

from __future__ import annotations

import numpy as np

from identification.analytical.coefficients import CoefficientTable, small_amplitude_stiffness
from identification.effects import CATALOGUE, HYSTERETIC
from identification.effects.base import NUMPY

__all__ = ["describing_sums", "single_harmonic_backbone"]

_EFFECTS_BY_INDEX = list(CATALOGUE.values())


def describing_sums(
    a: np.ndarray, omega: np.ndarray, table: CoefficientTable
) -> tuple[np.ndarray, np.ndarray]:
    """Equivalent stiffness ``Σ c_i k_eq,i`` and damping ``Σ c_i c_eq,i`` of all terms.

    ``a`` and ``omega`` broadcast against ``(n_sets, 1)``. Even effects (x², ẋ²,
    x·ẋ and the even part of exp) have no single-harmonic signature: their
    describing functions are zero, so this sum (and ``method="single"``) cannot
    see them; only the multi-harmonic balance does, through the mean and the
    second harmonic.
    """
    k_total = np.zeros(np.broadcast_shapes(np.shape(a), np.shape(omega), (table.n_sets, 1)))
    c_total = np.zeros_like(k_total)
    terms = []
    for i, index in enumerate(table.indices):
        effect = _EFFECTS_BY_INDEX[index]
        shape = {name: table.shapes[:, i, slot, None] for slot, name in enumerate(effect.shape)}
        terms.append((effect, table.coefficients[:, i, None], shape))
    if table.has_hysteretic:
        coefficient = table.hysteretic[:, 0, None]
        terms.append((HYSTERETIC, coefficient, table.hysteretic_shape(keepdims=True)))
    for effect, coefficient, shape in terms:
        # The parts broadcast by themselves: a stiffness part stays the size of the
        # amplitude grid, and a part that is zero costs nothing.
        k_eq, c_eq = effect.describing_parts(NUMPY, a, omega, **shape)
        if k_eq is not None:
            k_total += coefficient * k_eq
        if c_eq is not None:
            c_total += coefficient * c_eq
    return k_total, c_total


def single_harmonic_backbone(
    a: np.ndarray, table: CoefficientTable, *, rtol: float = 1e-13, max_iter: int = 100
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequency (rad/s), damping ratio and convergence of the single-harmonic backbone.

    Solves ``ω² = Σ c_i k_eq,i(a, ω)`` by fixed-point iteration (one step when no
    term's stiffness depends on ω; ``x·ẋ²`` is the catalogue's one that does) and
    gives ``ζ = Σ c_i c_eq,i(a, ω) / (2ω)``. Outputs have shape ``(n_sets, n_amp)``;
    NaN and ``converged = False`` where the equivalent stiffness is not positive
    or the iteration does not settle.
    """
    shape = (table.n_sets, np.size(a))
    linear = small_amplitude_stiffness(table)
    omega = np.broadcast_to(np.sqrt(np.where(linear > 0, linear, 1.0))[:, None], shape).copy()
    damping = np.full(shape, np.nan)
    done = np.zeros(shape, dtype=bool)
    for _ in range(max_iter):
        # Describing functions overflow where a term grows without bound (exp, x·ẋ² at
        # large amplitudes): no backbone there, which the NaN below reports.
        with np.errstate(over="ignore", invalid="ignore"):
            k_eq, c_eq = describing_sums(a, omega, table)
            updated = np.sqrt(np.where(k_eq > 0, k_eq, np.nan))
        settled = ~done & (np.abs(updated - omega) <= rtol * updated)
        # Freeze settled points: the answer must not depend on what else is in the batch.
        damping = np.where(settled, c_eq / (2.0 * omega), damping)
        done |= settled
        failed = ~done & ~np.isfinite(updated)
        omega = np.where(done, omega, updated)
        if np.all(done | failed):
            break
    omega = np.where(done, omega, np.nan)
    return omega, np.where(done, damping, np.nan), done
