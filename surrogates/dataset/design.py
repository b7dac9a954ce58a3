"""Design of a dataset: the parameter box, its quasi-random sets, the excitation levels.

The parameter sets are a seeded quasi-random design (Latin hypercube or
scrambled Sobol, :mod:`scipy.stats.qmc`) over a box, by default ± a relative
spread around a :class:`~identification.model.JointModel`'s values
(sign-aware); the excitation levels default to those that hold the *nominal*
model at amplitudes spaced geometrically over a range.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike
from scipy.stats import qmc

from identification.analytical.harmonic import backbone
from identification.fitting.prediction import resolve_method
from identification.model import JointModel, parameter_bounds


def sample_parameters(
    bounds: ArrayLike, n: int, *, sampler: Literal["lhs", "sobol"] = "lhs", seed: int = 0
) -> np.ndarray:
    """``(n, n_params)`` quasi-random points in the box (scipy.stats.qmc, seeded).

    ``"lhs"``: Latin hypercube; ``"sobol"``: scrambled Sobol' (balanced when
    ``n`` is a power of 2; scipy warns otherwise).
    """
    bounds = np.asarray(bounds, dtype=float)
    if bounds.ndim != 2 or bounds.shape[1] != 2 or not np.all(bounds[:, 0] < bounds[:, 1]):
        raise ValueError(f"bounds must be (n_params, 2) rows with low < high, got {bounds}")
    if not isinstance(n, int | np.integer) or n < 1:
        raise ValueError(f"n must be an integer ≥ 1, got {n!r}")
    engines = {"lhs": qmc.LatinHypercube, "sobol": qmc.Sobol}
    if sampler not in engines:
        raise ValueError(f"sampler must be one of {sorted(engines)}, got {sampler!r}")
    unit = engines[sampler](bounds.shape[0], rng=np.random.default_rng(seed)).random(n)
    return qmc.scale(unit, bounds[:, 0], bounds[:, 1])


def nominal_levels(
    model: JointModel,
    amplitude_range_m: tuple[float, float] = (5e-5, 2e-3),
    n_levels: int = 41,
    *,
    harmonic: str = "auto",
    harmonics: int = 5,
) -> np.ndarray:
    """Excitation levels (m/s²) holding ``model`` at amplitudes geometric over the range.

    ValueError if the model's excitation is not increasing over the range
    (then several amplitudes hold one level: pass levels explicitly).
    """
    low, high = amplitude_range_m
    if not (0 < low < high and math.isfinite(high)) or n_levels < 2:
        raise ValueError(
            f"need n_levels ≥ 2 and 0 < low < high, got {n_levels}, {amplitude_range_m}"
        )
    amplitudes = np.geomspace(low, high, n_levels)
    result = backbone(
        model, amplitudes, method=resolve_method(harmonic, model), harmonics=harmonics
    )
    levels = result.base_acceleration
    if not (result.converged.all() and levels[0] > 0 and np.all(np.diff(levels) > 0)):
        raise ValueError(
            f"model {model.name or model.equation()!r}: its excitation is not positive and "
            f"increasing over {1e3 * low:g}–{1e3 * high:g} mm; pass levels explicitly"
        )
    return levels


def _box(
    model: JointModel,
    names: list[str],
    spread: float | Mapping[str, float],
    bounds: ArrayLike | Mapping[str, tuple[float, float]] | None,
) -> np.ndarray:
    if bounds is None:
        return parameter_bounds(model, names, spread)
    if isinstance(bounds, Mapping):
        unknown = set(bounds) - set(names)
        if unknown:
            raise ValueError(f"bounds given for {sorted(unknown)}, which are not in {names}")
        free = [n for n in names if n not in bounds]
        defaults = dict(zip(free, parameter_bounds(model, free, spread), strict=True))
        return np.array([bounds.get(n, defaults.get(n)) for n in names], dtype=float)
    box = np.asarray(bounds, dtype=float)
    if box.shape != (len(names), 2):
        raise ValueError(f"bounds must have shape ({len(names)}, 2) for {names}, got {box.shape}")
    return box
