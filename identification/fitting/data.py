"""Measured backbones in fitting form: channels, curves at levels, and one likelihood.

A model is compared with measured backbones in **channels**: the frequency and
the power-balance damping ratio of every point (:data:`BACKBONE_CHANNELS`), and,
where the backbones carry the higher harmonics their hold fits measured
(:class:`identification.measurements.backbone.Backbone`), the 2nd and 3rd
harmonics of the response as a third kind (:data:`HARMONIC_CHANNELS`): even
terms such as ``x²`` leave a second harmonic, ``x³`` a third, where the
backbone alone cannot tell them apart.

**The likelihood.** Each curve is interpolated to common amplitude levels
(:func:`measurement_levels`; linear in log-amplitude, each branch of a test that
steps up and down on its own, the branches then averaged, which cancels a drift
linear in time). A population-mean model meets the *mean* curve, and the points
of one curve share that assembly's offsets, so the residual of the mean curve,
``r = mean_c(Y_c − μ_c)`` (``L`` levels × ``C`` channels), is Gaussian with the
covariance ``V = Σ/n + diag(floor²)`` of :mod:`identification.fitting.covariance`:
``Σ`` the between-curve covariance estimated from the curves themselves (shrunk,
heteroscedastic, floored by the hold fits' standard errors), ``floor`` the stated
systematic floors (:data:`NOISE_FLOOR`). ``Σ`` does not depend on the model, so
every model is judged in the same metric: fits minimise ``rᵀV⁻¹r``
(:meth:`FitData.whitened`), and the criticism's tests use the same quantity.

Each point also keeps the harmonics of the base acceleration its hold measured,
the forcing the model's prediction at that point is driven by
(:func:`identification.fitting.prediction.predict_channels`).
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from identification.fitting import covariance as cov
from identification.measurements.backbone import Backbone, BackboneSet

__all__ = [
    "BACKBONE_CHANNELS",
    "FAILED_RESIDUAL",
    "HARMONIC_CHANNELS",
    "HARMONIC_ORDERS",
    "NOISE_FLOOR",
    "FitData",
    "Metric",
    "fit_data",
    "measurement_levels",
]

#: Backbone channels: frequency (Hz) and power-balance damping ratio.
BACKBONE_CHANNELS = ("frequency_hz", "damping_ratio")
#: Higher-harmonic channels from the hold fits: ``C_h/a`` and ``S_h/a`` of the relative
#: displacement ``x = a cos θ + Σ_h C_h cos hθ + S_h sin hθ`` (fractions of the fundamental).
HARMONIC_ORDERS = (2, 3)
HARMONIC_CHANNELS = tuple(f"harmonic{h}_{part}" for h in HARMONIC_ORDERS for part in ("cos", "sin"))
#: Systematic floors of the mean curve: frequency (Hz), damping ratio (1), harmonics
#: (fraction of the fundamental). They stand for what the measurement chain adds that
#: does not average out over curves (a phase offset of the lock shifts the frequency by
#: about f·ζ·tan φ: 0.016 Hz at 101 Hz, 0.3 % damping and 3°; sensor nonlinearity and
#: shaker distortion leak into the harmonics).
NOISE_FLOOR = {"frequency_hz": 0.02, "damping_ratio": 2e-5, "harmonics": 1e-3}
#: Whitened residual given to an entry where the model has no backbone (no periodic solution).
FAILED_RESIDUAL = 1e3


def _floor_key(channel: str) -> str:
    return "harmonics" if channel.startswith("harmonic") else channel


# --------------------------------------------------------------------------
# Branches and levels


def branches(amplitude_m: np.ndarray) -> list[np.ndarray]:
    """Indices of the monotone runs of a curve's points in test order.

    A test stepped up then down has two branches sharing the turning point; a
    test stepped one way has one. Repeated amplitudes stay in the run they are in.
    """
    a = np.asarray(amplitude_m, dtype=float)
    if a.size < 3:
        return [np.arange(a.size)]
    direction = np.sign(np.diff(a))
    runs, start, current = [], 0, 0.0
    for i, d in enumerate(direction):
        if d == 0 or d == current or current == 0:
            current = current or d
            continue
        runs.append(np.arange(start, i + 1))  # the turning point ends this run …
        start, current = i, d  # … and starts the next
    runs.append(np.arange(start, a.size))
    return runs


def measurement_levels(measured: BackboneSet) -> np.ndarray:
    """Amplitude levels (m) where measured and predicted backbones are compared.

    Quantiles of the measured amplitudes inside the range every curve shares, as
    many as a curve's longest branch has points there: the levels follow the
    test's own spacing (geometric steps put many levels at small amplitudes,
    where friction acts), and a test stepped up and down counts its levels once.

    Raises
    ------
    ValueError
        If a curve has fewer than 3 points in the shared range (too sparse to compare).
    """
    low, high = measured.common_range()
    counts, pooled = [], []
    for curve in measured:
        a = curve.amplitude_m
        inside = (a >= low * (1 - 1e-12)) & (a <= high * (1 + 1e-12))
        if np.unique(a[inside]).size < 3:
            raise ValueError(
                f"curve {curve.label!r} has {np.unique(a[inside]).size} backbone point(s) in the "
                f"range all curves share ({1e3 * low:.4g}–{1e3 * high:.4g} mm); at least 3 are "
                "needed to compare model and measurement"
            )
        counts.append(max(np.unique(a[run][inside[run]]).size for run in branches(a)))
        pooled.append(a[inside])
    n = int(np.clip(np.median(counts), 3, 41))
    amplitudes_m = np.quantile(np.concatenate(pooled), np.linspace(0.0, 1.0, n))
    return np.unique(np.clip(amplitudes_m, low, high))


def _branch_values(
    runs: Sequence[Sequence[np.ndarray]],
    amplitude: np.ndarray,
    levels_m: np.ndarray,
    per_point: np.ndarray,
) -> np.ndarray:
    """``(n_curves, n_branches, n_levels, n_columns)`` each branch interpolated to the levels.

    Linear in log-amplitude inside the branch's range, points at equal amplitude
    averaged; NaN where a branch does not reach a level or lacks the column, and at
    levels next to a NaN point (a model without a periodic solution there) only.
    """
    n_branches = max(len(r) for r in runs)
    out = np.full((len(runs), n_branches, levels_m.size, per_point.shape[1]), np.nan)
    log_levels = np.log(levels_m)
    for i, curve_runs in enumerate(runs):
        for b, rows in enumerate(curve_runs):
            unique, inverse = np.unique(amplitude[rows], return_inverse=True)
            if unique.size < 2:
                continue
            counts = np.bincount(inverse)
            inside = (levels_m >= unique[0] * (1 - 1e-12)) & (levels_m <= unique[-1] * (1 + 1e-12))
            for j in range(per_point.shape[1]):
                column = per_point[rows, j]
                mean = np.bincount(inverse, weights=column) / counts
                out[i, b, inside, j] = np.interp(log_levels[inside], np.log(unique), mean)
    return out


# --------------------------------------------------------------------------
# The metric of one set of channel weights


@dataclass(frozen=True, eq=False)
class Metric:
    """The likelihood's metric for given channel weights.

    ``keep`` selects the entries of the level table (``(n_levels, n_channels)``,
    flattened level-major) that count: used channels with a non-zero weight;
    ``weights`` multiplies each kept residual entry; ``covariance`` is the
    :class:`~identification.fitting.covariance.LevelCovariance` of the kept entries.
    """

    keep: np.ndarray
    weights: np.ndarray
    covariance: cov.LevelCovariance

    @property
    def size(self) -> int:
        return int(self.keep.sum())

    def whiten(self, level_residual: np.ndarray) -> np.ndarray:
        """Whitened weighted residual of an ``(n_levels, n_channels)`` table (or a stack of
        them, ``(..., n_levels, n_channels)``); entries where the model failed (NaN) get
        :data:`FAILED_RESIDUAL` standard errors."""
        flat = level_residual.reshape(*level_residual.shape[:-2], -1)[..., self.keep]
        se = self.covariance.standard_error
        flat = np.where(np.isfinite(flat), flat, FAILED_RESIDUAL * se)
        return self.covariance.whiten((self.weights * flat).T).T


# --------------------------------------------------------------------------
# Measured data in fitting form


@dataclass(frozen=True, eq=False)
class FitData:
    """Measured points of several curves, their levels and the likelihood's covariance.

    Attributes
    ----------
    labels
        Curve labels.
    curve
        ``(n_points,)`` index into ``labels`` of each point.
    amplitude_m
        ``(n_points,)`` fundamental amplitudes (m).
    channels
        Channel names (:data:`BACKBONE_CHANNELS`, then :data:`HARMONIC_CHANNELS` with harmonics).
    values
        ``(n_points, n_channels)`` measured values; NaN where a curve lacks a channel.
    standard_error
        ``(n_points, n_channels)`` standard error of each measured value where known
        (the harmonics' from their hold fits), else 0.
    levels_m
        Amplitude levels of the comparison (:func:`measurement_levels`).
    runs
        Per curve, the point indices (into the arrays above) of each branch, in test order.
    time
        ``(n_points,)`` when each point was held: seconds from the record's start where
        the backbones carry hold times, else the point's position in its record.
    time_unit
        ``"s"`` or ``"hold"``.
    noise_floor
        The systematic floors used (:data:`NOISE_FLOOR` keys).
    excitation_harmonics
        ``(n_points, n_orders)`` harmonics ``2, 3, …`` of each point's measured base
        acceleration (fractions of its fundamental, in its own frame): the forcing
        its prediction is driven by (0 for curves that do not carry them); None
        where no curve does.
    """

    labels: tuple[str, ...]
    curve: np.ndarray
    amplitude_m: np.ndarray
    channels: tuple[str, ...]
    values: np.ndarray
    standard_error: np.ndarray
    levels_m: np.ndarray
    runs: tuple[tuple[np.ndarray, ...], ...]
    time: np.ndarray
    time_unit: str
    noise_floor: Mapping[str, float]
    excitation_harmonics: np.ndarray | None = None
    _metrics: dict = field(default_factory=dict, repr=False)

    # ------------------------------------------------------------ layout
    @property
    def n_points(self) -> int:
        return self.amplitude_m.size

    @property
    def n_curves(self) -> int:
        return len(self.labels)

    @property
    def has_harmonics(self) -> bool:
        return any(c in HARMONIC_CHANNELS for c in self.channels)

    def column(self, channel: str) -> int:
        return self.channels.index(channel)

    # ------------------------------------------------------------ curves at levels
    def branch_values(self, per_point: np.ndarray) -> np.ndarray:
        """``(n_curves, n_branches, n_levels, n_channels)``: each branch at the levels."""
        return _branch_values(self.runs, self.amplitude_m, self.levels_m, per_point)

    def at_levels(self, per_point: np.ndarray) -> np.ndarray:
        """``(n_curves, n_levels, n_channels)`` per-point values at the levels, the branches
        of a curve averaged (NaN where no branch reaches a level or the channel is absent)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # levels no branch reaches
            return np.nanmean(self.branch_values(per_point), axis=1)

    def excitation_at(self, amplitude_m: np.ndarray) -> np.ndarray | None:
        """``(n, n_orders)`` the measured excitation's harmonics at amplitudes that are not
        the points (the comparison levels, a plotting grid): each curve's, interpolated in
        log-amplitude and held at its ends, averaged over the curves. This is the forcing
        of level-wise predictions, as :attr:`excitation_harmonics` is that of the points'
        (a shaker's distortion changes with the level it is driven at). None where no
        curve carries the excitation's harmonics."""
        if self.excitation_harmonics is None:
            return None
        log_a = np.log(np.asarray(amplitude_m, float)).reshape(-1)
        out = np.zeros((log_a.size, self.excitation_harmonics.shape[1]), dtype=complex)
        for i in range(self.n_curves):
            rows = np.flatnonzero(self.curve == i)
            rows = rows[np.argsort(self.amplitude_m[rows], kind="stable")]
            known = np.log(self.amplitude_m[rows])
            for m, ratios in enumerate(self.excitation_harmonics[rows].T):
                out[:, m] += np.interp(log_a, known, ratios.real)
                out[:, m] += 1j * np.interp(log_a, known, ratios.imag)
        return out / self.n_curves

    @cached_property
    def curves_at_levels(self) -> np.ndarray:
        """The measured curves at the levels (:meth:`at_levels` of :attr:`values`)."""
        return self.at_levels(self.values)

    @cached_property
    def used(self) -> np.ndarray:
        """``(n_channels,)`` whether a channel enters the likelihood: every curve has it at
        every level (a channel some curves lack is compared nowhere, and said so)."""
        return np.isfinite(self.curves_at_levels).all(axis=(0, 1))

    def mean_residual(self, predicted: np.ndarray) -> np.ndarray:
        """``(n_levels, n_channels)`` mean over curves of measured − predicted at the levels
        (NaN in unused channels and where the model has no solution)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanmean(self.at_levels(self.values - predicted), axis=0) * np.where(
                self.used, 1.0, np.nan
            )

    # ------------------------------------------------------------ the covariance
    def estimate_covariance(self, channels: np.ndarray) -> cov.LevelCovariance:
        """Covariance of the mean residual over ``channels`` (a boolean mask of used
        channels; entries level-major), estimated from the curves as
        :func:`identification.fitting.covariance.estimate` does for a simulated campaign."""
        curves = self.curves_at_levels[:, :, channels]
        n, n_levels, n_channels = curves.shape
        errors = self.at_levels(self.standard_error**2)[:, :, channels]
        variance_floor = np.nanmean(errors, axis=0).reshape(-1)
        per_curve, lam_r, lam_v = cov.estimate(
            curves.reshape(1, n, -1),
            np.tile(np.arange(n_channels), n_levels),
            np.log(self.levels_m),
            variance_floor,
        )
        floors = np.array([self.noise_floor[_floor_key(c)] for c in self.channels])[channels]
        return cov.LevelCovariance(
            per_curve[0],
            np.tile(floors**2, n_levels),
            n,
            float(lam_r[0]),
            float(lam_v[0]),
            "between-curve" if n > 1 else "within-curve",
        )

    @property
    def covariance(self) -> cov.LevelCovariance:
        """Covariance of the mean residual over every used channel (:meth:`metric`'s)."""
        return self.metric().covariance

    @cached_property
    def level_sigma(self) -> np.ndarray:
        """``(n_levels, n_channels)`` scatter of one curve (√ of the covariance's diagonal;
        NaN in unused channels)."""
        return self._unflatten(np.sqrt(np.diag(self.covariance.per_curve)))

    @cached_property
    def sigma(self) -> np.ndarray:
        """``(n_points, n_channels)`` a standard deviation per point (one curve's scatter at
        its amplitude ⊕ floor ⊕ the point's standard error): the diagonal weights of the
        linearised start values, not the likelihood."""
        log_a = np.log(self.amplitude_m)
        out = np.zeros_like(self.values)
        for j, channel in enumerate(self.channels):
            scatter = self.level_sigma[:, j]
            level = (
                np.interp(log_a, np.log(self.levels_m), scatter) if self.used[j] else 0.0 * log_a
            )
            out[:, j] = np.sqrt(
                level**2
                + self.noise_floor[_floor_key(channel)] ** 2
                + self.standard_error[:, j] ** 2
            )
        return out

    def _unflatten(self, entries: np.ndarray) -> np.ndarray:
        table = np.full((self.levels_m.size, len(self.channels)), np.nan)
        table[:, self.used] = entries.reshape(self.levels_m.size, -1)
        return table

    def metric(self, weights: Sequence[float] | None = None) -> Metric:
        """The likelihood's :class:`Metric` for channel weights (default all 1)."""
        w = np.ones(len(self.channels)) if weights is None else np.asarray(weights, float)
        key = tuple(w)
        if key not in self._metrics:
            channels = self.used & (w > 0)
            on = np.broadcast_to(channels, (self.levels_m.size, len(self.channels))).reshape(-1)
            self._metrics[key] = Metric(
                on,
                np.broadcast_to(w, (self.levels_m.size, w.size)).reshape(-1)[on],
                self.estimate_covariance(channels),
            )
        return self._metrics[key]

    def level_mean(self, per_point: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean over curves at the levels ``(n_levels, n_channels)`` and its standard error
        under the likelihood's covariance (NaN in unused channels)."""
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # channels no curve has
            mean = np.nanmean(self.at_levels(per_point), axis=0)
        return mean, self._unflatten(self.covariance.standard_error)

    def whitened(self, predicted: np.ndarray, weights: Sequence[float] | None = None) -> np.ndarray:
        """Whitened mean residual of a prediction at the points: its sum of squares is the
        ``χ²`` of the likelihood."""
        return self.metric(weights).whiten(self.mean_residual(predicted))

    def loglik(self, predicted: np.ndarray, weights: Sequence[float] | None = None) -> float:
        """Gaussian log-likelihood of the mean residual (−inf where the model has no solution)."""
        metric = self.metric(weights)
        residual = self.mean_residual(predicted).reshape(-1)[metric.keep]
        if not np.isfinite(residual).all():
            return -np.inf
        z = metric.covariance.whiten(metric.weights * residual)
        log_det = 2 * np.sum(np.log(np.diag(metric.covariance.cholesky)))
        return float(-0.5 * (z @ z + log_det + z.size * np.log(2 * np.pi)))

    def subset(self, index: int) -> FitData:
        """The data of curve ``index`` alone (its covariance from its own roughness)."""
        rows = np.flatnonzero(self.curve == index)
        position = {g: k for k, g in enumerate(rows)}
        runs = tuple(np.array([position[g] for g in run]) for run in self.runs[index])
        return FitData(
            (self.labels[index],),
            np.zeros(rows.size, dtype=int),
            self.amplitude_m[rows],
            self.channels,
            self.values[rows],
            self.standard_error[rows],
            self.levels_m,
            (runs,),
            self.time[rows],
            self.time_unit,
            self.noise_floor,
            None if self.excitation_harmonics is None else self.excitation_harmonics[rows],
        )


def fit_data(measured: BackboneSet, noise_floor: Mapping[str, float] | None = None) -> FitData:
    """Measured backbones (and the harmonics they carry) in fitting form.

    Parameters
    ----------
    measured
        The measured backbones. When some carry harmonics
        (:attr:`~identification.measurements.backbone.Backbone.harmonics`), the
        orders :data:`HARMONIC_ORDERS` become channels, NaN for curves (or orders)
        without them. Hold times (a ``time_s`` per point) are used where every curve
        has them, else each point's position in its record stands for its time.
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
    with_harmonics = any(b.harmonics is not None for b in measured)
    channels = BACKBONE_CHANNELS + (HARMONIC_CHANNELS if with_harmonics else ())
    timed = all(getattr(b, "time_s", None) is not None for b in measured)
    curve, amplitude, values, errors, times, runs = [], [], [], [], [], []
    offset = 0
    excitation = None
    if any(b.excitation_harmonics is not None for b in measured):
        excitation = np.vstack([_excitation_block(b) for b in measured])
    for i, b in enumerate(measured):
        block = np.full((len(b), len(channels)), np.nan)
        se = np.zeros_like(block)
        block[:, 0], block[:, 1] = b.frequency_hz, b.damping_ratio
        if with_harmonics and b.harmonics is not None:
            n_orders = min(len(HARMONIC_ORDERS), b.harmonics.shape[1])  # orders 2, 3, …
            relative = b.harmonics[:, :n_orders]
            stop = 2 + 2 * n_orders
            parts = np.stack([relative.real, -relative.imag], axis=-1)  # C_h/a, S_h/a
            block[:, 2:stop] = parts.reshape(len(b), -1)
            if b.harmonic_standard_error is not None:
                se[:, 2:stop] = np.repeat(b.harmonic_standard_error[:, :n_orders], 2, axis=1)
        curve.append(np.full(len(b), i))
        amplitude.append(b.amplitude_m)
        values.append(block)
        errors.append(se)
        times.append(np.asarray(b.time_s, float) if timed else np.arange(len(b), dtype=float))
        runs.append(tuple(offset + r for r in branches(b.amplitude_m)))
        offset += len(b)
    if any((a <= 0).any() for a in amplitude):
        raise ValueError("measured backbones have points of zero amplitude")
    return FitData(
        tuple(measured.labels),
        np.concatenate(curve),
        np.concatenate(amplitude),
        channels,
        np.vstack(values),
        np.vstack(errors),
        measurement_levels(measured),
        tuple(runs),
        np.concatenate(times),
        "s" if timed else "hold",
        floor,
        excitation,
    )


def _excitation_block(curve: Backbone) -> np.ndarray:
    """The orders :data:`HARMONIC_ORDERS` of a curve's excitation harmonics (0 where absent)."""
    block = np.zeros((len(curve), len(HARMONIC_ORDERS)), dtype=complex)
    if curve.excitation_harmonics is not None:
        n_orders = min(len(HARMONIC_ORDERS), curve.excitation_harmonics.shape[1])
        block[:, :n_orders] = curve.excitation_harmonics[:, :n_orders]
    return block
