"""Generation: analytical backbones of the designed parameter sets on a fixed grid.

``method="harmonic"``: the harmonic-balance backbone
(:func:`identification.analytical.harmonic.backbone`) gives the excitation
``A(a)`` needed at a response amplitude ``a``; it is evaluated on a geometric
amplitude grid, each level is bracketed at its **first crossing** and the root
``A(a) = level`` is refined with Chandrupatla's method
(:func:`scipy.optimize.elementwise.find_root`) to 1e-12 relative. Where ``A(a)``
is not monotone below the top level (several amplitudes hold one level), the
first crossing is the branch a test stepping its level *up* follows; such sets
are kept and flagged (``non_monotone="first"``) or dropped (``"drop"``).
``method="pll"``: the time-domain PLL simulator
(:func:`identification.analytical.pll.pll_backbones`) runs directly on the
levels (slower; unlocked levels fail the set). Failed sets (no convergence, a
level out of reach, no lock) are dropped, counted, and kept with their
reasons. On the amplitude grid (:mod:`surrogates.grid`) every set is kept.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import elementwise
from tqdm.auto import tqdm

from identification.analytical.harmonic import backbone
from identification.artifacts import versions
from identification.fitting.least_squares import default_free
from identification.fitting.prediction import resolve_method
from identification.model import JointModel
from surrogates.dataset.container import (
    _ALL_CHANNELS,
    ANALYTICAL,
    FORMAT,
    FORMAT_VERSION,
    BackboneDataset,
)
from surrogates.dataset.design import _box, nominal_levels, sample_parameters
from surrogates.grid import (
    GRID_CHANNELS,
    GridEvaluation,
    geometric_grid,
    grid_backbones,
    grid_counts,
    passed_curves,
)
from surrogates.runtime import REPRESENTATION_CHANNELS, SurrogateSpec

NonMonotone = Literal["first", "drop"]
Representation = Literal["excitation_levels", "amplitude_grid"]


@dataclass(frozen=True)
class _Inversion:
    """What every chunk needs to invert ``A(a)`` onto the levels."""

    excitation_m_s2: np.ndarray
    grid: np.ndarray
    method: str
    harmonics: int
    non_monotone: NonMonotone


def _evaluate(
    model: JointModel, names: list[str], row: np.ndarray, how: _Inversion, a: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Excitation (m/s²), frequency (Hz), damping ratio and convergence of one set at ``a``."""
    result = backbone(
        model, a, parameters=row[None], names=names, method=how.method, harmonics=how.harmonics
    )
    return (
        result.base_acceleration[0],
        result.frequency_hz[0],
        result.damping_ratio[0],
        result.converged[0],
    )


class _Outcome(NamedTuple):
    """One parameter set: its ``(n_levels, 3)`` curve (None if it failed), flag and why."""

    curve: np.ndarray | None
    non_monotone: bool = False
    reason: str = ""

    @classmethod
    def failed(cls, reason: str, non_monotone: bool = False) -> _Outcome:
        return cls(None, non_monotone, reason)


def _invert(model: JointModel, names: list[str], row: np.ndarray, how: _Inversion) -> _Outcome:
    """One set's amplitude, frequency and damping ratio at the levels."""
    excitation_m_s2, grid = how.excitation_m_s2, how.grid
    excitation, _, _, converged = _evaluate(model, names, row, how, grid)
    reached = np.flatnonzero(excitation >= excitation_m_s2[-1])
    top = reached[0] if reached.size else grid.size - 1
    unconverged = np.flatnonzero(~converged[: top + 1])
    if unconverged.size:
        a = 1e3 * grid[unconverged[0]]
        return _Outcome.failed(f"harmonic balance did not converge at {a:.4g} mm")
    if not reached.size:
        return _Outcome.failed(
            f"the top level {excitation_m_s2[-1]:.4g} m/s² is not reached below "
            f"{1e3 * grid[-1]:.4g} mm (largest excitation {excitation.max():.4g} m/s²)"
        )
    if excitation[0] >= excitation_m_s2[0]:
        return _Outcome.failed(
            f"the lowest level {excitation_m_s2[0]:.4g} m/s² is reached already at "
            f"{1e3 * grid[0]:.4g} mm, the grid's smallest amplitude"
        )
    non_monotone = bool(np.any(np.diff(excitation[: top + 1]) <= 0))
    if non_monotone and how.non_monotone == "drop":
        return _Outcome.failed("excitation A(a) is not monotone below the top level", True)
    # First crossing of each level: the branch a test stepping its level up follows.
    upper = np.argmax(excitation[None, :] >= excitation_m_s2[:, None], axis=1)
    root = elementwise.find_root(
        lambda a, target: _evaluate(model, names, row, how, a)[0] / target - 1.0,
        (grid[upper - 1], grid[upper]),
        args=(excitation_m_s2,),
        tolerances={"fatol": 1e-13, "xrtol": 4 * np.finfo(float).eps},
    )
    excitation, frequency, damping, converged = _evaluate(model, names, row, how, root.x)
    if not (converged.all() and np.all(np.abs(excitation / excitation_m_s2 - 1) <= 1e-10)):
        return _Outcome.failed("A(a) = level could not be solved to 1e-10", non_monotone)
    return _Outcome(np.stack([root.x, frequency, damping], axis=-1), non_monotone)


