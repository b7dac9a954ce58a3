"""Harmonic-balance backbones of a base-excited joint model at phase resonance.

The model (:class:`~identification.model.JointModel`) is ``ẍ + f(x, ẋ) = −a_base(t)``
with ``x`` the displacement relative to the base. A backbone point is the
periodic response whose fundamental harmonic is ``a cos ωt`` while the base
acceleration is the pure fundamental ``a_base = A sin ωt``: the displacement
then lags the effective force ``−a_base`` by 90°, the phase-resonance condition
a PLL test holds. For each amplitude ``a`` the backbone gives

* the frequency ``ω`` (reported in Hz),
* the base-acceleration amplitude ``A`` (m/s²) that holds that amplitude,
* the damping ratio from the power balance of a base-excited test,
  ``D = |Q_b| / (2 |Q|)`` with ``Q_b = A / ω²`` the base-displacement and
  ``Q = a`` the relative-displacement fundamentals, i.e. ``D = A / (2 ω² a)``.

``A`` and ``D`` keep their sign: a negative value means the model's net
damping at that amplitude is negative (e.g. a dominant negative Van der Pol
term), so energy must be taken out to hold the amplitude.

A test's base motion is not a pure sine (shaker distortion, a PLL's frequency
ripple). With ``method="multi"`` the measured excitation's harmonics and mean can be
the forcing (``excitation_harmonics``, :func:`forcing_rows`): its fundamental is still
``A sin ωt`` with ``A`` the unknown the phase-resonance condition fixes, its
harmonics are the measured fractions of ``A``, so the response harmonics the
excitation explains are in the model's prediction and not left to its joint terms.
A force-driven test is the same with the force per unit mass in place of ``−a_base``.

Two methods, one module each; this one is their entry point (:func:`backbone`)
and keeps their public names importable from here:

``"single"``
    Single-harmonic balance with the catalogue's closed-form describing
    functions, ``ω² = Σ c_i k_eq,i(a, ω)``, ``D = Σ c_i c_eq,i(a, ω) / (2ω)``
    (:mod:`~identification.analytical.single_harmonic`).
``"multi"``
    Multi-harmonic balance with harmonics ``0..H`` (the mean included) and
    the alternating frequency–time scheme (AFT), started from the
    single-harmonic point (:mod:`~identification.analytical.multi_harmonic`).

Many parameter sets are evaluated at once through a :class:`CoefficientTable`
built from one template model plus override columns (no model per set;
:mod:`~identification.analytical.coefficients`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.coefficients import CoefficientTable, coefficient_table
from identification.analytical.multi_harmonic import (
    EXCITATION_KINDS,
    default_time_samples,
    forcing_rows,
    multi_harmonic,
)
from identification.analytical.single_harmonic import describing_sums, single_harmonic_backbone
from identification.checks import positive_vector
from identification.model import JointModel

__all__ = [
    "EXCITATION_KINDS",
    "CoefficientTable",
    "HarmonicBackbone",
    "backbone",
    "coefficient_table",
    "default_time_samples",
    "describing_sums",
    "forcing_rows",
    "single_harmonic_backbone",
]


@dataclass(frozen=True)
class HarmonicBackbone:
    """Phase-resonant backbone, one row per parameter set (or 1-D for one model).

    Attributes
    ----------
    amplitude_m
        Fundamental-harmonic amplitude of the relative displacement (m), shape ``(n_amp,)``.
    frequency_hz
        Backbone frequency (Hz).
    damping_ratio
        ``A / (2 ω² a)`` from the power balance (signed).
    base_acceleration
        Base-acceleration amplitude ``A`` (m/s², fundamental, signed).
    converged
        False where no phase-resonant solution was found; the numbers there are NaN.
    method
        ``"single"`` or ``"multi"``.
    harmonics
        Highest harmonic ``H`` balanced (1 for ``"single"``).
    harmonics_cos_m, harmonics_sin_m
        ``"multi"`` only: ``x(t) = Σ_h C_h cos hωt + S_h sin hωt`` for ``h = 0..H``
        (last axis); ``C_0`` is the mean, ``C_1 = a``, ``S_1 = 0``. None for ``"single"``.
    """

    amplitude_m: np.ndarray
    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    base_acceleration: np.ndarray
    converged: np.ndarray
    method: str
    harmonics: int
    harmonics_cos_m: np.ndarray | None = None
    harmonics_sin_m: np.ndarray | None = None


def backbone(
    model: JointModel,
    amplitudes_m: ArrayLike,
    *,
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
    method: str = "single",
    harmonics: int = 5,
    n_time: int | None = None,
    tol: float = 1e-10,
    max_iter: int = 50,
    excitation_harmonics: ArrayLike | None = None,
    excitation_kind: str = "base_acceleration",
    excitation_mean: ArrayLike | None = None,
) -> HarmonicBackbone:
    """Phase-resonant backbone of ``model`` at the given fundamental amplitudes.

    Parameters
    ----------
    model
        The joint model (template when ``parameters`` is given).
    amplitudes_m
        Fundamental-harmonic amplitudes of the relative displacement (m), 1-D, > 0.
    parameters, names
        Optional ``(n_sets, len(names))`` values of the named parameters
        (:attr:`JointModel.parameter_names`, e.g. ``"cubic_stiffness"``,
        ``"microslip.k_t"``); outputs then have shape ``(n_sets, n_amp)``, else ``(n_amp,)``.
    method
        ``"single"`` (describing functions; even terms have no effect there) or
        ``"multi"`` (harmonic balance with harmonics 0..``harmonics`` and AFT).
    harmonics
        Highest harmonic ``H`` of ``"multi"``.
    n_time
        AFT samples per period (≥ 4H + 1); default :func:`default_time_samples`.
        Friction terms converge like ``1/N²`` in the damping: raise it for
        precise friction damping.
    tol
        ``"multi"``: converged when every harmonic residual is below ``tol · ω² a``.
    max_iter
        ``"multi"``: Newton iterations before a case is declared not converged.
    excitation_harmonics, excitation_kind, excitation_mean
        ``"multi"``: the measured excitation as the forcing (:func:`forcing_rows`): its
        orders ``2, 3, …`` as fractions of its fundamental in its own frame, per
        amplitude ``(n_amp, n_orders)`` or shared ``(n_orders,)``; what it is
        (:data:`EXCITATION_KINDS`: a base acceleration or a force per unit mass); its
        mean over its fundamental's amplitude. The fundamental's amplitude is still
        the unknown the phase-resonance condition fixes (``base_acceleration``, which
        is then the force per unit mass for ``"force"``), the harmonics scale with
        it, and the damping ratio stays that of the fundamental's power balance. None:
        a pure sine.

    Returns
    -------
    HarmonicBackbone
        NaN and ``converged = False`` where there is no phase-resonant solution
        (e.g. no positive stiffness) or the solver did not converge.
    """
    a = positive_vector(amplitudes_m, "amplitudes_m")
    if method not in ("single", "multi"):
        raise ValueError(f"method must be 'single' or 'multi', got {method!r}")
    table = coefficient_table(model, parameters, names)
    omega, damping, converged = single_harmonic_backbone(a, table)
    cos_m = sin_m = None
    forced = excitation_harmonics is not None or excitation_mean is not None
    if method == "single":
        if forced:
            raise ValueError("an excitation with harmonics or a mean needs method='multi'")
        harmonics = 1
    else:
        if not isinstance(harmonics, int | np.integer) or harmonics < 1:
            raise ValueError(f"harmonics must be an integer ≥ 1, got {harmonics!r}")
        if not (np.isfinite(tol) and tol > 0):
            raise ValueError(f"tol must be finite and > 0, got {tol!r}")
        if not isinstance(max_iter, int | np.integer) or max_iter < 0:
            raise ValueError(f"max_iter must be an integer ≥ 0, got {max_iter!r}")
        if n_time is None:
            n_time = default_time_samples(model, harmonics)
        if not isinstance(n_time, int | np.integer) or n_time < 4 * harmonics + 1:
            raise ValueError(
                f"n_time must be an integer ≥ 4·harmonics + 1 = {4 * harmonics + 1}, got {n_time!r}"
            )
        forcing = None
        if forced:
            ratios = np.zeros(0) if excitation_harmonics is None else excitation_harmonics
            forcing = forcing_rows(ratios, a.size, harmonics, excitation_kind, excitation_mean)
        y, base, converged = multi_harmonic(
            a, table, omega, harmonics, n_time, tol, max_iter, forcing
        )
        omega = y[..., 1]
        with np.errstate(over="ignore", invalid="ignore"):  # NaN or inf: not converged
            damping = base / (2.0 * omega**2 * a)
        cos_m = np.concatenate([y[..., :1], np.broadcast_to(a, omega.shape)[..., None],
                                y[..., 2::2]], axis=-1)  # fmt: skip
        sin_m = np.concatenate([np.zeros((*omega.shape, 2)), y[..., 3::2]], axis=-1)
        sin_m[~converged] = np.nan
        cos_m[~converged] = np.nan
    with np.errstate(over="ignore", invalid="ignore"):
        base_acceleration = 2.0 * omega**2 * a * damping
    squeeze = (lambda z: z[0]) if parameters is None else (lambda z: z)
    return HarmonicBackbone(
        amplitude_m=a,
        frequency_hz=squeeze(omega / (2.0 * np.pi)),
        damping_ratio=squeeze(damping),
        base_acceleration=squeeze(base_acceleration),
        converged=squeeze(converged),
        method=method,
        harmonics=harmonics,
        harmonics_cos_m=None if cos_m is None else squeeze(cos_m),
        harmonics_sin_m=None if sin_m is None else squeeze(sin_m),
    )
