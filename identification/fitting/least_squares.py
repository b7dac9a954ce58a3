"""Fitting a JointModel's coefficients to measured backbones through harmonic balance.

The model's named parameters (:attr:`JointModel.parameter_names`: coefficients
and shape parameters such as ``microslip.k_t`` or ``stribeck_friction.v_s``) are
fitted by least squares (:func:`scipy.optimize.least_squares`) so that its
harmonic-balance backbone (:func:`identification.analytical.harmonic.backbone`) meets the
measured ones in **both** channels: friction shows in the damping, stiffness in
the frequency. Backbones that carry the higher harmonics of their hold fits add
them as a third channel (:mod:`identification.fitting.data`), and each point's
prediction is driven by the base acceleration its hold measured, harmonics
included, so response harmonics the excitation explains are not left to the
model's joint terms.

The objective is the likelihood of :class:`~identification.fitting.data.FitData`:
the residual of the mean curve at the comparison levels, whitened by its
covariance (between-curve scatter over the number of curves, plus the systematic
floors), so that points of one curve are not counted as independent. AIC and BIC
count the fitted parameters; they describe a fit, the criticism decides with
calibrated tests instead (:mod:`identification.criticism`).

Start values come from a linearised fit: for fixed shape parameters the
single-harmonic balance is *linear* in the coefficients when evaluated at the
measured frequencies, ``ω² = Σ c_i k_eq,i(a, ω)`` and ``2ζω = Σ c_i c_eq,i(a, ω)``,
so one weighted linear least-squares solve per point of a shape-parameter grid
gives robust starts. Effects with no single-harmonic signature (the even terms)
start from a scan of their coefficient through the multi-harmonic balance.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from identification.effects import CATALOGUE, FitScale, get_effect
from identification.fitting.data import (
    BACKBONE_CHANNELS,
    HARMONIC_CHANNELS,
    FitData,
    _floor_key,
    fit_data,
)
from identification.fitting.prediction import predict_channels, resolve_method
from identification.measurements.backbone import BackboneSet
from identification.model import JointModel

__all__ = [
    "FitOutcome",
    "FitResult",
    "default_free",
    "default_shape_grid",
    "evaluate",
    "fit_backbones",
    "fit_scale",
    "natural_coefficient",
    "shape_bounds",
]

# --------------------------------------------------------------------------
# Fit results


class FitOutcome(StrEnum):
    """How a fit ended (:attr:`FitResult.outcome`)."""

    #: The optimiser converged (or the model was evaluated as given).
    CONVERGED = "converged"
    #: The information criteria stopped moving (:data:`STALL_IC`).
    STALLED = "stalled"
    #: The optimiser stopped without converging (its message says why).
    NOT_CONVERGED = "not converged"
    #: The optimiser met parameters where the model has no periodic solution at some
    #: measured amplitudes and could not go on from there: the result is the last model
    #: it could evaluate, not a fit.
    NO_PERIODIC_SOLUTION = "no periodic solution"


@dataclass(frozen=True)
class FitResult:
    """A model against measured data.

    Attributes
    ----------
    model
        The (fitted) model.
    free
        Names of the fitted parameters (empty for a model evaluated as given).
    method
        Harmonic-balance method used (``"single"`` or ``"multi"``).
    data
        The measured data (:class:`FitData`).
    predicted
        ``(n_points, n_channels)`` model values at the measured points.
    weights
        Weight of each channel in the residual.
    loglik, aic, bic
        Gaussian log-likelihood of the mean residual at the levels
        (:meth:`FitData.loglik`) and the information criteria with
        ``n_parameters = len(free)`` (or the count given).
    n_residuals
        Number of residual entries (levels × channels that count).
    success, message
        Optimiser outcome.
    outcome
        How the fit ended (:class:`FitOutcome`); :attr:`solved` is False where it met a
        region without a periodic solution (:attr:`outcome_text` says so in words).
    """

    model: JointModel
    free: tuple[str, ...]
    method: str
    data: FitData
    predicted: np.ndarray
    weights: np.ndarray
    loglik: float
    aic: float
    bic: float
    n_parameters: int
    n_residuals: int
    success: bool = True
    message: str = ""
    outcome: FitOutcome = FitOutcome.CONVERGED

    @property
    def solved(self) -> bool:
        """Whether the fit ended in a model it could judge (not stopped by a region without
        a periodic solution)."""
        return self.outcome is not FitOutcome.NO_PERIODIC_SOLUTION

    @property
    def outcome_text(self) -> str:
        """How the fit ended, in words."""
        if self.outcome is FitOutcome.NO_PERIODIC_SOLUTION:
            return (
                f"the refit of {self.model.equation()} met parameters without a periodic "
                "solution at some measured amplitudes and stopped there (not a fit)"
            )
        return self.outcome.value + (f" ({self.message})" if self.message else "")

    def __repr__(self) -> str:
        """Equation, fitted parameters, χ² and how the fit ended; the arrays are behind
        the attributes (``predicted``, ``weights``, ``data``)."""
        parameters = ", ".join(f"{n}={self.model.parameters[n]:.4g}" for n in self.free)
        harmonics = "" if self.harmonic_rmse is None else f", harmonics {self.harmonic_rmse:.3g}"
        return (
            f"<FitResult {self.model.equation()} ({self.method} harmonic balance): "
            f"{self.outcome.value}, χ² {self.chi2:.4g}, BIC {self.bic:.4g}\n"
            f"  RMSE frequency {self.frequency_rmse_hz:.3g} Hz, damping "
            f"{self.damping_rmse:.3g}{harmonics}"
            + (f"\n  fitted: {parameters}>" if parameters else ">")
        )

    @property
    def residual(self) -> np.ndarray:
        """Measured minus predicted, ``(n_points, n_channels)``."""
        return self.data.values - self.predicted

    def level_residual(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean residual over curves at the levels and its standard error."""
        return self.data.mean_residual(self.predicted), self.data.level_mean(self.residual)[1]

    @property
    def chi2(self) -> float:
        """``rᵀV⁻¹r`` of the mean residual: the likelihood's misfit (unit weights)."""
        z = self.data.whitened(self.predicted)
        return float(z @ z)

    def _rmse(self, channels: Sequence[str]) -> float | None:
        columns = [self.data.column(c) for c in channels if c in self.data.channels]
        columns = [j for j in columns if self.data.used[j]]
        if not columns:
            return None
        mean = self.data.mean_residual(self.predicted)
        return float(np.sqrt(np.mean(np.sum(mean[:, columns] ** 2, axis=1))))

    @property
    def frequency_rmse_hz(self) -> float:
        """RMS over the levels of the mean frequency residual (Hz).

        The mean over curves takes out the assembly-to-assembly scatter, which no
        population-mean model can fit: what is left is the model-form error.
        """
        return self._rmse(("frequency_hz",))

    @property
    def damping_rmse(self) -> float:
        """RMS over the levels of the mean damping-ratio residual (1)."""
        return self._rmse(("damping_ratio",))

    @property
    def harmonic_rmse(self) -> float | None:
        """RMS over the levels of the mean harmonic residual ``|ΔQ_2|, |ΔQ_3|`` combined
        (fraction of the fundamental); None without measured harmonics."""
        return self._rmse(HARMONIC_CHANNELS)

    @property
    def n_points(self) -> int:
        return self.data.n_points

    def information_criterion(self, kind: str = "bic") -> float:
        if kind not in ("aic", "bic"):
            raise ValueError(f"information criterion must be 'aic' or 'bic', got {kind!r}")
        return self.aic if kind == "aic" else self.bic

    def summary(self) -> dict:
        """JSON-ready figures."""
        return {
            "equation": self.model.equation(),
            "effects": self.model.effects,
            "parameters": self.model.parameters,
            "free": list(self.free),
            "method": self.method,
            "frequency_rmse_hz": self.frequency_rmse_hz,
            "damping_rmse": self.damping_rmse,
            "harmonic_rmse": self.harmonic_rmse,
            "loglik": self.loglik,
            "aic": self.aic,
            "bic": self.bic,
            "n_parameters": self.n_parameters,
            "n_residuals": self.n_residuals,
            "n_points": self.n_points,
            "success": self.success,
        }