def _harmonic_chunk(
    model: JointModel, names: list[str], parameters: np.ndarray, how: _Inversion
) -> list[_Outcome]:
    """Executor task: a chunk of sets (module level so that it pickles)."""
    return [_invert(model, names, row, how) for row in parameters]


def _pll_outcomes(
    model, names, parameters, excitation_m_s2, config, executor, progress
) -> list[_Outcome]:
    from identification.analytical.pll import pll_backbones

    result = pll_backbones(
        model, excitation_m_s2, parameters, names, config, executor=executor, progress=progress
    )
    curves = np.stack([result.amplitude_m, result.frequency_hz, result.damping_ratio], axis=-1)
    outcomes = []
    for curve, locked, error in zip(curves, result.locked, result.phase_error_deg, strict=True):
        j = int(np.argmin(locked))
        outcomes.append(
            _Outcome(curve)
            if locked.all()
            else _Outcome.failed(f"PLL did not lock at level {j} (phase error {error[j]:.3g}°)")
        )
    return outcomes


def generate_dataset(
    model: JointModel,
    names: Sequence[str] | None = None,
    n: int = 500,
    *,
    representation: Representation = "excitation_levels",
    spread: float | Mapping[str, float] = 0.2,
    bounds: ArrayLike | Mapping[str, tuple[float, float]] | None = None,
    levels: ArrayLike | None = None,
    n_levels: int = 41,
    amplitude_range_m: tuple[float, float] = (5e-5, 2e-3),
    method: Literal["harmonic", "pll"] = "harmonic",
    harmonic: Literal["auto", "single", "multi"] = "auto",
    harmonics: int = 5,
    pll_config: Any = None,
    channels: Sequence[str] | None = None,
    sampler: Literal["lhs", "sobol"] = "lhs",
    seed: int = 0,
    non_monotone: NonMonotone = "first",
    grid_points: int = 240,
    grid_margin: float = 3.0,
    refine: int = 4,
    executor: Any = None,
    chunk_size: int = 16,
    progress: bool = True,
) -> BackboneDataset:
    """Analytical backbones of ``n`` parameter sets of ``model`` on a fixed grid.

    Parameters
    ----------
    model
        Template model; the named parameters vary, the others stay at its values.
    names
        Parameters that vary (:attr:`JointModel.parameter_names`); default
        :func:`identification.fitting.least_squares.default_free` (all but a redundant
        Jenkins coefficient).
    n
        Parameter sets drawn. On the amplitude grid every set is kept; on
        excitation levels failed sets are dropped, so the dataset may hold fewer.
    representation
        ``"amplitude_grid"``: ``n_levels`` response amplitudes geometric over
        ``amplitude_range_m`` (m), channels frequency, damping ratio, base
        acceleration and the mask ``has_backbone`` (:mod:`surrogates.grid`);
        defined for every set. ``"excitation_levels"``: base-acceleration levels
        (m/s²), channels from amplitude, frequency, damping ratio.
    spread, bounds
        The box: ``bounds`` (``(n_params, 2)`` or ``{name: (low, high)}``, the
        latter overriding :func:`~identification.model.parameter_bounds` for those names),
        else ± ``spread``.
    levels, n_levels, amplitude_range_m
        Excitation levels: ``levels`` (m/s², increasing), default
        :func:`nominal_levels` of ``n_levels`` over ``amplitude_range_m`` (m), which
        also sets the amplitude search grid of the harmonic inversion (÷/×
        ``grid_margin``, ``grid_points`` geometric points). Amplitude grid:
        ``n_levels`` amplitudes over ``amplitude_range_m``; ``levels`` must be None.
    method
        ``"harmonic"`` (harmonic balance) or ``"pll"`` (time-domain PLL simulation on
        the excitation levels, :class:`~identification.analytical.pll.PLLConfig`
        ``pll_config``).
    harmonic, harmonics
        Harmonic balance: ``"single"``, ``"multi"`` with ``harmonics``, or
        ``"auto"`` (multi only for models with even terms; see
        :func:`identification.fitting.prediction.resolve_method`).
    channels
        Backbone channels kept (default: every channel of the representation,
        :data:`~surrogates.runtime.REPRESENTATION_CHANNELS`; amplitude and
        frequency on excitation levels).
    sampler, seed
        Design of the parameter sets (:func:`sample_parameters`).
    non_monotone
        Excitation levels only: sets whose ``A(a)`` is not monotone keep the first
        crossing and are flagged (``"first"``) or are dropped (``"drop"``).
    refine
        Amplitude grid: evaluation points per grid interval (and ``grid_margin``
        the lead-in below it) on which a dip of ``A(a)`` is looked for.
    executor, chunk_size
        Anything with ``submit(fn, *args)`` (``concurrent.futures``, a dask
        ``Client``): chunks of ``chunk_size`` sets run there (the PLL method
        chunks by itself); the data are identical to a local run.
    progress
        Show a progress bar.

    Returns
    -------
    BackboneDataset
        With ``provenance["counts"]``: requested, kept, failed, non-monotone,
        measured, and on the amplitude grid also generated (= requested = kept),
        the masked entries by reason and the curves with a mask (a warning says
        when sets failed or were flagged).
    """
    names = default_free(model) if names is None else list(names)
    box = _box(model, names, spread, bounds)
    if representation not in REPRESENTATION_CHANNELS:
        raise ValueError(
            f"representation must be one of {list(REPRESENTATION_CHANNELS)}, got {representation!r}"
        )
    # An N-mode surrogate's channel is not the one-mode balance's (surrogates.dataset.modal).
    grid_channels = (
        GRID_CHANNELS
        if representation == "amplitude_grid"
        else REPRESENTATION_CHANNELS[representation]
    )
    if channels is None:
        on_levels = ("amplitude_m", "frequency_hz")
        channels = grid_channels if representation == "amplitude_grid" else on_levels
    channels = tuple(channels)
    unknown = [c for c in channels if c not in grid_channels]
    if unknown or not channels:
        raise ValueError(f"channels must be names from {grid_channels}, got {channels}")
    if method not in ("harmonic", "pll"):
        raise ValueError(f"method must be 'harmonic' or 'pll', got {method!r}")
    if non_monotone not in ("first", "drop"):
        raise ValueError(f"non_monotone must be 'first' or 'drop', got {non_monotone!r}")
    if not isinstance(chunk_size, int | np.integer) or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer ≥ 1, got {chunk_size!r}")
    if not (grid_margin > 1 and grid_points >= 2):
        raise ValueError(
            f"need grid_margin > 1 and grid_points ≥ 2, got {grid_margin}, {grid_points}"
        )
    low, high = amplitude_range_m
    if not (0 < low < high and math.isfinite(high)) or n_levels < 2:
        raise ValueError(
            f"need n_levels ≥ 2 and 0 < low < high, got {n_levels}, {amplitude_range_m}"
        )
    resolved = resolve_method(harmonic, model)
    order = harmonics if resolved == "multi" else 1
    parameters = sample_parameters(box, n, sampler=sampler, seed=seed)
    provenance = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "representation": representation,
        "model": model.to_dict(),
        "parameter_names": list(names),
        "bounds": box.tolist(),
        "spread": dict(spread) if isinstance(spread, Mapping) else spread,
        "amplitude_range_m": list(amplitude_range_m),
        "channels": list(channels),
        "method": method,
        "harmonic": None if method == "pll" else {"method": resolved, "harmonics": order},
        "pll_config": None if method == "harmonic" else repr(pll_config),
        "sampler": sampler,
        "seed": seed,
        "chunk_size": chunk_size,
        "measured": {"added": [], "excluded": {}},
        "versions": versions(),
    }
    if representation == "amplitude_grid":
        if method != "harmonic" or levels is not None:
            raise ValueError(
                "the amplitude grid is evaluated by harmonic balance at amplitudes: pass "
                "method='harmonic' and no levels (the PLL steps excitation levels: use "
                "representation='excitation_levels' for it)"
            )
        how = GridEvaluation(
            geometric_grid(amplitude_range_m, n_levels), resolved, harmonics, refine, grid_margin
        )
        return _grid_dataset(
            model, names, parameters, how, channels, provenance, chunk_size, executor, progress
        )
    if levels is None:
        excitation_m_s2 = nominal_levels(
            model, amplitude_range_m, n_levels, harmonic=resolved, harmonics=harmonics
        )
    else:
        excitation_m_s2 = levels
    spec = SurrogateSpec(tuple(names), box, excitation_m_s2, channels)

    if method == "harmonic":
        grid = np.geomspace(low / grid_margin, high * grid_margin, grid_points)
        how = _Inversion(spec.levels, grid, resolved, harmonics, non_monotone)
        chunks = _map_chunks(
            _harmonic_chunk, model, names, parameters, how, chunk_size, executor, progress
        )
        outcomes = [outcome for chunk in chunks for outcome in chunk]
    else:
        outcomes = _pll_outcomes(
            model, names, parameters, spec.levels, pll_config, executor, progress
        )

    kept = [o for o in outcomes if o.curve is not None]
    keep = np.array([o.curve is not None for o in outcomes], dtype=bool)
    columns = [_ALL_CHANNELS.index(c) for c in channels]
    y = np.array([o.curve[:, columns] for o in kept]).reshape(-1, *spec.backbone_shape)
    flags = np.array([o.non_monotone for o in kept], dtype=bool)
    reasons = [o.reason for o in outcomes if o.curve is None]
    provenance.update(
        levels=spec.levels.tolist(),
        level_unit=spec.level_unit,
        non_monotone=non_monotone,
        counts={
            "requested": n,
            "kept": int(keep.sum()),
            "failed": int((~keep).sum()),
            "non_monotone": int(flags.sum()),
            "measured": 0,
        },
    )
    if reasons or flags.any():
        warnings.warn(
            f"generate_dataset: {len(reasons)} of {n} parameter sets failed and were dropped"
            + (f" (first: {reasons[0]})" if reasons else "")
            + f"; {int(flags.sum())} kept with a non-monotone A(a) (first crossing taken)",
            stacklevel=2,
        )
    return BackboneDataset(
        X=parameters[keep],
        Y=y,
        spec=spec,
        origin=np.full(int(keep.sum()), ANALYTICAL),
        non_monotone=flags,
        failed_parameters=parameters[~keep],
        failed_reasons=np.array(reasons, dtype=str),
        provenance=provenance,
    )


