"""Fitting a JointModel's coefficients to measured backbones through harmonic balance.

The model's named parameters (:attr:`JointModel.parameter_names`: coefficients
and shape parameters such as ``microslip.k_t`` or ``stribeck_friction.v_s``) are
fitted by least squares (:func:`scipy.optimize.least_squares`) so that its
harmonic-balance backbone (:func:`identification.analytical.harmonic.backbone`) meets the
measured ones in **both** channels: friction shows in the damping, stiffness in
the frequency. With test records, the higher harmonics of the response are a
third channel (:func:`extract_harmonics`): even terms such as ``x²`` leave a
second harmonic, ``x³`` a third, where the backbone alone cannot tell them apart.

Residuals are normalised per amplitude level by the measured scatter across
curves (assembly-to-assembly variability), combined with a stated noise floor
(:data:`NOISE_FLOOR`), so a population-mean model is judged against the
spread the test itself shows. The log-likelihood is that of independent
Gaussian residuals with those standard deviations; AIC and BIC count the fitted
parameters.

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
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

from identification.analytical.harmonic import backbone
from identification.effects import CATALOGUE, get_effect
from identification.measurements.backbone import (
    BackboneSet,
    ShortHoldError,
    fourier_basis,
    hold_window,
)
from identification.measurements.records import Record
from identification.model import JointModel

__all__ = [
    "BACKBONE_CHANNELS",
    "HARMONIC_CHANNELS",
    "NOISE_FLOOR",
    "FitData",
    "FitResult",
    "HoldHarmonics",
    "default_free",
    "default_shape_grid",
    "evaluate",
    "extract_harmonics",
    "fit_backbones",
    "fit_data",
    "measurement_levels",
    "predict_channels",
    "resolve_method",
    "shape_bounds",
]

#: Backbone channels: frequency (Hz) and power-balance damping ratio.
BACKBONE_CHANNELS = ("frequency_hz", "damping_ratio")
#: Higher-harmonic channels from test records: ``C_h/a`` and ``S_h/a`` of the relative
#: displacement ``x = a cos θ + Σ_h C_h cos hθ + S_h sin hθ`` (fractions of the fundamental).
HARMONIC_ORDERS = (2, 3)
HARMONIC_CHANNELS = tuple(f"harmonic{h}_{part}" for h in HARMONIC_ORDERS for part in ("cos", "sin"))
#: Noise floors combined with the measured scatter: frequency (Hz), damping ratio (1),
#: harmonics (fraction of the fundamental). The harmonics floor stands for what a real
#: rig adds (shaker distortion, sensor nonlinearity) beyond the fit's standard error.
NOISE_FLOOR = {"frequency_hz": 0.02, "damping_ratio": 2e-5, "harmonics": 1e-3}
#: Harmonics balanced by ``method="multi"``.
N_HARMONICS = 5
#: Normalised residual given to a point where the model has no backbone (HB failure).
_FAILED_RESIDUAL = 1e3


def _floor_key(channel: str) -> str:
    return "harmonics" if channel.startswith("harmonic") else channel


# --------------------------------------------------------------------------
# Higher harmonics of test records


@dataclass(frozen=True)
class HoldHarmonics:
    """Higher harmonics of the relative displacement, one row per hold phase of a record.

    Attributes
    ----------
    label
        Record name (the backbone curve's label).
    amplitude_m
        Fundamental amplitude ``|Q_1|`` (m).
    relative
        ``(n_holds, len(HARMONIC_ORDERS))`` complex ``Q_h e^{-ih arg Q_1} / |Q_1|``: the
        harmonic in the frame where the fundamental is ``a cos θ``, so that its real
        part is ``C_h/a`` and minus its imaginary part ``S_h/a``.
    standard_error
        Standard error of each real component of ``relative`` (from the fit residual).
    """

    label: str
    amplitude_m: np.ndarray
    relative: np.ndarray
    standard_error: np.ndarray


def _hold_harmonics(
    time_s: np.ndarray,
    response_velocity: np.ndarray,
    frequency_hz: np.ndarray,
    n_periods: int,
    harmonics: int,
) -> tuple[float, np.ndarray, np.ndarray]:
    """Fundamental amplitude, relative harmonics and their standard errors of one hold.

    The window of :func:`identification.measurements.backbone.hold_window` (the one backbone
    points use), a constant plus ``harmonics`` harmonics fitted to the velocity.
    The displacement's mean is not observable from velocities, so only ``h ≥ 1``.
    """
    try:
        start, phi, omega = hold_window(time_s, frequency_hz, n_periods)
    except ShortHoldError as short:  # use the whole periods there are
        if short.periods < 1:
            raise ValueError("the hold phase is shorter than one period") from None
        start, phi, omega = hold_window(time_s, frequency_hz, int(short.periods))
    k = np.arange(1, harmonics + 1)
    basis = fourier_basis(phi, harmonics)
    coef, *_ = np.linalg.lstsq(basis, response_velocity[start:], rcond=None)
    dof = max(phi.size - basis.shape[1], 1)
    variance = np.sum((response_velocity[start:] - basis @ coef) ** 2) / dof
    se_velocity = np.sqrt(variance * np.diag(np.linalg.inv(basis.T @ basis)))[1 : 1 + harmonics]
    velocity = coef[1 : 1 + harmonics] - 1j * coef[1 + harmonics :]  # v = Re(V e^{ihφ})
    displacement = velocity / (1j * k * omega)
    rotated = displacement * np.exp(-1j * k * np.angle(displacement[0]))
    amplitude = abs(displacement[0])
    return amplitude, rotated[1:] / amplitude, se_velocity[1:] / (k[1:] * omega * amplitude)


def extract_harmonics(records: Iterable[Record], n_periods: int = 70) -> dict[str, HoldHarmonics]:
    """Second and third harmonics of every hold phase of every record, by record name.

    Uses the same hold phases and window as
    :func:`identification.measurements.backbone.extract_backbone` (a hold shorter than
    ``n_periods`` uses its whole periods), so row ``i`` belongs to backbone point ``i``.
    """
    out = {}
    for record in records:
        rows = []
        where = record.path or record.name
        for hold in record.steps.holds():
            t = record.time_s
            window = slice(
                np.searchsorted(t, hold.start_s), np.searchsorted(t, hold.end_s, "right")
            )
            try:
                rows.append(
                    _hold_harmonics(
                        t[window],
                        record.response_velocity[window],
                        record.frequency_hz[window],
                        n_periods,
                        max(HARMONIC_ORDERS),
                    )
                )
            except ValueError as exc:
                raise ValueError(f"{where}: hold phase at level {hold.level:g}: {exc}") from None
        if not rows:
            raise ValueError(f"{where}: no hold phase in the step schedule")
        out[record.name] = HoldHarmonics(
            label=record.name,
            amplitude_m=np.array([r[0] for r in rows]),
            relative=np.array([r[1] for r in rows]),
            standard_error=np.array([r[2] for r in rows]),
        )
    return out


# --------------------------------------------------------------------------
# Measured data in fitting form


def measurement_levels(measured: BackboneSet) -> np.ndarray:
    """Amplitude levels (m) where measured and predicted backbones are compared.

    Quantiles of the measured amplitudes inside the range every curve shares, as
    many as a curve has points there: the levels follow the test's own spacing
    (geometric steps put many levels at small amplitudes, where friction acts).

    Raises
    ------
    ValueError
        If a curve has fewer than 3 points in the shared range (too sparse to compare).
    """
    low, high = measured.common_range()
    counts, pooled = [], []
    for curve in measured:
        a = curve.amplitude_m
        inside = a[(a >= low * (1 - 1e-12)) & (a <= high * (1 + 1e-12))]
        if np.unique(inside).size < 3:
            raise ValueError(
                f"curve {curve.label!r} has {np.unique(inside).size} backbone point(s) in the "
                f"range all curves share ({1e3 * low:.4g}–{1e3 * high:.4g} mm); at least 3 are "
                "needed to compare model and measurement"
            )
        counts.append(np.unique(inside).size)
        pooled.append(inside)
    n = int(np.clip(np.median(counts), 3, 41))
    levels = np.quantile(np.concatenate(pooled), np.linspace(0.0, 1.0, n))
    return np.unique(np.clip(levels, low, high))


@dataclass(frozen=True)
class FitData:
    """Measured points of several curves, with the standard deviation of each value.

    Attributes
    ----------
    labels
        Curve labels.
    curve
        ``(n_points,)`` index into ``labels`` of each point.
    amplitude_m
        ``(n_points,)`` fundamental amplitudes (m).
    channels
        Channel names (:data:`BACKBONE_CHANNELS`, then :data:`HARMONIC_CHANNELS` with records).
    values
        ``(n_points, n_channels)`` measured values; NaN where a curve lacks a channel.
    sigma
        ``(n_points, n_channels)`` standard deviation: scatter across curves at that
        amplitude combined with the noise floor (and, for harmonics, the fit's error).
    levels_m
        Amplitude levels of the comparison (:func:`measurement_levels`).
    level_sigma
        ``(n_levels, n_channels)`` scatter across curves ⊕ noise floor at the levels.
    standard_error
        ``(n_points, n_channels)`` standard error of each measured value where known
        (record harmonics), else 0.
    noise_floor
        The noise floors used (:data:`NOISE_FLOOR` keys).
    """

    labels: tuple[str, ...]
    curve: np.ndarray
    amplitude_m: np.ndarray
    channels: tuple[str, ...]
    values: np.ndarray
    sigma: np.ndarray
    levels_m: np.ndarray
    level_sigma: np.ndarray

    standard_error: np.ndarray
    noise_floor: Mapping[str, float]

    @property
    def n_points(self) -> int:
        return self.amplitude_m.size

    @property
    def has_harmonics(self) -> bool:
        return any(c in HARMONIC_CHANNELS for c in self.channels)

    def column(self, channel: str) -> int:
        return self.channels.index(channel)

    def at_levels(self, per_point: np.ndarray) -> np.ndarray:
        """``(n_curves, n_levels, n_channels)`` per-point values interpolated to the levels."""
        return _at_levels(len(self.labels), self.curve, self.amplitude_m, self.levels_m, per_point)

    def level_mean(self, per_point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean over curves at the levels ``(n_levels, n_channels)`` and its standard error."""
        values = self.at_levels(per_point)
        count = np.sum(np.isfinite(values), axis=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # channels no curve has
            mean = np.nanmean(values, axis=0)
        return mean, self.level_sigma / np.sqrt(np.maximum(count, 1))

    def subset(self, index: int) -> FitData:
        """The data of curve ``index`` alone (its standard deviations from the noise floor)."""
        rows = self.curve == index
        return _assemble(
            (self.labels[index],),
            np.zeros(rows.sum(), dtype=int),
            self.amplitude_m[rows],
            self.channels,
            self.values[rows],
            self.standard_error[rows],
            self.levels_m,
            self.noise_floor,
        )


def _at_levels(
    n_curves: int, curve: np.ndarray, amplitude: np.ndarray, levels: np.ndarray, per_point
) -> np.ndarray:
    """Per-point values of each curve interpolated to the levels, linear in log-amplitude.

    Points at equal amplitude are averaged; NaN where a curve lacks the channel or
    does not reach a level.
    """
    out = np.full((n_curves, levels.size, per_point.shape[1]), np.nan)
    log_levels = np.log(levels)
    for i in range(n_curves):
        rows = curve == i
        unique, inverse = np.unique(amplitude[rows], return_inverse=True)
        if unique.size < 2:
            continue
        counts = np.bincount(inverse)
        inside = (levels >= unique[0] * (1 - 1e-12)) & (levels <= unique[-1] * (1 + 1e-12))
        for j in range(per_point.shape[1]):
            column = per_point[rows, j]
            if not np.isfinite(column).all():
                continue
            mean = np.bincount(inverse, weights=column) / counts
            out[i, inside, j] = np.interp(log_levels[inside], np.log(unique), mean)
    return out


def fit_data(
    measured: BackboneSet,
    harmonics: Mapping[str, HoldHarmonics] | None = None,
    noise_floor: Mapping[str, float] | None = None,
) -> FitData:
    """Measured backbones (and record harmonics) in fitting form.

    Parameters
    ----------
    measured
        The measured backbones.
    harmonics
        :func:`extract_harmonics` of the curves' records, by label; every curve must
        have its entry, with one row per backbone point.
    noise_floor
        Overrides of :data:`NOISE_FLOOR` (keys ``frequency_hz``, ``damping_ratio``,
        ``harmonics``).
    """
    if not isinstance(measured, BackboneSet) or len(measured) == 0:
        raise ValueError("measured must be a non-empty BackboneSet")
    floor = dict(NOISE_FLOOR)
    for key, value in (noise_floor or {}).items():
        if key not in floor:
            raise ValueError(f"unknown noise_floor key {key!r}; use {sorted(floor)}")
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"noise_floor[{key!r}] must be finite and > 0, got {value}")
        floor[key] = float(value)
    channels = BACKBONE_CHANNELS + (HARMONIC_CHANNELS if harmonics else ())
    curve, amplitude, values, errors = [], [], [], []
    for i, b in enumerate(measured):
        block = np.full((len(b), len(channels)), np.nan)
        se = np.zeros_like(block)
        block[:, 0], block[:, 1] = b.frequency_hz, b.damping_ratio
        if harmonics:
            if b.label not in harmonics:
                raise ValueError(
                    f"no record harmonics for curve {b.label!r} (records: {sorted(harmonics)})"
                )
            h = harmonics[b.label]
            if h.amplitude_m.size != len(b):
                raise ValueError(
                    f"curve {b.label!r}: {len(b)} backbone points but {h.amplitude_m.size} hold "
                    "phases in its record (extract both with the same n_periods)"
                )
            parts = np.stack([h.relative.real, -h.relative.imag], axis=-1).reshape(len(b), -1)
            block[:, 2:] = parts
            se[:, 2:] = np.repeat(h.standard_error, 2, axis=1)
        curve.append(np.full(len(b), i))
        amplitude.append(b.amplitude_m)
        values.append(block)
        errors.append(se)
    if any((a <= 0).any() for a in amplitude):
        raise ValueError("measured backbones have points of zero amplitude")
    return _assemble(
        tuple(measured.labels),
        np.concatenate(curve),
        np.concatenate(amplitude),
        channels,
        np.vstack(values),
        np.vstack(errors),
        measurement_levels(measured),
        floor,
    )


def _assemble(labels, curve, amplitude, channels, values, errors, levels, floor) -> FitData:
    """FitData with the scatter across curves at the levels and per point."""
    at_levels = _at_levels(len(labels), curve, amplitude, levels, values)
    floors = np.array([floor[_floor_key(c)] for c in channels])
    scatter = np.zeros((levels.size, len(channels)))
    if len(labels) > 1:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # channels fewer than two curves have
            scatter = np.nan_to_num(np.nanstd(at_levels, axis=0, ddof=1))
    level_sigma = np.hypot(scatter, floors)
    point_scatter = np.column_stack(
        [np.interp(np.log(amplitude), np.log(levels), scatter[:, j]) for j in range(len(channels))]
    )
    sigma = np.sqrt(point_scatter**2 + floors**2 + errors**2)
    return FitData(
        labels, curve, amplitude, channels, values, sigma, levels, level_sigma, errors, floor
    )


# --------------------------------------------------------------------------
# Model predictions in the channel layout


def resolve_method(method: str, model: JointModel, data: FitData | None = None) -> str:
    """``"auto"``: multi-harmonic balance when the model has even terms or the data
    harmonics, else the (much faster) single-harmonic balance."""
    if method == "auto":
        even = any(CATALOGUE[e].parity != "odd" for e in model.effects)
        return "multi" if even or (data is not None and data.has_harmonics) else "single"
    if method not in ("single", "multi"):
        raise ValueError(f"method must be 'auto', 'single' or 'multi', got {method!r}")
    if method == "single" and data is not None and data.has_harmonics:
        raise ValueError("record harmonics need method='multi' (or 'auto')")
    return method


def predict_channels(
    model: JointModel,
    amplitude_m: ArrayLike,
    channels: Sequence[str] = BACKBONE_CHANNELS,
    *,
    method: str = "single",
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
) -> np.ndarray:
    """Model prediction of each channel at the given amplitudes.

    Returns ``(n_points, n_channels)``, or ``(n_sets, n_points, n_channels)`` with
    ``parameters`` (see :func:`identification.analytical.harmonic.backbone`); NaN where the
    harmonic balance has no solution.
    """
    a = np.asarray(amplitude_m, dtype=float)
    unique, inverse = np.unique(a, return_inverse=True)
    harmonic_channels = [c for c in channels if c in HARMONIC_CHANNELS]
    if harmonic_channels and method != "multi":
        raise ValueError(f"channels {harmonic_channels} need method='multi'")
    result = backbone(
        model, unique, parameters=parameters, names=names, method=method, harmonics=N_HARMONICS
    )
    columns = []
    for channel in channels:
        if channel == "frequency_hz":
            columns.append(result.frequency_hz)
        elif channel == "damping_ratio":
            columns.append(result.damping_ratio)
        elif channel in HARMONIC_CHANNELS:
            order, part = int(channel[len("harmonic")]), channel.rsplit("_", 1)[1]
            table = result.harmonics_cos_m if part == "cos" else result.harmonics_sin_m
            columns.append(table[..., order] / unique)
        else:
            raise ValueError(f"unknown channel {channel!r}")
    return np.stack(columns, axis=-1)[..., inverse, :]


# --------------------------------------------------------------------------
# Fit results


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
        Gaussian log-likelihood of the weighted normalised residuals and the
        information criteria with ``n_parameters = len(free)`` (or the count given).
    n_residuals
        Number of residual entries (points × channels with data and weight).
    success, message
        Optimiser outcome.
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

    @property
    def residual(self) -> np.ndarray:
        """Measured minus predicted, ``(n_points, n_channels)``."""
        return self.data.values - self.predicted

    def level_residual(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean residual over curves at the levels and its standard error."""
        return self.data.level_mean(self.residual)

    def _rmse(self, channels: Sequence[str]) -> float | None:
        columns = [self.data.column(c) for c in channels if c in self.data.channels]
        if not columns:
            return None
        mean, _ = self.level_residual()
        return float(np.sqrt(np.nanmean(np.sum(mean[:, columns] ** 2, axis=1))))

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
        (fraction of the fundamental); None without record harmonics."""
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
    """Weighted normalised residuals of the entries that count (failures penalised)."""
    used = np.isfinite(data.values) & (weights > 0)
    z = weights * (data.values - predicted) / data.sigma
    z = np.where(np.isfinite(z), z, _FAILED_RESIDUAL)
    return z[used]


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
) -> FitResult:
    """The model as it is against the data (no fitting).

    ``n_parameters`` is what the information criteria count (default ``len(free)``);
    give the model's number of adjustable parameters to compare it with refitted ones.
    """
    method = resolve_method(method, model, data)
    w = _channel_weights(data, weights)
    predicted = predict_channels(model, data.amplitude_m, data.channels, method=method)
    used = np.isfinite(data.values) & (w > 0)
    sigma = (data.sigma / np.where(w > 0, w, 1.0))[used]
    z = ((data.values - predicted) / data.sigma * w)[used]
    n = int(used.sum())
    k = len(free) if n_parameters is None else int(n_parameters)
    if np.isfinite(z).all():
        loglik = float(np.sum(-0.5 * z**2 - np.log(sigma)) - 0.5 * n * np.log(2 * np.pi))
    else:
        loglik, success = -np.inf, False
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
    )


# --------------------------------------------------------------------------
# Parameters


def default_free(model: JointModel) -> list[str]:
    """Every parameter of the model except the Jenkins element's coefficient.

    ``c·Jenkins(x; k_t, F_s) = Jenkins(x; c·k_t, c·F_s)``: with ``k_t`` and ``F_s``
    free the coefficient is redundant, so it stays fixed (usually at 1).
    """
    names = model.parameter_names
    return [n for n in names if not (n == "microslip" and "microslip.k_t" in names)]


def _checked_free(model: JointModel, free: Sequence[str] | None) -> list[str]:
    if free is None:
        return default_free(model)
    free = list(free)
    unknown = [n for n in free if n not in model.parameter_names]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown}; the model has {model.parameter_names}")
    if len(set(free)) != len(free):
        raise ValueError(f"free parameters repeat: {free}")
    if {"microslip", "microslip.k_t", "microslip.F_s"} <= set(free):
        raise ValueError(
            "microslip's coefficient, k_t and F_s cannot all be free: c·Jenkins(k_t, F_s) = "
            "Jenkins(c·k_t, c·F_s); leave the coefficient out"
        )
    return free


