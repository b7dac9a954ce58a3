"""Measured backbones in fitting form: channels, amplitude levels, standard deviations.

A model is compared with measured backbones in **channels**: the frequency and
the power-balance damping ratio of every point (:data:`BACKBONE_CHANNELS`), and,
where the backbones carry the higher harmonics their hold fits measured
(:class:`identification.measurements.backbone.Backbone`), the 2nd and 3rd
harmonics of the response as a third kind (:data:`HARMONIC_CHANNELS`): even
terms such as ``x²`` leave a second harmonic, ``x³`` a third, where the
backbone alone cannot tell them apart.

Each value's standard deviation combines the measured scatter across curves at
its amplitude (assembly-to-assembly variability), a stated noise floor
(:data:`NOISE_FLOOR`) and, for the harmonics, the hold fit's standard error, so
a population-mean model is judged against the spread the test itself shows.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from identification.measurements.backbone import BackboneSet

__all__ = [
    "BACKBONE_CHANNELS",
    "HARMONIC_CHANNELS",
    "HARMONIC_ORDERS",
    "NOISE_FLOOR",
    "FitData",
    "fit_data",
    "measurement_levels",
]

#: Backbone channels: frequency (Hz) and power-balance damping ratio.
BACKBONE_CHANNELS = ("frequency_hz", "damping_ratio")
#: Higher-harmonic channels from the hold fits: ``C_h/a`` and ``S_h/a`` of the relative
#: displacement ``x = a cos θ + Σ_h C_h cos hθ + S_h sin hθ`` (fractions of the fundamental).
HARMONIC_ORDERS = (2, 3)
HARMONIC_CHANNELS = tuple(f"harmonic{h}_{part}" for h in HARMONIC_ORDERS for part in ("cos", "sin"))
#: Noise floors combined with the measured scatter: frequency (Hz), damping ratio (1),
#: harmonics (fraction of the fundamental). The harmonics floor stands for what a real
#: rig adds (shaker distortion, sensor nonlinearity) beyond the fit's standard error.
NOISE_FLOOR = {"frequency_hz": 0.02, "damping_ratio": 2e-5, "harmonics": 1e-3}


def _floor_key(channel: str) -> str:
    return "harmonics" if channel.startswith("harmonic") else channel


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
        Channel names (:data:`BACKBONE_CHANNELS`, then :data:`HARMONIC_CHANNELS` with harmonics).
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
        (the harmonics' from their hold fits), else 0.
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


def fit_data(measured: BackboneSet, noise_floor: Mapping[str, float] | None = None) -> FitData:
    """Measured backbones (and the harmonics they carry) in fitting form.

    Parameters
    ----------
    measured
        The measured backbones. When some carry harmonics
        (:attr:`~identification.measurements.backbone.Backbone.harmonics`), the
        orders :data:`HARMONIC_ORDERS` become channels, NaN for curves (or orders)
        without them.
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
    curve, amplitude, values, errors = [], [], [], []
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
