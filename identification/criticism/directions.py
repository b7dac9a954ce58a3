"""Directions in which a refitted model can move: its own parameters, each catalogue
candidate, and a free-form reference.

Everything here lives in the space of the likelihood
(:mod:`identification.fitting.data`): the mean over curves of a prediction at the
comparison levels, flattened over the entries that count. The criticism's
statistics (:mod:`identification.criticism.calibration`) are linear in these
directions, which is what makes a parametric bootstrap of thousands of whole
campaigns take a second.

* :func:`base_jacobian` — the refitted model's parameters (forward differences;
  shape parameters in log).
* :func:`candidate_directions` — each catalogue effect added with a small
  coefficient, over its grid of shape parameters (one column per shape value):
  the first-order change it brings.
* :func:`reference_directions` — a free-form reference: a smooth correction of
  every channel against log-amplitude (cubic B-splines with one interior knot for
  the frequency and damping, a quadratic for each harmonic part). On the
  frequency and damping channels it is a free-form equivalent stiffness
  ``k_eq(a) = ω(a)²`` and damping ``c_eq(a) = 2ζ(a)ω(a)``: whatever physics is
  missing, if it is smooth in amplitude, this reference captures it.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.interpolate import BSpline

from identification.effects import CATALOGUE, get_effect
from identification.fitting.data import FitData, Metric
from identification.fitting.least_squares import fit_scale, natural_coefficient
from identification.fitting.prediction import predict_channels, resolve_method
from identification.model import JointModel

__all__ = [
    "Direction",
    "base_jacobian",
    "candidate_directions",
    "mean_prediction",
    "reference_directions",
]

#: Relative size of a candidate's probe: its force reaches this share of the linear force
#: at the largest amplitude (small enough to stay linear, large against the solver's 1e-10).
PROBE = 1e-3
#: A probe that moves the prediction by less than this share of the data's standard error
#: has no first-order signature here (an even term without measured harmonics).
SILENT = 1e-9


@dataclass(frozen=True)
class Direction:
    """One candidate column: the effect, its shape values, which coefficient signs are physical.

    ``sign`` is +1 where only a positive coefficient is physical (friction, slip), else 0.
    """

    effect: str
    shape: dict[str, float]
    sign: int


def mean_prediction(data: FitData, predicted: np.ndarray) -> np.ndarray:
    """``(..., n_levels, n_channels)`` mean over curves of predictions at the points, at the
    levels (the same interpolation as the measured curves get)."""
    stack = np.asarray(predicted, float)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # no solution at some level: NaN
        if stack.ndim == 2:
            return np.nanmean(data.at_levels(stack), axis=0)
        return np.stack([np.nanmean(data.at_levels(p), axis=0) for p in stack])


def _flat(metric: Metric, tables: np.ndarray) -> np.ndarray:
    """``(p, k)`` weighted kept entries of ``(k, n_levels, n_channels)`` tables."""
    flat = tables.reshape(tables.shape[0], -1)[:, metric.keep]
    return (metric.weights * flat).T


def base_jacobian(
    model: JointModel, free: Sequence[str], data: FitData, method: str, metric: Metric
) -> np.ndarray:
    """``(p, k)`` derivative of the mean prediction by each free parameter (shape
    parameters by their logarithm), each point driven by its measured excitation."""
    values = np.array([model.parameters[n] for n in free])
    is_log = np.array(["." in n for n in free])
    scale = fit_scale(model, data)
    omega = math.sqrt(scale.stiffness)
    size = np.where(
        values != 0,
        np.abs(values),
        [natural_coefficient(n.split(".")[0], scale.amplitude_m[1], omega, scale.stiffness)
         for n in free],
    )  # fmt: skip
    step = np.where(is_log, 1e-4, 1e-4 * size)
    move = step.copy()
    move[is_log] = values[is_log] * np.expm1(step[is_log])  # d/d(log p): a relative step
    trial = values + np.diag(move)
    rows = np.vstack([values, trial])
    predicted = predict_channels(
        model, data.amplitude_m, data.channels, method=method, parameters=rows, names=list(free),
        excitation_harmonics=data.excitation_harmonics,
    )  # fmt: skip
    tables = mean_prediction(data, predicted)
    return _flat(metric, (tables[1:] - tables[0]) / step[:, None, None])


def _probe_coefficients(
    effect: str, shapes: Sequence[dict[str, float]], model: JointModel, data: FitData
) -> np.ndarray:
    """The probe of each shape column: where that shape makes the term strongest over the
    tested amplitudes, its force reaches :data:`PROBE` of the linear force (a Stribeck
    drop or a saturation of one shape acts at small amplitudes only, of another at
    all; one probe for every shape would be lost in the solver's noise for some and
    leave the linear range for others)."""
    # a hysteretic element's shape grid sets its stuck stiffness (a tenth of the model's)
    if CATALOGUE[effect].hysteretic:
        return np.full(len(shapes), PROBE)
    scale = fit_scale(model, data)
    amplitudes = np.geomspace(*scale.amplitude_m, 5)
    omega = math.sqrt(scale.stiffness)
    return np.array([
        PROBE * natural_coefficient(effect, amplitudes, omega, scale.stiffness, **shape)
        for shape in shapes
    ])  # fmt: skip


def candidate_directions(
    model: JointModel,
    effects: Sequence[str],
    data: FitData,
    method: str,
    metric: Metric,
) -> tuple[np.ndarray, list[Direction]]:
    """``(p, M)`` first-order change of the mean prediction per unit coefficient of each
    effect, one column per value of its shape grid, and what each column is.

    Each column is the difference of the model with and without the probe, both
    through the harmonic balance the extended model needs (an even term needs the
    multi-harmonic one) and both driven by the excitation each point's hold measured
    (as the fit's predictions are), with a probe sized for each shape. Columns whose
    change is below :data:`SILENT` standard errors are returned as zeros: the effect has
    no first-order signature on these data (so are those of shapes where the harmonic
    balance has no solution at some point).
    """
    columns, directions = [], []
    se = metric.covariance.standard_error
    for effect in effects:
        spec = get_effect(effect)
        grid = spec.shape_grid(fit_scale(model, data))
        shapes = _product(grid)
        probe = _probe_coefficients(effect, shapes, model, data)
        extended = model.with_effect(effect, probe[0], **shapes[0])
        how = resolve_method(method if method == "multi" else "auto", extended, data)
        forcing = {"method": how, "excitation_harmonics": data.excitation_harmonics}
        with_probe = predict_channels(
            extended,
            data.amplitude_m,
            data.channels,
            parameters=np.column_stack([probe, [list(s.values()) for s in shapes]]),
            names=[effect] + [f"{effect}.{name}" for name in grid],
            **forcing,
        )
        without = predict_channels(model, data.amplitude_m, data.channels, **forcing)
        change = _flat(metric, mean_prediction(data, with_probe - without[None])) / probe
        # A shape where the harmonic balance fails somewhere gives no direction at all.
        failed = ~np.isfinite(change).all(axis=0)
        change[:, failed] = 0.0
        silent = np.max(np.abs(change) * probe / (metric.weights * se)[:, None], axis=0) < SILENT
        change[:, silent] = 0.0
        columns.append(change)
        sign = 1 if spec.coefficient_sign > 0 else 0
        directions += [Direction(effect, s, sign) for s in shapes]
    if not columns:  # no candidates: the decision rests on the free-form reference
        return np.zeros((metric.keep.sum(), 0)), directions
    return np.hstack(columns), directions


def _product(grid: dict[str, np.ndarray]) -> list[dict[str, float]]:
    """Every combination of the shape grids (one empty shape without grids)."""
    if not grid:
        return [{}]
    names = list(grid)
    mesh = np.meshgrid(*(np.asarray(grid[n], float) for n in names), indexing="ij")
    return [
        {n: float(v) for n, v in zip(names, values, strict=True)}
        for values in zip(*(m.ravel() for m in mesh), strict=True)
    ]


def _basis(positions: np.ndarray, smooth_degree: int) -> np.ndarray:
    """``(n_levels, m)`` B-spline basis over the positions: cubic with one interior knot
    (``smooth_degree=3``) or a polynomial of the given degree, no more columns than levels − 1."""
    u = (positions - positions[0]) / (positions[-1] - positions[0])
    degree = min(smooth_degree, u.size - 2)
    interior = [0.5] if smooth_degree == 3 and u.size >= 7 else []
    knots = np.concatenate([np.zeros(degree + 1), interior, np.ones(degree + 1)])
    return BSpline.design_matrix(np.clip(u, 0, 1), knots, degree).toarray()


def reference_directions(data: FitData, metric: Metric) -> tuple[np.ndarray, list[str]]:
    """``(p, m)`` columns of the free-form reference and the channel of each column.

    Frequency and damping get a cubic B-spline in log-amplitude with one interior knot
    (five functions: an equivalent stiffness and damping of any smooth shape); each
    harmonic part a quadratic (the harmonics a smooth nonlinearity leaves grow as a
    power of the amplitude).
    """
    positions = np.log(data.levels_m)
    n_levels, n_channels = data.levels_m.size, len(data.channels)
    columns, labels = [], []
    for j, channel in enumerate(data.channels):
        basis = _basis(positions, 3 if channel in ("frequency_hz", "damping_ratio") else 2)
        for column in basis.T:
            table = np.zeros((n_levels, n_channels))
            table[:, j] = column
            columns.append(table)
            labels.append(channel)
    flat = _flat(metric, np.array(columns))
    kept = np.any(flat != 0, axis=0)
    return flat[:, kept], [label for label, k in zip(labels, kept, strict=True) if k]