def _natural_coefficient(effect: str, amplitude_m: float, omega: float, stiffness: float) -> float:
    """Coefficient at which the term's force reaches the linear force ``k·a`` at amplitude ``a``."""
    spec = get_effect(effect)
    theta = np.linspace(0.0, 2 * np.pi, 64, endpoint=False)
    x, v = amplitude_m * np.cos(theta), -amplitude_m * omega * np.sin(theta)
    peak = np.max(np.abs(spec.feature(x, v, **spec.defaults)))
    return stiffness * amplitude_m / peak if peak > 0 else 1.0


def default_shape_grid(effect: str, data: FitData, model: JointModel) -> dict[str, np.ndarray]:
    """Shape-parameter values scanned for the start of a newly added effect.

    Spans the measured amplitude (or velocity) range, so that e.g. the slip onset
    of microslip or the Stribeck velocity can fall anywhere in the test.
    """
    a_lo, a_hi = data.amplitude_m.min(), data.amplitude_m.max()
    f = data.values[:, data.column("frequency_hz")]
    v_lo, v_hi = a_lo * 2 * np.pi * f.min(), a_hi * 2 * np.pi * f.max()
    if effect == "microslip":
        # The linear solve fits the coefficient, so only the slip amplitude F_s/k_t matters.
        k_ref = 0.1 * _stiffness(model, data)
        return {"k_t": np.array([k_ref]), "F_s": k_ref * np.geomspace(a_lo / 2, a_hi, 16)}
    if effect == "stribeck_friction":
        return {"v_s": np.geomspace(v_lo / 3, 10 * v_hi, 16)}
    if effect == "tanh_saturation":
        return {"x_s": np.geomspace(a_lo / 3, 10 * a_hi, 16)}
    if effect == "exponential":
        return {"x_s": np.geomspace(a_hi / 3, 30 * a_hi, 16)}
    return {}


