"""Training data for backbone surrogates: parameter sets → backbones on fixed excitation levels.

A surrogate maps a parameter vector to a backbone sampled at fixed
**excitation levels** (base-acceleration amplitudes, m/s²), the way a
phase-resonance test steps its shaker: the response amplitude and frequency are
outputs, the level is the grid (:class:`~surrogates.runtime.SurrogateSpec`).
This module builds such datasets:

1. **Parameters.** A seeded quasi-random design (Latin hypercube or scrambled
   Sobol, :mod:`scipy.stats.qmc`) over a box, by default ± a relative spread
   around a :class:`~identification.model.JointModel`'s values (sign-aware).
2. **Levels.** By default the ``n_levels`` levels that hold the *nominal* model
   at amplitudes spaced geometrically over ``amplitude_range_m``.
3. **Backbones.** ``method="harmonic"``: the harmonic-balance backbone
   (:func:`identification.analytical.harmonic.backbone`) gives the excitation ``A(a)``
   needed at a response amplitude ``a``; it is evaluated on a geometric
   amplitude grid, each level is bracketed at its **first crossing** and the
   root ``A(a) = level`` is refined with Chandrupatla's method
   (:func:`scipy.optimize.elementwise.find_root`) to 1e-12 relative. Where
   ``A(a)`` is not monotone below the top level (several amplitudes hold one
   level), the first crossing is the branch a test stepping its level *up*
   follows; such sets are kept and flagged (``non_monotone="first"``) or
   dropped (``"drop"``). ``method="pll"``: the time-domain PLL simulator
   (:func:`identification.analytical.pll.pll_backbones`) runs directly on the levels
   (slower; unlocked levels fail the set). Failed sets (no convergence, a level
   out of reach, no lock) are dropped, counted, and kept with their reasons.
4. **Measured curves** (:func:`add_measured`), as the paper trained on 25
   measured + 475 analytical curves: each measured curve, labelled with the
   parameters of its own fit, is interpolated onto the levels when it covers
   them, else excluded with the reason.

A :class:`BackboneDataset` is saved as one ``.npz`` with a JSON provenance
record (model, names, box, levels, method, seed, sampler, versions, counts) and
a SHA-256 of its content that :meth:`BackboneDataset.load` checks.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import warnings
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal, NamedTuple

import numpy as np
from numpy.typing import ArrayLike
from scipy.optimize import elementwise
from scipy.stats import qmc
from tqdm.auto import tqdm

from identification.analytical.harmonic import backbone
from identification.artifacts import atomic_write_bytes, sha256_bytes, versions
from identification.fitting.least_squares import default_free
from identification.fitting.prediction import resolve_method
from identification.measurements.backbone import BackboneSet
from identification.measurements.records import Record
from identification.model import JointModel, parameter_bounds
from identification.sindy import identify
from surrogates.runtime import SurrogateSpec

__all__ = [
    "BackboneDataset",
    "add_measured",
    "generate_dataset",
    "nominal_levels",
    "reachable_amplitude_range",
    "record_labels",
    "sample_parameters",
]

FORMAT = "pm-joint/BackboneDataset"
FORMAT_VERSION = 1
ANALYTICAL = "analytical"
MEASURED_PREFIX = "measured:"

#: All channels a dataset can hold, in the order the generators compute them.
_ALL_CHANNELS = ("amplitude_m", "frequency_hz", "damping_ratio")
_ARRAYS = ("X", "Y", "origin", "non_monotone", "failed_parameters", "failed_reasons")

NonMonotone = Literal["first", "drop"]


# ---------------------------------------------------------------------------
# The container


@dataclass(frozen=True, eq=False)
class BackboneDataset:
    """Parameter vectors and their backbones on fixed excitation levels.

    Attributes
    ----------
    X
        ``(n, n_params)`` physical parameters, columns ``spec.parameter_names``.
    Y
        ``(n, n_levels, n_channels)`` backbones on ``spec.levels``, SI units.
    spec
        Names, box, levels and channels (what :func:`~surrogates.train.train_surrogate` takes).
    origin
        ``(n,)`` ``"analytical"`` or ``"measured:<curve label>"``.
    non_monotone
        ``(n,)`` True where ``A(a)`` was not monotone and the first crossing was taken.
    failed_parameters, failed_reasons
        Parameter sets that gave no backbone, ``(m, n_params)``, and why.
    provenance
        How the data were made (see :func:`generate_dataset`); plain JSON.
    """

    X: np.ndarray
    Y: np.ndarray
    spec: SurrogateSpec
    origin: np.ndarray
    non_monotone: np.ndarray
    failed_parameters: np.ndarray
    failed_reasons: np.ndarray
    provenance: dict[str, Any]

    def __post_init__(self) -> None:
        x = self.spec.check_parameters(self.X, "dataset parameters")
        y = self.spec.check_backbones(self.Y, "dataset backbones")
        n = x.shape[0]
        if y.shape[0] != n:
            raise ValueError(f"dataset: {n} parameter vectors but {y.shape[0]} backbones")
        self.spec.require_in_box(x, "dataset parameters")
        origin = np.asarray(self.origin, dtype=str).reshape(-1)
        flags = np.asarray(self.non_monotone, dtype=bool).reshape(-1)
        failed = np.asarray(self.failed_parameters, dtype=float).reshape(-1, self.spec.n_params)
        reasons = np.asarray(self.failed_reasons, dtype=str).reshape(-1)
        if origin.size != n or flags.size != n or reasons.size != failed.shape[0]:
            raise ValueError(
                f"dataset: origin ({origin.size}), non_monotone ({flags.size}) must have one "
                f"entry per curve ({n}), failed_reasons one per failed set ({failed.shape[0]})"
            )
        for name, value in zip(_ARRAYS, (x, y, origin, flags, failed, reasons), strict=True):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return self.X.shape[0]

    def __repr__(self) -> str:
        return (
            f"<BackboneDataset: {len(self)} curves ({self.n_measured} measured), "
            f"{self.spec.n_params} parameters, {self.spec.n_levels} levels, "
            f"channels {list(self.spec.channels)}, {self.failed_reasons.size} failed>"
        )

    @property
    def n_measured(self) -> int:
        return int(np.char.startswith(self.origin, MEASURED_PREFIX).sum())

    @property
    def content_hash(self) -> str:
        """SHA-256 over every array and the provenance (what :meth:`load` checks)."""
        return sha256_bytes(_canonical_bytes(self._payload()))

    # -------------------------------------------------------------- subsets
    def subset(self, index: ArrayLike) -> BackboneDataset:
        """The curves at ``index`` (integer or boolean), failed sets and provenance kept."""
        index = np.asarray(index)
        provenance = {**self.provenance, "subset_of": self.content_hash}
        return dataclasses.replace(
            self,
            X=self.X[index],
            Y=self.Y[index],
            origin=self.origin[index],
            non_monotone=self.non_monotone[index],
            provenance=provenance,
        )

    def split(self, n_test: int, seed: int = 0) -> tuple[BackboneDataset, BackboneDataset]:
        """``(train, test)``: ``n_test`` curves drawn by a seeded permutation, the rest."""
        if not 0 < n_test < len(self):
            raise ValueError(f"n_test must be between 1 and {len(self) - 1}, got {n_test}")
        order = np.random.default_rng(seed).permutation(len(self))
        return self.subset(np.sort(order[n_test:])), self.subset(np.sort(order[:n_test]))

    # ------------------------------------------------------------------ files
    def save(self, path: str | Path) -> Path:
        """Write the dataset as one ``.npz`` (atomically), with its content hash."""
        payload = self._payload()
        buffer = io.BytesIO()
        np.savez(buffer, **payload, sha256=np.array(sha256_bytes(_canonical_bytes(payload))))
        return atomic_write_bytes(path, buffer.getvalue())

    @classmethod
    def load(cls, path: str | Path) -> BackboneDataset:
        """Read a dataset written by :meth:`save`; ValueError on a hash mismatch."""
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as stored:
                payload = {key: stored[key] for key in stored.files}
        except FileNotFoundError:
            raise ValueError(f"{path}: no dataset file here") from None
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise ValueError(f"{path}: not a readable .npz dataset ({exc})") from None
        missing = [k for k in (*_ARRAYS, "spec", "provenance", "sha256") if k not in payload]
        if missing:
            raise ValueError(f"{path}: not a {FORMAT} file (lacks {', '.join(missing)})")
        recorded = str(payload.pop("sha256"))
        actual = sha256_bytes(_canonical_bytes(payload))
        if actual != recorded:
            raise ValueError(
                f"{path}: hash mismatch: the content has SHA-256 {actual}, the file records "
                f"{recorded}; it was modified or damaged"
            )
        provenance = json.loads(str(payload["provenance"]))
        if provenance.get("format") != FORMAT or provenance.get("format_version", 0) > 1:
            raise ValueError(f"{path}: not a {FORMAT} version ≤ {FORMAT_VERSION} file")
        spec = SurrogateSpec.from_dict(json.loads(str(payload["spec"])))
        return cls(**{k: payload[k] for k in _ARRAYS}, spec=spec, provenance=provenance)

    def _payload(self) -> dict[str, np.ndarray]:
        return {
            **{name: getattr(self, name) for name in _ARRAYS},
            "spec": np.array(json.dumps(self.spec.to_dict(), sort_keys=True)),
            "provenance": np.array(json.dumps(self.provenance, sort_keys=True)),
        }


def _canonical_bytes(payload: Mapping[str, np.ndarray]) -> bytes:
    """Names, dtypes, shapes and contents of the arrays, in name order."""
    chunks = []
    for name in sorted(payload):
        array = np.ascontiguousarray(payload[name])
        chunks += [f"{name}|{array.dtype.str}|{array.shape}|".encode(), array.tobytes()]
    return b"".join(chunks)


# ---------------------------------------------------------------------------
# Parameters and levels


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


def reachable_amplitude_range(
    model: JointModel, low_m: float, high_m: float
) -> tuple[float, float]:
    """The part of the amplitudes ``[low_m, high_m]`` a stepped excitation can hold the model at.

    Excitation levels map one-to-one onto amplitudes only while the base
    acceleration the backbone needs increases with amplitude; past its first
    maximum a PLL test jumps, so the range ends there (multi-harmonic balance
    on 200 geometric amplitudes).

    Raises
    ------
    ValueError
        When the range ends before ``1.5 × low_m``.
    """
    grid = np.geomspace(low_m, high_m, 200)
    hb = backbone(model, grid, method="multi")
    level = np.where(hb.converged, hb.base_acceleration, np.nan)
    falling = np.flatnonzero(~(np.diff(level) > 0))
    end = grid[falling[0]] if falling.size else high_m
    if end <= low_m * 1.5:
        raise ValueError(
            f"model {model.name or model.equation()!r}: its backbone needs a base acceleration "
            f"that does not increase over the measured {1e3 * low_m:.3g}–{1e3 * high_m:.3g} mm"
        )
    return low_m, float(end)


# ---------------------------------------------------------------------------
# Harmonic balance inverted onto the levels


@dataclass(frozen=True)
class _Inversion:
    """What every chunk needs to invert ``A(a)`` onto the levels."""

    levels: np.ndarray
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
    levels, grid = how.levels, how.grid
    excitation, _, _, converged = _evaluate(model, names, row, how, grid)
    reached = np.flatnonzero(excitation >= levels[-1])
    top = reached[0] if reached.size else grid.size - 1
    unconverged = np.flatnonzero(~converged[: top + 1])
    if unconverged.size:
        a = 1e3 * grid[unconverged[0]]
        return _Outcome.failed(f"harmonic balance did not converge at {a:.4g} mm")
    if not reached.size:
        return _Outcome.failed(
            f"the top level {levels[-1]:.4g} m/s² is not reached below {1e3 * grid[-1]:.4g} mm "
            f"(largest excitation {excitation.max():.4g} m/s²)"
        )
    if excitation[0] >= levels[0]:
        return _Outcome.failed(
            f"the lowest level {levels[0]:.4g} m/s² is reached already at "
            f"{1e3 * grid[0]:.4g} mm, the grid's smallest amplitude"
        )
    non_monotone = bool(np.any(np.diff(excitation[: top + 1]) <= 0))
    if non_monotone and how.non_monotone == "drop":
        return _Outcome.failed("excitation A(a) is not monotone below the top level", True)
    # First crossing of each level: the branch a test stepping its level up follows.
    upper = np.argmax(excitation[None, :] >= levels[:, None], axis=1)
    root = elementwise.find_root(
        lambda a, level: _evaluate(model, names, row, how, a)[0] / level - 1.0,
        (grid[upper - 1], grid[upper]),
        args=(levels,),
        tolerances={"fatol": 1e-13, "xrtol": 4 * np.finfo(float).eps},
    )
    excitation, frequency, damping, converged = _evaluate(model, names, row, how, root.x)
    if not (converged.all() and np.all(np.abs(excitation / levels - 1) <= 1e-10)):
        return _Outcome.failed("A(a) = level could not be solved to 1e-10", non_monotone)
    return _Outcome(np.stack([root.x, frequency, damping], axis=-1), non_monotone)


def _harmonic_chunk(
    model: JointModel, names: list[str], parameters: np.ndarray, how: _Inversion
) -> list[_Outcome]:
    """Executor task: a chunk of sets (module level so that it pickles)."""
    return [_invert(model, names, row, how) for row in parameters]


def _pll_outcomes(model, names, parameters, levels, config, executor, progress) -> list[_Outcome]:
    from identification.analytical.pll import pll_backbones

    result = pll_backbones(
        model, levels, parameters, names, config, executor=executor, progress=progress
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


# ---------------------------------------------------------------------------
# Generation


def generate_dataset(
    model: JointModel,
    names: Sequence[str] | None = None,
    n: int = 500,
    *,
    spread: float | Mapping[str, float] = 0.2,
    bounds: ArrayLike | Mapping[str, tuple[float, float]] | None = None,
    levels: ArrayLike | None = None,
    n_levels: int = 41,
    amplitude_range_m: tuple[float, float] = (5e-5, 2e-3),
    method: Literal["harmonic", "pll"] = "harmonic",
    harmonic: Literal["auto", "single", "multi"] = "auto",
    harmonics: int = 5,
    pll_config: Any = None,
    channels: Sequence[str] = ("amplitude_m", "frequency_hz"),
    sampler: Literal["lhs", "sobol"] = "lhs",
    seed: int = 0,
    non_monotone: NonMonotone = "first",
    grid_points: int = 240,
    grid_margin: float = 3.0,
    executor: Any = None,
    chunk_size: int = 16,
    progress: bool = True,
) -> BackboneDataset:
    """Analytical backbones of ``n`` parameter sets of ``model`` on fixed excitation levels.

    Parameters
    ----------
    model
        Template model; the named parameters vary, the others stay at its values.
    names
        Parameters that vary (:attr:`JointModel.parameter_names`); default
        :func:`identification.fitting.least_squares.default_free` (all but a redundant
        Jenkins coefficient).
    n
        Parameter sets drawn (failed ones are dropped, so the dataset may hold fewer).
    spread, bounds
        The box: ``bounds`` (``(n_params, 2)`` or ``{name: (low, high)}``, the
        latter overriding :func:`~identification.model.parameter_bounds` for those names),
        else ± ``spread``.
    levels, n_levels, amplitude_range_m
        Excitation levels (m/s², increasing); default :func:`nominal_levels` of
        ``n_levels`` over ``amplitude_range_m`` (m), which also sets the
        amplitude search grid of the harmonic inversion (÷/× ``grid_margin``,
        ``grid_points`` geometric points).
    method
        ``"harmonic"`` (harmonic balance inverted onto the levels) or ``"pll"``
        (time-domain PLL simulation, :class:`~identification.analytical.pll.PLLConfig`
        ``pll_config``).
    harmonic, harmonics
        Harmonic balance: ``"single"``, ``"multi"`` with ``harmonics``, or
        ``"auto"`` (multi only for models with even terms; see
        :func:`identification.fitting.prediction.resolve_method`).
    channels
        Backbone channels kept, from ``amplitude_m``, ``frequency_hz``, ``damping_ratio``.
    sampler, seed
        Design of the parameter sets (:func:`sample_parameters`).
    non_monotone
        Sets whose ``A(a)`` is not monotone: keep the first crossing and flag
        them (``"first"``) or drop them (``"drop"``).
    executor, chunk_size
        Anything with ``submit(fn, *args)`` (``concurrent.futures``, a dask
        ``Client``): chunks of ``chunk_size`` sets run there (the PLL method
        chunks by itself); the data are identical to a local run.
    progress
        Show a progress bar.

    Returns
    -------
    BackboneDataset
        With ``provenance["counts"]``: requested, kept, failed, non-monotone
        (a warning says so when any set failed or was flagged).
    """
    names = default_free(model) if names is None else list(names)
    box = _box(model, names, spread, bounds)
    channels = tuple(channels)
    unknown = [c for c in channels if c not in _ALL_CHANNELS]
    if unknown or not channels:
        raise ValueError(f"channels must be names from {_ALL_CHANNELS}, got {channels}")
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
    resolved = resolve_method(harmonic, model)
    if levels is None:
        levels = nominal_levels(
            model, amplitude_range_m, n_levels, harmonic=resolved, harmonics=harmonics
        )
    spec = SurrogateSpec(tuple(names), box, levels, channels)
    parameters = sample_parameters(box, n, sampler=sampler, seed=seed)

    if method == "harmonic":
        low, high = amplitude_range_m
        grid = np.geomspace(low / grid_margin, high * grid_margin, grid_points)
        how = _Inversion(spec.levels, grid, resolved, harmonics, non_monotone)
        outcomes = _run_harmonic(model, names, parameters, how, chunk_size, executor, progress)
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
    order = harmonics if resolved == "multi" else 1
    provenance = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "model": model.to_dict(),
        "parameter_names": list(names),
        "bounds": box.tolist(),
        "spread": dict(spread) if isinstance(spread, Mapping) else spread,
        "levels": spec.levels.tolist(),
        "level_unit": spec.level_unit,
        "amplitude_range_m": list(amplitude_range_m),
        "channels": list(channels),
        "method": method,
        "harmonic": None if method == "pll" else {"method": resolved, "harmonics": order},
        "pll_config": None if method == "harmonic" else repr(pll_config),
        "non_monotone": non_monotone,
        "sampler": sampler,
        "seed": seed,
        "counts": {
            "requested": n,
            "kept": int(keep.sum()),
            "failed": int((~keep).sum()),
            "non_monotone": int(flags.sum()),
            "measured": 0,
        },
        "measured": {"added": [], "excluded": {}},
        "versions": versions(),
    }
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


def _run_harmonic(
    model: JointModel,
    names: list[str],
    parameters: np.ndarray,
    how: _Inversion,
    chunk_size: int,
    executor: Any,
    progress: bool,
) -> list[_Outcome]:
    """Invert every set, chunk by chunk, here or on ``executor``; outcomes in order."""
    chunks = [parameters[s : s + chunk_size] for s in range(0, len(parameters), chunk_size)]
    if executor is None:
        results = (_harmonic_chunk(model, names, chunk, how) for chunk in chunks)
    else:
        futures = [executor.submit(_harmonic_chunk, model, names, c, how) for c in chunks]
        results = (future.result() for future in futures)
    outcomes = []
    with tqdm(
        total=len(parameters), desc="harmonic backbones", unit="set", disable=not progress
    ) as bar:
        for chunk, result in zip(chunks, results, strict=True):
            outcomes += result
            bar.update(len(chunk))
    return outcomes


# ---------------------------------------------------------------------------
# Measured curves


def record_labels(records: Sequence[Record], model: JointModel, names: Sequence[str]) -> np.ndarray:
    """Parameters of each record alone: least squares on the model's own terms.

    The paper labels its measured backbones by identifying each record; with
    the model's support fixed (no thresholding) that is a well-posed fit of
    the same parameters, record by record. Shape parameters keep the model's
    values. Returns ``(n_records, len(names))``, rows in the order of ``records``
    (the labels :func:`add_measured` takes).
    """
    shapes = {t.effect: dict(t.shape) for t in model.terms if t.shape}
    rows = []
    for record in records:
        fitted = identify(record, model.effects, threshold=None, shapes=shapes).model
        values = {**model.parameters, **fitted.parameters}
        rows.append([values[n] for n in names])
    return np.array(rows)


def add_measured(
    dataset: BackboneDataset,
    backbones: BackboneSet,
    labels: ArrayLike,
    *,
    level_gain: float | None = None,
) -> BackboneDataset:
    """The dataset with measured backbones appended, labelled by their fitted parameters.

    Parameters
    ----------
    dataset
        Analytical dataset whose levels, channels and box the curves must meet.
    backbones
        Measured curves, each on its own excitation levels.
    labels
        ``(n_curves, n_params)`` parameters of each curve (e.g. from fitting the
        model to that curve alone, :func:`identification.fitting.least_squares.fit_backbones`), in
        the order of ``dataset.spec.parameter_names``.
    level_gain
        How a point's base-acceleration amplitude is known. None: from the power
        balance of the point itself, ``A = 2 D ω² a / cos(phase error)`` (the
        extraction's damping ratio, :mod:`identification.measurements.extraction`), which needs
        no shaker calibration. A number: ``excitation_level × level_gain``
        (m/s² per unit of the record's level, e.g. per shaker volt).

    Each curve is sorted by level (equal levels averaged) and its amplitude,
    frequency and damping ratio interpolated linearly onto the dataset's levels.
    A curve that does not cover them, or whose labels lie outside the training
    box, is left out, with a warning naming it and why; the reasons are kept in
    ``provenance["measured"]["excluded"]``.
    """
    spec = dataset.spec
    curves = list(backbones)
    values = np.asarray(labels, dtype=float)
    if values.shape != (len(curves), spec.n_params):
        raise ValueError(
            f"labels must have shape ({len(curves)}, {spec.n_params}) for the curves "
            f"{[c.label for c in curves]} and parameters {list(spec.parameter_names)}, "
            f"got {values.shape}"
        )
    spec.check_parameters(values, "measured labels")
    if level_gain is not None and not (math.isfinite(level_gain) and level_gain > 0):
        raise ValueError(f"level_gain must be finite and > 0, got {level_gain}")
    columns = [_ALL_CHANNELS.index(c) for c in spec.channels]
    added, excluded, rows, ys = [], {}, [], []
    for curve, label in zip(curves, values, strict=True):
        try:
            spec.require_in_box(label[None], f"labels of curve {curve.label!r}")
            ys.append(_measured_on_levels(curve, spec.levels, level_gain)[:, columns])
        except ValueError as exc:
            excluded[curve.label] = str(exc)
            warnings.warn(f"add_measured: curve {curve.label!r} left out: {exc}", stacklevel=2)
            continue
        added.append(curve.label)
        rows.append(label)
    origin = [f"{MEASURED_PREFIX}{label}" for label in added]
    clash = sorted(set(origin) & set(dataset.origin))
    if clash:
        raise ValueError(f"add_measured: curves {clash} are already in the dataset")
    provenance = json.loads(json.dumps(dataset.provenance))  # a deep, JSON-clean copy
    record = provenance.setdefault("measured", {"added": [], "excluded": {}})
    record["added"] += added
    record["excluded"].update(excluded)
    record["level_source"] = (
        "power balance" if level_gain is None else f"excitation_level × {level_gain} m/s² per unit"
    )
    provenance["counts"]["measured"] = len(record["added"])
    n_params, shape = spec.n_params, (0, *spec.backbone_shape)
    return dataclasses.replace(
        dataset,
        X=np.vstack([dataset.X, np.reshape(rows, (-1, n_params))]),
        Y=np.concatenate([dataset.Y, np.reshape(ys, (-1, *shape[1:]))]),
        origin=np.concatenate([dataset.origin, np.array(origin, dtype=str)]),
        non_monotone=np.concatenate([dataset.non_monotone, np.zeros(len(added), dtype=bool)]),
        provenance=provenance,
    )


def _measured_on_levels(curve, levels: np.ndarray, level_gain: float | None) -> np.ndarray:
    """``(n_levels, 3)`` amplitude, frequency, damping of a measured curve on ``levels``."""
    if level_gain is None:
        phase = 0.0 if curve.phase_error_deg is None else np.radians(curve.phase_error_deg)
        omega = 2 * np.pi * curve.frequency_hz
        own = 2 * curve.damping_ratio * omega**2 * curve.amplitude_m / np.cos(phase)
        if np.any(own <= 0):
            raise ValueError("a point has no positive power input (damping ratio ≤ 0)")
    elif curve.excitation_level is None:
        raise ValueError("it has no excitation levels to scale by level_gain")
    else:
        own = curve.excitation_level * level_gain
    own, inverse = np.unique(own, return_inverse=True)
    counts = np.bincount(inverse)
    points = np.stack([curve.amplitude_m, curve.frequency_hz, curve.damping_ratio], axis=-1)
    points = np.stack([np.bincount(inverse, weights=p) / counts for p in points.T], axis=-1)
    tolerance = 1e-9 * levels[-1]
    if own.size < 2 or own[0] > levels[0] + tolerance or own[-1] < levels[-1] - tolerance:
        raise ValueError(
            f"it covers levels {own[0]:.4g}–{own[-1]:.4g} m/s², the dataset needs "
            f"{levels[0]:.4g}–{levels[-1]:.4g} m/s²"
        )
    return np.stack([np.interp(levels, own, p) for p in points.T], axis=-1)