def _grid_dataset(
    model: JointModel,
    names: list[str],
    parameters: np.ndarray,
    how: GridEvaluation,
    channels: tuple[str, ...],
    provenance: dict[str, Any],
    chunk_size: int,
    executor: Any,
    progress: bool,
) -> BackboneDataset:
    """Every set on the amplitude grid: nothing dropped, masks counted by reason."""
    chunks = _map_chunks(
        grid_backbones, model, names, parameters, how, chunk_size, executor, progress
    )
    values = np.concatenate([c[0] for c in chunks])
    reasons = np.concatenate([c[1] for c in chunks])
    spec = SurrogateSpec(
        tuple(names), np.array(provenance["bounds"]), channels=channels,
        amplitudes_m=how.amplitudes_m,
    )  # fmt: skip
    provenance.update(
        amplitudes_m=how.amplitudes_m.tolist(),
        evaluation={"refine": how.refine, "lead_in": how.lead_in,
                    "lead_in_points": how.lead_in_points},
        counts=grid_counts(reasons),
    )  # fmt: skip
    columns = [GRID_CHANNELS.index(c) for c in channels]
    return BackboneDataset(
        X=parameters,
        Y=values[..., columns],
        spec=spec,
        origin=np.full(len(parameters), ANALYTICAL),
        non_monotone=passed_curves(reasons),
        failed_parameters=np.empty((0, len(names))),
        failed_reasons=np.empty(0, dtype=str),
        provenance=provenance,
    )


def _map_chunks(
    function: Callable[[JointModel, list[str], np.ndarray, Any], Any],
    model: JointModel,
    names: list[str],
    parameters: np.ndarray,
    how: Any,
    chunk_size: int,
    executor: Any,
    progress: bool,
) -> list[Any]:
    """``function(model, names, chunk, how)`` for every chunk of sets, here or on ``executor``.

    The chunks are cut the same way whatever runs them, and the results come
    back in chunk order, so a dataset does not depend on where it was computed.
    """
    chunks = [parameters[s : s + chunk_size] for s in range(0, len(parameters), chunk_size)]
    if executor is None:
        results = (function(model, names, chunk, how) for chunk in chunks)
    else:
        futures = [executor.submit(function, model, names, c, how) for c in chunks]
        results = (future.result() for future in futures)
    collected = []
    with tqdm(total=len(parameters), desc="backbones", unit="set", disable=not progress) as bar:
        for chunk, result in zip(chunks, results, strict=True):
            collected.append(result)
            bar.update(len(chunk))
    return collected
