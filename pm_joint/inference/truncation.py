"""The single-harmonic graph's truncation error on measured curves, moved out of the data.

The hierarchical model scores each measured point against the single-harmonic
balance, the differentiable graph NUTS needs. Measured backbones carry every
harmonic. On the ``trc-like`` rig (nominal model and three assemblies 10 %
away, PLL simulator at its 12 levels) the PLL's frequency at the two largest
amplitudes (1.4–2.4 mm, cubic hardening) lies 0.8–15 standard deviations of
the extraction noise above the single-harmonic one, and within 0.47 of the
harmonic balance with five harmonics at every point (damping: 0.44 against
0.07). Scored as it is, that error is read as a smaller cubic stiffness.

The approximation-error approach (Kaipio & Somersalo, *Statistical inverse
problems: discretization, model reduction and inverse crimes*, J. Comput. Appl.
Math. 198, 2007) treats the gap between an accurate model and the one the
posterior is computed with as part of the data: here its value at a point
estimate of each curve's parameters, ``δ_i(a) = multi(θ̂_i, a) − single(θ̂_i, a)``
(:func:`identification.analytical.harmonic.backbone`, ``method="multi"``), is
subtracted from curve i's measured points. The gap changes slowly with θ (it is
of second order in the cubic stiffness), so its value at θ̂_i stands for its
value over the curve's posterior; θ̂_i is fitted again to the corrected points
and δ_i recomputed there (``passes``).

θ̂_i is the maximum a posteriori estimate of curve i alone under the
hierarchical prior's marginal for ``η_i = log(θ_i/θ0)`` (Normal with standard
deviation ``prior_scale``): frequency residuals in Hz, damping residuals
relative, each scaled by its channel's residual spread over every curve of the
previous pass. The standard deviations of ``η_i`` from the curve's points
alone come with it; they say which parameters the curves pin
(:func:`centred_choice`).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares

from identification.analytical.harmonic import backbone
from identification.model import JointModel

__all__ = ["TruncationCorrection", "centred_choice", "truncation_correction"]

#: Scales of the first pass's residuals, before any spread is measured: 0.1 % of the
#: frequency and 5 % of the damping ratio.
_FIRST_FREQUENCY_SCALE, _FIRST_DAMPING_SCALE = 1e-3, 0.05


@dataclass(frozen=True)
class TruncationCorrection:
    """What :func:`truncation_correction` found.

    Attributes
    ----------
    frequency_hz, damping_ratio
        ``multi − single`` at each point (flat, in the order of the points given):
        subtract from the measured values.
    estimate
        ``(n_curves, n_params)`` θ̂_i the gap was computed at.
    log_sd
        ``(n_curves, n_params)`` standard deviations of ``log θ_i`` at θ̂_i from the
        curve's points alone (Gauss–Newton, the prior left out; infinite where the
        points do not pin a parameter).
    harmonics
        Highest harmonic of the accurate balance.
    """

    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    estimate: np.ndarray
    log_sd: np.ndarray
    harmonics: int


def _curve_fit(
    model: JointModel,
    names: Sequence[str],
    theta0: np.ndarray,
    amplitude: np.ndarray,
    frequency: np.ndarray,
    damping: np.ndarray,
    scales: tuple[float, float],
    prior_scale: float,
    start: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """MAP of ``η = log(θ/θ0)`` of one curve under the single-harmonic balance, and the
    standard deviations of η its points alone give."""
    s_f, s_d = scales

    def residual(eta: np.ndarray) -> np.ndarray:
        hb = backbone(model, amplitude, parameters=(theta0 * np.exp(eta))[None], names=names)
        r_f = (hb.frequency_hz[0] - frequency) / s_f
        with np.errstate(invalid="ignore", divide="ignore"):
            r_d = np.log(hb.damping_ratio[0] / damping) / s_d
        # No backbone (no positive stiffness) or a sign change: a large, finite miss.
        r = np.concatenate([r_f, r_d])
        return np.concatenate([np.where(np.isfinite(r), r, 1e3), eta / prior_scale])

    fit = least_squares(residual, start, x_scale=prior_scale, method="trf")
    # The curve's own information (Gauss–Newton, the prior's rows left out): how tightly
    # its points pin each parameter; infinite where they do not.
    data_rows = fit.jac[: -start.size]
    try:
        sd = np.sqrt(np.diag(np.linalg.inv(data_rows.T @ data_rows)))
    except np.linalg.LinAlgError:
        sd = np.full(start.size, np.inf)
    return fit.x, sd


def truncation_correction(
    model: JointModel,
    names: Sequence[str],
    curve: np.ndarray,
    amplitude: np.ndarray,
    frequency_hz: np.ndarray,
    damping_ratio: np.ndarray,
    *,
    prior_scale: float,
    harmonics: int = 5,
    passes: int = 2,
) -> TruncationCorrection:
    """The multi-minus-single harmonic balance gap at each measured point.

    Parameters
    ----------
    model
        Template model: the structure, and θ0 for the named parameters.
    names
        Parameters that vary from curve to curve.
    curve, amplitude, frequency_hz, damping_ratio
        Flat points: the curve index, amplitude (m) and measured values of each.
    prior_scale
        Standard deviation of ``log(θ_i/θ0)`` under the prior, each parameter
        (the hierarchical model's ``sqrt(location_scale² + population_scale²)``).
    harmonics
        Highest harmonic of the accurate balance (AFT, :func:`~identification.
        analytical.harmonic.backbone` ``method="multi"``).
    passes
        Fits of θ̂_i: the first to the measured points, each later one to the points
        less the gap at the previous θ̂_i.

    Returns
    -------
    TruncationCorrection
        Where the multi-harmonic balance has no solution at θ̂_i the gap is 0 (a
        warning says how many points).
    """
    names = list(names)
    theta0 = np.array([model.parameters[n] for n in names])
    curve = np.asarray(curve, int)
    n_curves = int(curve.max()) + 1
    eta = np.zeros((n_curves, len(names)))
    log_sd = np.full_like(eta, np.inf)
    gap_f = np.zeros_like(frequency_hz, dtype=float)
    gap_d = np.zeros_like(damping_ratio, dtype=float)
    scales = (_FIRST_FREQUENCY_SCALE * float(np.median(frequency_hz)), _FIRST_DAMPING_SCALE)
    failed = 0
    for _ in range(passes):
        single_f, single_d = np.empty_like(gap_f), np.empty_like(gap_d)
        for i in range(n_curves):
            at = curve == i
            eta[i], log_sd[i] = _curve_fit(
                model, names, theta0, amplitude[at], frequency_hz[at] - gap_f[at],
                damping_ratio[at] - gap_d[at], scales, prior_scale, eta[i],
            )  # fmt: skip
            parameters = (theta0 * np.exp(eta[i]))[None]
            single = backbone(model, amplitude[at], parameters=parameters, names=names)
            multi = backbone(model, amplitude[at], parameters=parameters, names=names,
                             method="multi", harmonics=harmonics)  # fmt: skip
            ok = multi.converged[0] & single.converged[0]
            failed += int(np.sum(~ok))
            gap_f[at] = np.where(ok, multi.frequency_hz[0] - single.frequency_hz[0], 0.0)
            gap_d[at] = np.where(ok, multi.damping_ratio[0] - single.damping_ratio[0], 0.0)
            single_f[at], single_d[at] = single.frequency_hz[0], single.damping_ratio[0]
        # The next pass weighs each channel by its residual spread over every curve.
        with np.errstate(invalid="ignore", divide="ignore"):
            r_f = frequency_hz - gap_f - single_f
            r_d = np.log((damping_ratio - gap_d) / single_d)
        scales = (float(np.nanstd(r_f)) or scales[0], float(np.nanstd(r_d)) or scales[1])
    if failed:
        warnings.warn(
            f"{failed} point-fits of the {harmonics}-harmonic balance did not converge: "
            "no truncation correction there",
            stacklevel=2,
        )
    return TruncationCorrection(gap_f, gap_d, theta0 * np.exp(eta), log_sd, harmonics)


def centred_choice(correction: TruncationCorrection) -> np.ndarray:
    """Which parameters to centre: those each curve pins more tightly than the curves
    scatter.

    The centred form ``η_i ~ Normal(μ, σ)`` mixes when the likelihood of each
    ``η_i`` is narrow against σ; the non-centred ``η_i = μ + σ z_i`` when it is
    wide, where the centred form meets the funnel (Betancourt & Girolami,
    *Hamiltonian Monte Carlo for hierarchical models*, 2015). The width is the
    median over curves of the standard deviation each curve's points alone give
    (``log_sd``); σ² is estimated by moments, the variance of the per-curve
    estimates ``log θ̂_i`` less that width squared. A parameter is centred where
    the estimate exceeds the width: where the per-curve estimates scatter more
    than twice as much (in variance) as their own error explains.
    """
    width = np.median(correction.log_sd, axis=0) ** 2
    scatter = np.var(np.log(np.abs(correction.estimate)), axis=0, ddof=1)
    return scatter - width > width