def shape_bounds(name: str, data: FitData, model: JointModel) -> tuple[float, float]:
    """Range a fitted shape parameter may take, from the test's amplitudes and velocities.

    A shape far outside what the test resolves lets the fit exploit numerics, not
    physics (e.g. a Stribeck velocity far below the smallest response velocity
    makes a force spike the harmonic balance's time grid cannot resolve).
    """
    a_lo, a_hi = data.amplitude_m.min(), data.amplitude_m.max()
    f = data.values[:, data.column("frequency_hz")]
    v_lo, v_hi = a_lo * 2 * np.pi * f.min(), a_hi * 2 * np.pi * f.max()
    k = _stiffness(model, data)
    bounds = {
        "stribeck_friction.v_s": (v_lo / 10, 100 * v_hi),
        "tanh_saturation.x_s": (a_lo / 10, 100 * a_hi),
        "exponential.x_s": (a_hi / 10, 1e3 * a_hi),
        "microslip.k_t": (1e-4 * k, 10 * k),
        "microslip.F_s": (1e-5 * k * a_lo, 100 * k * a_hi),
    }
    value = model.parameters[name]
    return bounds.get(name, (value * math.exp(-30), value * math.exp(30)))


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
        if term.effect == "microslip":
            return bool(free_set & {"microslip", "microslip.k_t", "microslip.F_s"})
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
            if term.effect == "microslip" and "microslip" not in free_set:
                scale = c / (term.coefficient if term.coefficient != 0 else 1.0)
                if not scale > 0:
                    cost = np.inf  # a Jenkins element cannot stiffen with amplitude
                    break
                values["microslip.k_t"] = scale * term.shape["k_t"]
                values["microslip.F_s"] = scale * term.shape["F_s"]
                if term.coefficient == 0:
                    values["microslip"] = 1.0
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
    scale = _natural_coefficient(
        effect, data.amplitude_m.max(), 2 * np.pi * np.median(f), _stiffness(model, data)
    )
    magnitudes = np.geomspace(1e-4, 1.0, 17)
    grid = scale * np.concatenate([-magnitudes[::-1], [0.0], magnitudes])
    predicted = predict_channels(
        model, data.amplitude_m, data.channels, method=method, parameters=grid[:, None],
        names=[effect],
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
    harmonics: Mapping[str, HoldHarmonics] | None = None,
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
        Measured backbones (or a ready :class:`FitData`).
    free
        Parameters to fit; default :func:`default_free`.
    method
        ``"single"``, ``"multi"`` or ``"auto"`` (:func:`resolve_method`).
    weights
        Channel weights ``{"frequency_hz", "damping_ratio", "harmonics"}`` (default 1);
        e.g. ``{"damping_ratio": 0}`` fits the frequency alone, as the paper does.
    shape_scan
        Grids of shape parameters for the start, by parameter name
        (``{"microslip.F_s": [...]}``); the product of the grids is scanned.
    harmonics
        Record harmonics (:func:`extract_harmonics`) fitted as a third channel.
    noise_floor
        Overrides of :data:`NOISE_FLOOR`.
    per_curve
        Fit every curve on its own: returns one :class:`FitResult` per curve.

    Returns
    -------
    FitResult, or a list of them with ``per_curve``.
    """
    data = measured if isinstance(measured, FitData) else fit_data(measured, harmonics, noise_floor)
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
    given_cost = np.sum(_normalised(data, predict_channels(
        model, data.amplitude_m, data.channels, method=method), w) ** 2)  # fmt: skip
    start_cost = np.sum(_normalised(data, predict_channels(
        start, data.amplitude_m, data.channels, method=method), w) ** 2)  # fmt: skip
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
        abs(p) if p != 0 else _natural_coefficient(n, data.amplitude_m.max(), omega,
                                                   _stiffness(start, data))
        for n, p in zip(free, p0, strict=True)
    ])  # fmt: skip

    def values(u: np.ndarray) -> np.ndarray:
        return np.where(is_log, p0 * np.exp(np.where(is_log, u, 0.0)), p0 + scale * u)

    def residuals(u: np.ndarray) -> np.ndarray:
        """Normalised residuals of each row of ``u`` (one harmonic-balance call for all)."""
        predicted = predict_channels(
            start, data.amplitude_m, data.channels, method=method, parameters=values(u),
            names=free,
        )  # fmt: skip
        return np.stack([_normalised(data, p, weights) for p in predicted])

    with np.errstate(divide="ignore", invalid="ignore"):
        lower = np.where(is_log, np.log(limits[:, 0] / p0), -np.inf)
        upper = np.where(is_log, np.log(limits[:, 1] / p0), np.inf)
    # Multi-harmonic solutions are converged to ~1e-10: coarser steps than √eps.
    relative_step = 1e-6 if method == "multi" else np.sqrt(np.finfo(float).eps)

    last: dict[str, np.ndarray] = {}

    def residual(u: np.ndarray) -> np.ndarray:
        last["u"], last["r"] = u.copy(), residuals(u[None])[0]
        return last["r"]

    def jacobian(u: np.ndarray) -> np.ndarray:
        """Forward differences as scipy takes them, all columns in one batched call.

        The residual at ``u`` is the one least squares has just evaluated there.
        """
        step = relative_step * np.where(u >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(u))
        step = np.where(u + step > upper, -step, step)  # one-sided the other way at a bound
        step = (u + step) - u
        at_u = last["r"] if np.array_equal(last.get("u"), u) else residuals(u[None])[0]
        return ((residuals(u + np.diag(step)) - at_u) / step[:, None]).T

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
    stalled = solution.status == -2
    fitted = start.with_parameters(dict(zip(free, values(solution.x), strict=True)))
    return evaluate(
        fitted, data, method=method, weights=weight_map, free=free,
        success=bool(solution.success or stalled),
        message=f"stalled: AIC/BIC moved < {STALL_IC} in {STALL_ITERATIONS} iterations"
        if stalled else str(solution.message),
    )  # fmt: skip