def _channel_weights(data: FitData, weights: Mapping[str, float] | None) -> np.ndarray:
    given = dict(weights or {})
    known = {"frequency_hz", "damping_ratio", "harmonics"}
    unknown = set(given) - known
    if unknown:
        raise ValueError(f"unknown weight key(s) {sorted(unknown)}; use {sorted(known)}")
    for key, value in given.items():
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"weights[{key!r}] must be finite and ≥ 0, got {value}")
    out = np.array([given.get(_floor_key(c), 1.0) for c in data.channels], dtype=float)
    if not out[: len(BACKBONE_CHANNELS)].any():
        raise ValueError("weights switch off both backbone channels")
    return out


def _normalised(data: FitData, predicted: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Whitened weighted mean residual (the likelihood's; failures penalised)."""
    return data.whitened(predicted, weights)


def evaluate(
    model: JointModel,
    data: FitData,
    *,
    method: str = "auto",
    weights: Mapping[str, float] | None = None,
    free: Sequence[str] = (),
    n_parameters: int | None = None,
    success: bool = True,
    message: str = "",
    outcome: FitOutcome = FitOutcome.CONVERGED,
) -> FitResult:
    """The model as it is against the data (no fitting).

    ``n_parameters`` is what the information criteria count (default ``len(free)``);
    give the model's number of adjustable parameters to compare it with refitted ones.
    ``success``, ``message`` and ``outcome`` say how a fit that ends here ended.
    """
    method = resolve_method(method, model, data)
    w = _channel_weights(data, weights)
    predicted = predict_channels(
        model, data.amplitude_m, data.channels, method=method,
        excitation_harmonics=data.excitation_harmonics,
    )  # fmt: skip
    n = data.metric(w).size
    k = len(free) if n_parameters is None else int(n_parameters)
    loglik = data.loglik(predicted, w)
    if not np.isfinite(loglik):
        success = False
        message = (message + "; " if message else "") + "no backbone at some measured amplitudes"
    return FitResult(
        model=model,
        free=tuple(free),
        method=method,
        data=data,
        predicted=predicted,
        weights=w,
        loglik=loglik,
        aic=2 * k - 2 * loglik,
        bic=k * np.log(n) - 2 * loglik,
        n_parameters=k,
        n_residuals=n,
        success=success,
        message=message,
        outcome=outcome,
    )


# --------------------------------------------------------------------------
# Parameters


def _scaled_parameters(effect: str) -> tuple[str, ...]:
    """A hysteretic (Jenkins) element's shape parameter names, which its coefficient
    scales all alike: ``c·Jenkins(x; k_t, F_s) = Jenkins(x; c·k_t, c·F_s)``; empty for
    every other effect."""
    spec = CATALOGUE[effect]
    return tuple(f"{effect}.{shape}" for shape in spec.shape) if spec.hysteretic else ()


def default_free(model: JointModel) -> list[str]:
    """Every parameter of the model except the Jenkins element's coefficient.

    ``c·Jenkins(x; k_t, F_s) = Jenkins(x; c·k_t, c·F_s)``: with ``k_t`` and ``F_s``
    free the coefficient is redundant, so it stays fixed (usually at 1).
    """
    names = model.parameter_names
    return [
        n for n in names
        if not (n in CATALOGUE and set(_scaled_parameters(n)) & set(names))
    ]  # fmt: skip


def _checked_free(model: JointModel, free: Sequence[str] | None) -> list[str]:
    if free is None:
        return default_free(model)
    free = list(free)
    unknown = [n for n in free if n not in model.parameter_names]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the model has {model.parameter_names}")
    if len(set(free)) != len(free):
        raise ValueError(f"free parameters repeat: {free}")
    for effect in model.effects:
        scaled = _scaled_parameters(effect)
        if scaled and {effect, *scaled} <= set(free):
            raise ValueError(
                f"{effect}'s coefficient, {' and '.join(CATALOGUE[effect].shape)} cannot all "
                "be free: c·Jenkins(k_t, F_s) = Jenkins(c·k_t, c·F_s); leave the coefficient out"
            )
    return free


def natural_coefficient(
    effect: str, amplitude_m: ArrayLike, omega: float, stiffness: float, **shape: float
) -> float:
    """Coefficient at which the term's force reaches the linear force ``k·a``.

    With several amplitudes, at the one where the term is strongest against the linear
    force (the smallest such coefficient): a Stribeck drop or a saturation is strong at
    small amplitudes and vanishes at large ones. ``shape``: the term's shape values
    (default the effect's defaults), which can move where it acts by decades.
    """
    spec = get_effect(effect)
    theta = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    values = {**spec.defaults, **shape}
    ratios = []
    for a in np.atleast_1d(np.asarray(amplitude_m, float)):
        path = spec.feature(a * np.cos(theta), -a * omega * np.sin(theta), **values)
        peak = np.max(np.abs(path))
        if peak > 0:
            ratios.append(stiffness * a / peak)
    return float(min(ratios)) if ratios else 1.0


def fit_scale(model: JointModel, data: FitData) -> FitScale:
    """The test's scale, from which each effect sets its shape grids and bounds.

    The stiffness is the model's small-amplitude one, or ``(2π f_median)²`` of
    the data where the model has none.
    """
    frequency = data.values[:, data.column("frequency_hz")]
    return FitScale.from_measurements(data.amplitude_m, frequency, _stiffness(model, data))


def default_shape_grid(effect: str, data: FitData, model: JointModel) -> dict[str, np.ndarray]:
    """Shape-parameter values scanned for the start of a newly added effect.

    Each effect spans the measured amplitude (or velocity) range with its own
    grid (:meth:`identification.effects.Effect.shape_grid`), so that e.g. the
    slip onset of microslip or the Stribeck velocity can fall anywhere in the test.
    """
    return get_effect(effect).shape_grid(fit_scale(model, data))


def shape_bounds(name: str, data: FitData, model: JointModel) -> tuple[float, float]:
    """Range a fitted shape parameter may take, from the test's amplitudes and velocities.

    A shape far outside what the test resolves lets the fit exploit numerics, not
    physics (e.g. a Stribeck velocity far below the smallest response velocity
    makes a force spike the harmonic balance's time grid cannot resolve). Each
    effect states its own (:meth:`identification.effects.Effect.shape_bounds`);
    a parameter it does not bound may move by e^±30.
    """
    effect, _, shape = name.partition(".")
    bounds = get_effect(effect).shape_bounds(fit_scale(model, data))
    value = model.parameters[name]
    return bounds.get(shape, (value * math.exp(-30), value * math.exp(30)))


def _stiffness(model: JointModel, data: FitData) -> float:
    k = model.linear_stiffness
    if k > 0:
        return k
    f = data.values[:, data.column("frequency_hz")]
    return float((2 * np.pi * np.median(f)) ** 2)


# --------------------------------------------------------------------------
# Start values


def _linear_start(
    model: JointModel,
    data: FitData,
    free: Sequence[str],
    weights: np.ndarray,
    grids: Mapping[str, Mapping[str, np.ndarray]],
) -> tuple[JointModel, float]:
    """Coefficients from the linearised single-harmonic balance, best over shape grids.

    At the measured frequencies ``ω`` the balance ``ω² = Σ c_i k_eq,i(a, ω)``,
    ``2ζω = Σ c_i c_eq,i(a, ω)`` is linear in the coefficients; rows are weighted so
    that their residuals are those of frequency (Hz) and damping ratio over σ.
    Returns the model and its linearised cost (inf if nothing could be solved).
    """
    a = data.amplitude_m
    omega = 2 * np.pi * data.values[:, data.column("frequency_hz")]
    zeta = data.values[:, data.column("damping_ratio")]
    w_f = weights[0] / (4 * np.pi * omega * data.sigma[:, 0])
    w_z = weights[1] / (2 * omega * data.sigma[:, 1])
    free_set = set(free)

    def solved(term) -> bool:
        if CATALOGUE[term.effect].parity == "even":
            return False  # no single-harmonic signature
        scaled = _scaled_parameters(term.effect)
        if scaled:
            return bool(free_set & {term.effect, *scaled})
        return term.effect in free_set

    best_cost, best_model = np.inf, model
    grid_items = [
        (f"{e}.{s}", np.asarray(g, float)) for e, sg in grids.items() for s, g in sg.items()
    ]
    for combination in itertools.product(*(g for _, g in grid_items)):
        names = [n for n, _ in grid_items]
        trial = model.with_parameters(dict(zip(names, combination, strict=True)))
        unknown, k_cols, c_cols = [], [], []
        k_known = np.zeros_like(a)
        c_known = np.zeros_like(a)
        for term in trial.terms:
            k_eq, c_eq = CATALOGUE[term.effect].describing(a, omega, **term.shape)
            if solved(term):
                unknown.append(term)
                k_cols.append(k_eq)
                c_cols.append(c_eq)
            else:
                k_known += term.coefficient * k_eq
                c_known += term.coefficient * c_eq
        if not unknown:
            return model, np.inf
        matrix = np.vstack(
            [np.column_stack(k_cols) * w_f[:, None], np.column_stack(c_cols) * w_z[:, None]]
        )
        rhs = np.concatenate([(omega**2 - k_known) * w_f, (2 * zeta * omega - c_known) * w_z])
        if not np.isfinite(matrix).all():
            continue
        solution, *_ = np.linalg.lstsq(matrix, rhs, rcond=None)
        cost = float(np.sum((matrix @ solution - rhs) ** 2))
        values = {}
        for term, c in zip(unknown, solution, strict=True):
            if _scaled_parameters(term.effect) and term.effect not in free_set:
                scale = c / (term.coefficient if term.coefficient != 0 else 1.0)
                if not scale > 0:
                    cost = np.inf  # a Jenkins element cannot stiffen with amplitude
                    break
                for shape in CATALOGUE[term.effect].shape:
                    values[f"{term.effect}.{shape}"] = scale * term.shape[shape]
                if term.coefficient == 0:
                    values[term.effect] = 1.0
            else:
                values[term.effect] = c
        if cost < best_cost:
            best_cost, best_model = cost, trial.with_parameters(values)
    return best_model, best_cost


def _scan_coefficient(
    model: JointModel, data: FitData, effect: str, method: str, weights: np.ndarray
) -> JointModel:
    """Best coefficient of ``effect`` on a ± log grid, everything else fixed."""
    f = data.values[:, data.column("frequency_hz")]
    shape = next(t.shape for t in model.terms if t.effect == effect)
    scale = natural_coefficient(
        effect, data.amplitude_m.max(), 2 * np.pi * np.median(f), _stiffness(model, data), **shape
    )
    magnitudes = np.geomspace(1e-4, 1.0, 17)
    grid = scale * np.concatenate([-magnitudes[::-1], [0.0], magnitudes])
    predicted = predict_channels(
        model, data.amplitude_m, data.channels, method=method, parameters=grid[:, None],
        names=[effect], excitation_harmonics=data.excitation_harmonics,
    )  # fmt: skip
    costs = [np.sum(_normalised(data, p, weights) ** 2) for p in predicted]
    return model.with_parameters({effect: grid[int(np.argmin(costs))]})


# --------------------------------------------------------------------------
# Fitting


def fit_backbones(
    model: JointModel,
    measured: BackboneSet | FitData,
    free: Sequence[str] | None = None,
    *,
    method: str = "auto",
    weights: Mapping[str, float] | None = None,
    shape_scan: Mapping[str, ArrayLike] | None = None,
    noise_floor: Mapping[str, float] | None = None,
    per_curve: bool = False,
) -> FitResult | list[FitResult]:
    """Fit the model's named parameters to measured backbones.

    Parameters
    ----------
    model
        Model with start values. An effect with coefficient 0 counts as newly
        added: its start comes from the linearised fit over a grid of its shape
        parameters (:func:`default_shape_grid`), or, for even effects, from a
        scan of its coefficient.
    measured
        Measured backbones (or a ready :class:`FitData`); the harmonics they carry
        are fitted as a third channel.
    free
        Parameters to fit; default :func:`default_free`.
    method
        ``"single"``, ``"multi"`` or ``"auto"`` (:func:`resolve_method`).
    weights
        Channel weights ``{"frequency_hz", "damping_ratio", "harmonics"}`` (default 1);
        e.g. ``{"damping_ratio": 0}`` fits the frequency alone, as the paper does.
    shape_scan
        Grids of shape parameters for the start, by parameter name
        (``{"<effect>.<shape>": [...]}``, e.g. the slip force of microslip); the product
        of the grids is scanned.
    noise_floor
        Overrides of :data:`NOISE_FLOOR`.
    per_curve
        Fit every curve on its own: returns one :class:`FitResult` per curve.

    Returns
    -------
    FitResult, or a list of them with ``per_curve``.
    """
    data = measured if isinstance(measured, FitData) else fit_data(measured, noise_floor)
    if per_curve:
        return [
            fit_backbones(model, data.subset(i), free, method=method, weights=weights,
                          shape_scan=shape_scan)
            for i in range(len(data.labels))
        ]  # fmt: skip
    free = _checked_free(model, free)
    if not free:
        raise ValueError("no free parameters to fit")
    method = resolve_method(method, model, data)
    w = _channel_weights(data, weights)
    grids = _start_grids(model, data, free, shape_scan)
    start, _ = _linear_start(model, data, free, w, grids)
    for effect in model.effects:
        if effect in free and CATALOGUE[effect].parity == "even" and model.coefficient(effect) == 0:
            start = _scan_coefficient(start, data, effect, method, w)
    # The linearised start is only as good as the single-harmonic picture; keep the better.
    forcing = data.excitation_harmonics
    given_cost = np.sum(_normalised(data, predict_channels(
        model, data.amplitude_m, data.channels, method=method, excitation_harmonics=forcing),
        w) ** 2)  # fmt: skip
    start_cost = np.sum(_normalised(data, predict_channels(
        start, data.amplitude_m, data.channels, method=method, excitation_harmonics=forcing),
        w) ** 2)  # fmt: skip
    if given_cost < start_cost:
        start = model
    return _refine(start, data, free, method, w, weights)


def _start_grids(
    model: JointModel,
    data: FitData,
    free: Sequence[str],
    shape_scan: Mapping[str, ArrayLike] | None,
) -> dict[str, dict[str, np.ndarray]]:
    """Shape grids by effect: defaults for new effects (coefficient 0), plus ``shape_scan``."""
    grids: dict[str, dict[str, np.ndarray]] = {}
    for term in model.terms:
        new = term.coefficient == 0 and any(n.startswith(f"{term.effect}.") for n in free)
        if new:
            grids[term.effect] = default_shape_grid(term.effect, data, model)
    for name, values in (shape_scan or {}).items():
        if "." not in name or name not in model.parameter_names:
            raise ValueError(
                f"shape_scan: {name!r} is not a shape parameter of the model "
                f"({[n for n in model.parameter_names if '.' in n]})"
            )
        values = np.atleast_1d(np.asarray(values, dtype=float))
        if values.size == 0 or not np.all(np.isfinite(values) & (values > 0)):
            raise ValueError(f"shape_scan[{name!r}] must be finite values > 0")
        effect, shape = name.split(".", 1)
        grids.setdefault(effect, {})[shape] = values
    return grids


#: A fit stops once ``STALL_ITERATIONS`` iterations have improved the information
#: criteria by less than ``STALL_IC`` in all: over-parametrised models (e.g. a
#: tanh whose x_s drifts towards the linear limit, traded against x and x³) crawl
#: along flat valleys for hundreds of iterations at a few hundredths per step,
#: while the criticism decides on differences of 10.
STALL_ITERATIONS, STALL_IC = 10, 0.1


def _refine(
    start: JointModel,
    data: FitData,
    free: Sequence[str],
    method: str,
    weights: np.ndarray,
    weight_map: Mapping[str, float] | None,
) -> FitResult:
    """Nonlinear least squares from ``start``: log-parameters for shapes, relative otherwise."""
    is_log = np.array(["." in n for n in free])
    limits = np.array(
        [shape_bounds(n, data, start) if log else (-np.inf, np.inf)
         for n, log in zip(free, is_log, strict=True)]
    )  # fmt: skip
    p0 = np.array([start.parameters[n] for n in free])
    p0 = np.where(is_log, np.clip(p0, limits[:, 0] * 1.001, limits[:, 1] / 1.001), p0)
    start = start.with_parameters(dict(zip(free, p0, strict=True)))
    f = data.values[:, data.column("frequency_hz")]
    omega = 2 * np.pi * np.median(f)
    scale = np.array([
        abs(p) if p != 0 else natural_coefficient(n, data.amplitude_m.max(), omega,
                                                   _stiffness(start, data))
        for n, p in zip(free, p0, strict=True)
    ])  # fmt: skip

    def values(u: np.ndarray) -> np.ndarray:
        return np.where(is_log, p0 * np.exp(np.where(is_log, u, 0.0)), p0 + scale * u)

    def residuals(u: np.ndarray) -> np.ndarray:
        """Normalised residuals of each row of ``u`` (one harmonic-balance call for all)."""
        predicted = predict_channels(
            start, data.amplitude_m, data.channels, method=method, parameters=values(u),
            names=free, excitation_harmonics=data.excitation_harmonics,
        )  # fmt: skip
        return np.stack([_normalised(data, p, weights) for p in predicted])

    with np.errstate(divide="ignore", invalid="ignore"):
        lower = np.where(is_log, np.log(limits[:, 0] / p0), -np.inf)
        upper = np.where(is_log, np.log(limits[:, 1] / p0), np.inf)
    # Multi-harmonic solutions are converged to ~1e-10: coarser steps than √eps.
    relative_step = 1e-6 if method == "multi" else np.sqrt(np.finfo(float).eps)

    last: dict[str, np.ndarray] = {}
    best: dict[str, np.ndarray] = {"u": np.zeros(len(free))}

    def residual(u: np.ndarray) -> np.ndarray:
        if not np.isfinite(u).all():
            raise _NoPeriodicSolution  # a step computed from an overflowed Jacobian
        last["u"], last["r"] = u.copy(), residuals(u[None])[0]
        with np.errstate(over="ignore"):
            cost = float(last["r"] @ last["r"])
        if np.isfinite(cost) and cost < best.get("cost", np.inf):
            best["u"], best["cost"] = u.copy(), cost
        return last["r"]

    def jacobian(u: np.ndarray) -> np.ndarray:
        """Forward differences as scipy takes them, all columns in one batched call.

        The residual at ``u`` is the one least squares has just evaluated there.
        """
        step = relative_step * np.where(u >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(u))
        step = np.where(u + step > upper, -step, step)  # one-sided the other way at a bound
        step = (u + step) - u
        at_u = last["r"] if np.array_equal(last.get("u"), u) else residuals(u[None])[0]
        with np.errstate(over="ignore", invalid="ignore"):
            columns = (residuals(u + np.diag(step)) - at_u) / step[:, None]
        if not np.isfinite(columns).all():
            raise _NoPeriodicSolution
        return columns.T

    costs: list[float] = []

    def stop_when_stalled(intermediate_result) -> None:
        # cost = ½Σz², so the information criteria move by twice its change.
        costs.append(intermediate_result.cost)
        if (
            len(costs) > STALL_ITERATIONS
            and 2 * (costs[-STALL_ITERATIONS - 1] - costs[-1]) < STALL_IC
        ):
            raise StopIteration

    # BLAS threads on these tiny matrices only spin, taking the core the
    # harmonic-balance threads need.
    with threadpool_limits(1, user_api="blas"):
        try:
            solution = least_squares(
                residual,
                np.zeros(len(free)),
                jac=jacobian,
                bounds=(lower, upper),
                x_scale="jac",
                ftol=1e-10,
                xtol=1e-10,
                gtol=1e-10,
                max_nfev=60 * (len(free) + 1),
                callback=stop_when_stalled,
            )
        except (_NoPeriodicSolution, ValueError) as error:
            # scipy refuses a Jacobian whose entries overflowed ("array must not contain
            # infs or NaNs"): the prediction left every periodic solution behind there.
            if not isinstance(error, _NoPeriodicSolution) and "infs or NaNs" not in str(error):
                raise
            solution = None
    if solution is not None and not np.isfinite(solution.cost):
        solution = None  # it never left a start whose response is absurd
    if solution is None:
        # A named outcome, not a traceback: the best model the optimiser could evaluate.
        fitted = start.with_parameters(dict(zip(free, values(best["u"]), strict=True)))
        return evaluate(
            fitted, data, method=method, weights=weight_map, free=free, success=False,
            message="met parameters without a periodic solution at some measured amplitudes",
            outcome=FitOutcome.NO_PERIODIC_SOLUTION,
        )  # fmt: skip
    stalled = solution.status == -2
    fitted = start.with_parameters(dict(zip(free, values(solution.x), strict=True)))
    return evaluate(
        fitted, data, method=method, weights=weight_map, free=free,
        success=bool(solution.success or stalled),
        message=f"stalled: AIC/BIC moved < {STALL_IC} in {STALL_ITERATIONS} iterations"
        if stalled else str(solution.message),
        outcome=FitOutcome.STALLED if stalled else FitOutcome.CONVERGED if solution.success
        else FitOutcome.NOT_CONVERGED,
    )  # fmt: skip


class _NoPeriodicSolution(Exception):
    """The optimiser met parameters whose prediction is not finite (no periodic solution)."""
