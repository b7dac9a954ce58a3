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
from collections.abc import Callable, Mapping, Sequence
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
from surrogates.grid import (
    GRID_CHANNELS,
    MASK_REASONS,
    GridEvaluation,
    assembly_scatter,
    geometric_grid,
    grid_backbones,
    measured_on_grid,
    point_base_acceleration,
)
from surrogates.labels import MisfitPolicy, label_misfit, misfit_weight
from surrogates.runtime import MASK_CHANNEL, REPRESENTATION_CHANNELS, SurrogateSpec

__all__ = [
    "BackboneDataset",
    "add_measured",
    "generate_dataset",
    "nominal_levels",
    "record_labels",
    "sample_parameters",
]

FORMAT = "pm-joint/BackboneDataset"
FORMAT_VERSION = 2
ANALYTICAL = "analytical"
MEASURED_PREFIX = "measured:"
#: The splits a curve can be in ("" until :meth:`BackboneDataset.with_splits` assigns them).
SPLITS = ("train", "validation", "test")

#: All channels a dataset can hold, in the order the generators compute them.
_ALL_CHANNELS = ("amplitude_m", "frequency_hz", "damping_ratio")
#: Arrays with one entry per curve (what :meth:`BackboneDataset.subset` selects).
_CURVE_ARRAYS = (
    "X", "Y", "origin", "non_monotone", "observed", "partition", "weight", "label_misfit",
)  # fmt: skip
_ARRAYS = (*_CURVE_ARRAYS, "failed_parameters", "failed_reasons")
#: Arrays a version-1 file lacks, read as their defaults.
_ADDED_IN_VERSION_2 = ("observed", "partition", "weight", "label_misfit")

NonMonotone = Literal["first", "drop"]
Representation = Literal["excitation_levels", "amplitude_grid"]


# ---------------------------------------------------------------------------
# The container


@dataclass(frozen=True, eq=False)
class BackboneDataset:
    """Parameter vectors and their backbones on a fixed grid.

    Attributes
    ----------
    X
        ``(n, n_params)`` physical parameters, columns ``spec.parameter_names``.
    Y
        ``(n, n_levels, n_channels)`` backbones on ``spec.grid``, SI units, finite
        everywhere: on the amplitude grid a masked entry (``has_backbone`` 0)
        holds 0 in every value channel.
    spec
        Names, box, grid and channels (what :func:`~surrogates.train.train_surrogate` takes).
    origin
        ``(n,)`` ``"analytical"`` or ``"measured:<curve label>"``.
    non_monotone
        ``(n,)`` True where ``A(a)`` was not monotone (on the excitation levels:
        the first crossing was taken; on the amplitude grid: some amplitudes are
        masked as passed).
    observed
        ``(n, n_levels)`` True where the curve was observed (a measured curve
        covers only its own amplitude range; analytical curves everywhere).
        Unobserved entries carry no loss weight.
    partition
        ``(n,)`` the curve's split: ``"train"``, ``"validation"``, ``"test"`` or ``""``
        (not assigned; :meth:`with_splits`).
    weight
        ``(n,)`` loss weight of each curve (1; less for a measured curve whose label
        misfits it, see :func:`add_measured`).
    label_misfit
        ``(n,)`` for measured curves, how far the label's own backbone lies from the
        curve, in assembly standard deviations (RMS over its amplitudes); NaN for
        analytical curves and where it could not be computed.
    failed_parameters, failed_reasons
        Parameter sets that gave no backbone, ``(m, n_params)``, and why (only the
        excitation-level representation drops sets).
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
    observed: np.ndarray | None = None
    partition: np.ndarray | None = None
    weight: np.ndarray | None = None
    label_misfit: np.ndarray | None = None

    def __post_init__(self) -> None:
        x = self.spec.check_parameters(self.X, "dataset parameters")
        y = self.spec.check_backbones(self.Y, "dataset backbones")
        n = x.shape[0]
        if y.shape[0] != n:
            raise ValueError(f"dataset: {n} parameter vectors but {y.shape[0]} backbones")
        self.spec.require_in_box(x, "dataset parameters")
        defaults = {
            "observed": np.ones((n, self.spec.n_levels), dtype=bool),
            "partition": np.full(n, "", dtype="<U10"),
            "weight": np.ones(n),
            "label_misfit": np.full(n, np.nan),
        }
        given = {k: defaults[k] if getattr(self, k) is None else getattr(self, k) for k in defaults}
        arrays = {
            "X": x,
            "Y": y,
            "origin": np.asarray(self.origin, dtype=str).reshape(-1),
            "non_monotone": np.asarray(self.non_monotone, dtype=bool).reshape(-1),
            "observed": np.asarray(given["observed"], dtype=bool).reshape(n, self.spec.n_levels),
            "partition": np.asarray(given["partition"], dtype=str).reshape(-1),
            "weight": np.asarray(given["weight"], dtype=float).reshape(-1),
            "label_misfit": np.asarray(given["label_misfit"], dtype=float).reshape(-1),
            "failed_parameters": np.asarray(self.failed_parameters, dtype=float).reshape(
                -1, self.spec.n_params
            ),
            "failed_reasons": np.asarray(self.failed_reasons, dtype=str).reshape(-1),
        }
        wrong = [k for k in _CURVE_ARRAYS if arrays[k].shape[0] != n]
        if wrong or arrays["failed_reasons"].size != arrays["failed_parameters"].shape[0]:
            raise ValueError(
                f"dataset: {', '.join(wrong) or 'failed_reasons'} must have one entry per curve "
                f"({n}) or failed set ({arrays['failed_parameters'].shape[0]})"
            )
        unknown = sorted(set(arrays["partition"]) - {"", *SPLITS})
        if unknown:
            raise ValueError(f"dataset: splits must be from {SPLITS} or '', got {unknown}")
        if not np.all((arrays["weight"] >= 0) & np.isfinite(arrays["weight"])):
            raise ValueError("dataset: curve weights must be finite and ≥ 0")
        for name, value in arrays.items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return self.X.shape[0]

    def __repr__(self) -> str:
        return (
            f"<BackboneDataset: {len(self)} curves ({self.n_measured} measured), "
            f"{self.spec.n_params} parameters, {self.spec.n_levels} points on "
            f"{self.spec.representation}, channels {list(self.spec.channels)}, "
            f"{self.failed_reasons.size} failed>"
        )

    @property
    def n_measured(self) -> int:
        return int(self.is_measured.sum())

    @property
    def is_measured(self) -> np.ndarray:
        """``(n,)`` True for measured curves."""
        return np.char.startswith(self.origin, MEASURED_PREFIX)

    @property
    def content_hash(self) -> str:
        """SHA-256 over every array and the provenance (what :meth:`load` checks)."""
        return sha256_bytes(_canonical_bytes(self._payload()))

    def loss_weights(self) -> np.ndarray:
        """``(n, n_levels, n_channels)`` weight of every entry in a training loss.

        The curve's weight where it was observed; on the amplitude grid a value
        channel also needs a backbone there (``has_backbone`` 1: a masked entry's
        neutral value teaches nothing), the mask channel does not.
        """
        weights = np.broadcast_to(
            (self.weight[:, None] * self.observed)[..., None], self.Y.shape
        ).copy()
        if MASK_CHANNEL in self.spec.channels:
            exists = self.Y[..., self.spec.channel_index(MASK_CHANNEL)] >= 0.5
            values = [self.spec.channel_index(c) for c in self.spec.value_channels]
            weights[..., values] *= exists[..., None]
        return weights

    # -------------------------------------------------------------- subsets
    def subset(self, index: ArrayLike) -> BackboneDataset:
        """The curves at ``index`` (integer or boolean), failed sets and provenance kept."""
        index = np.asarray(index)
        provenance = {**self.provenance, "subset_of": self.content_hash}
        return dataclasses.replace(
            self, **{k: getattr(self, k)[index] for k in _CURVE_ARRAYS}, provenance=provenance
        )

    def split(self, n_test: int, seed: int = 0) -> tuple[BackboneDataset, BackboneDataset]:
        """``(train, test)``: ``n_test`` curves drawn by a seeded permutation, the rest."""
        if not 0 < n_test < len(self):
            raise ValueError(f"n_test must be between 1 and {len(self) - 1}, got {n_test}")
        order = np.random.default_rng(seed).permutation(len(self))
        return self.subset(np.sort(order[n_test:])), self.subset(np.sort(order[:n_test]))

    def with_splits(
        self,
        validation_fraction: float = 0.15,
        test_fraction: float = 0.15,
        *,
        seed: int = 0,
        hold_out_measured: bool = False,
    ) -> BackboneDataset:
        """The dataset with every curve in a split: train, validation, test.

        Analytical and measured curves are split separately (each origin keeps
        the fractions, rounded, with at least one curve per split where it has
        three or more), by a seeded permutation. ``hold_out_measured`` puts every
        measured curve in the test split: nothing the likelihood later scores
        was training data. The counts, per origin and split, go to
        ``provenance["splits"]``.
        """
        if not (0 < validation_fraction < 1 and 0 < test_fraction < 1):
            raise ValueError(
                f"fractions must lie in (0, 1): {validation_fraction}, {test_fraction}"
            )
        if validation_fraction + test_fraction >= 1:
            raise ValueError("validation and test fractions leave no curve to train on")
        rng = np.random.default_rng(seed)
        partition = np.full(len(self), "", dtype="<U10")
        for kind, rows in (("analytical", ~self.is_measured), ("measured", self.is_measured)):
            index = rng.permutation(np.flatnonzero(rows))
            if kind == "measured" and hold_out_measured:
                partition[index] = "test"
                continue
            n = index.size
            n_test = max(round(test_fraction * n), int(n >= 3))
            n_validation = max(round(validation_fraction * n), int(n >= 3))
            partition[index[:n_test]] = "test"
            partition[index[n_test : n_test + n_validation]] = "validation"
            partition[index[n_test + n_validation :]] = "train"
        provenance = json.loads(json.dumps(self.provenance))  # a deep, JSON-clean copy
        provenance["splits"] = {
            "seed": seed,
            "validation_fraction": validation_fraction,
            "test_fraction": test_fraction,
            "hold_out_measured": hold_out_measured,
        }
        updated = dataclasses.replace(self, partition=partition, provenance=provenance)
        provenance["splits"]["counts"] = updated.split_counts()
        return updated

    def split_counts(self) -> dict[str, dict[str, int]]:
        """Curves per origin (``analytical``, ``measured``, ``all``) and split."""
        kinds = {"analytical": ~self.is_measured, "measured": self.is_measured}
        kinds["all"] = np.ones(len(self), dtype=bool)
        return {
            kind: {s: int(np.sum(rows & (self.partition == s))) for s in SPLITS}
            for kind, rows in kinds.items()
        }

    def in_split(self, name: str) -> np.ndarray:
        """Row indices of the curves in split ``name`` (ValueError before :meth:`with_splits`)."""
        if name not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {name!r}")
        if np.any(self.partition == ""):
            raise ValueError("the dataset has curves in no split: call with_splits first")
        return np.flatnonzero(self.partition == name)

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
        required = [k for k in _ARRAYS if k not in _ADDED_IN_VERSION_2]
        missing = [k for k in (*required, "spec", "provenance", "sha256") if k not in payload]
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
        version = provenance.get("format_version", 0)
        if provenance.get("format") != FORMAT or version > FORMAT_VERSION:
            raise ValueError(f"{path}: not a {FORMAT} version ≤ {FORMAT_VERSION} file")
        if version >= 2 and any(k not in payload for k in _ADDED_IN_VERSION_2):
            raise ValueError(f"{path}: a version-2 dataset lacks {_ADDED_IN_VERSION_2}")
        spec = SurrogateSpec.from_dict(json.loads(str(payload["spec"])))
        arrays = {k: payload[k] for k in _ARRAYS if k in payload}
        return cls(**arrays, spec=spec, provenance=provenance)

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
    grid_channels = REPRESENTATION_CHANNELS[representation]
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
        levels = nominal_levels(
            model, amplitude_range_m, n_levels, harmonic=resolved, harmonics=harmonics
        )
    spec = SurrogateSpec(tuple(names), box, levels, channels)

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
    passed = np.any(reasons == 1 + MASK_REASONS.index("passed"), axis=1)
    masked = reasons != 0
    provenance.update(
        amplitudes_m=how.amplitudes_m.tolist(),
        evaluation={"refine": how.refine, "lead_in": how.lead_in,
                    "lead_in_points": how.lead_in_points},
        counts={
            "requested": len(parameters),
            "generated": len(parameters),
            "kept": len(parameters),
            "failed": 0,
            "non_monotone": int(passed.sum()),
            "measured": 0,
            "curves_with_mask": int(masked.any(axis=1).sum()),
            "curves_without_backbone": int(masked.all(axis=1).sum()),
            "masked_entries": {
                reason: int(np.sum(reasons == 1 + i)) for i, reason in enumerate(MASK_REASONS)
            },
        },
    )  # fmt: skip
    columns = [GRID_CHANNELS.index(c) for c in channels]
    return BackboneDataset(
        X=parameters,
        Y=values[..., columns],
        spec=spec,
        origin=np.full(len(parameters), ANALYTICAL),
        non_monotone=passed,
        failed_parameters=np.empty((0, len(names))),
        failed_reasons=np.empty(0, dtype=str),
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
    scatter: ArrayLike | None = None,
    misfit_threshold: float = 1.0,
    misfit_policy: MisfitPolicy = "exclude",
) -> BackboneDataset:
    """The dataset with measured backbones appended, labelled by their fitted parameters.

    Parameters
    ----------
    dataset
        Analytical dataset whose grid, channels and box the curves must meet.
    backbones
        Measured curves, each on its own excitation levels.
    labels
        ``(n_curves, n_params)`` parameters of each curve (e.g. from fitting the
        model to that curve alone, :func:`identification.fitting.least_squares.fit_backbones`), in
        the order of ``dataset.spec.parameter_names``.
    level_gain
        How a point's base-acceleration amplitude is known
        (:func:`~surrogates.grid.point_base_acceleration`): None from the power
        balance of the point, a number as ``excitation_level × level_gain``.
    scatter
        Amplitude grid: ``(n_levels, 3)`` assembly standard deviations of
        frequency, damping ratio and base acceleration on the grid; default
        :func:`~surrogates.grid.assembly_scatter` of ``backbones`` themselves.
    misfit_threshold, misfit_policy
        Amplitude grid: what becomes of a curve whose label misfits it by more
        than ``misfit_threshold`` assembly standard deviations in frequency
        (:mod:`surrogates.labels`): left out, down-weighted or kept.

    On excitation levels each curve is sorted by level (equal levels averaged)
    and its amplitude, frequency and damping ratio interpolated linearly onto
    the dataset's levels; a curve that does not cover them is left out. On the
    amplitude grid a curve enters where it covers the grid (``observed``); the
    rest of its row is its label's own backbone, which carries no loss weight
    but gives the autoencoder a whole curve to encode; every curve's label
    misfit is kept in ``label_misfit`` and ``provenance["measured"]["label_misfit"]``.
    A curve whose labels lie outside the training box is left out. Every curve
    left out is named in a warning and, with why, in
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
    misfit_weight(math.nan, misfit_threshold, misfit_policy)  # checks the policy's arguments
    on_grid = spec.representation == "amplitude_grid"
    by_channel: dict[str, dict[str, float]] = {}
    if on_grid:
        rows = _grid_rows(dataset, curves, values, level_gain, scatter, by_channel)
    else:
        columns = [_ALL_CHANNELS.index(c) for c in spec.channels]
        rows = []
        for curve, label in zip(curves, values, strict=True):
            try:
                spec.require_in_box(label[None], f"labels of curve {curve.label!r}")
                y = _measured_on_levels(curve, spec.levels, level_gain)[:, columns]
                rows.append((curve.label, label, y, None, math.nan, None))
            except ValueError as exc:
                rows.append((curve.label, label, None, None, math.nan, str(exc)))
    added, excluded, misfits, kept = [], {}, {}, []
    for name, label, y, observed, misfit, reason in rows:
        if on_grid and reason is None:
            misfits[name] = misfit
            weight = misfit_weight(misfit, misfit_threshold, misfit_policy)
            if weight is None and math.isinf(misfit):
                reason = "its label's model has no backbone at an amplitude it was measured at"
            elif weight is None:
                reason = (
                    f"its label misfits it by {misfit:.3g} assembly standard deviations in "
                    f"frequency (threshold {misfit_threshold:g})"
                )
        if reason is not None:
            excluded[name] = reason
            warnings.warn(f"add_measured: curve {name!r} left out: {reason}", stacklevel=2)
            continue
        added.append(name)
        kept.append((label, y, observed, misfit, weight if on_grid else 1.0))
    if on_grid and misfits and all(math.isnan(m) for m in misfits.values()):
        warnings.warn(
            "add_measured: no label misfit could be computed (fewer than 3 curves cover every "
            "grid amplitude and no scatter was given): the curves are kept unchecked",
            stacklevel=2,
        )
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
    if on_grid:
        record.setdefault("label_misfit", {}).update(
            {k: _json_misfit(v) for k, v in misfits.items()}
        )
        record.setdefault("label_misfit_by_channel", {}).update(
            {k: {c: _json_misfit(v) for c, v in m.items()} for k, m in by_channel.items()}
        )
        record["misfit_policy"] = {"policy": misfit_policy, "threshold": misfit_threshold}
    provenance["counts"]["measured"] = len(record["added"])
    provenance.pop("splits", None)  # the new curves are in no split yet
    n, shape = len(kept), (len(kept), *spec.backbone_shape)
    labels_kept, ys, observed, misfit, weight = ([k[i] for k in kept] for i in range(5))
    return dataclasses.replace(
        dataset,
        X=np.vstack([dataset.X, np.reshape(labels_kept, (n, spec.n_params))]),
        Y=np.concatenate([dataset.Y, np.reshape(ys, shape)]),
        origin=np.concatenate([dataset.origin, np.array(origin, dtype=str)]),
        non_monotone=np.concatenate([dataset.non_monotone, np.zeros(n, dtype=bool)]),
        observed=np.concatenate(
            [
                dataset.observed,
                np.ones((n, spec.n_levels), bool)
                if not on_grid
                else np.reshape(observed, (n, spec.n_levels)),
            ]
        ),
        partition=np.concatenate([dataset.partition, np.full(n, "", dtype="<U10")]),
        weight=np.concatenate([dataset.weight, np.asarray(weight, dtype=float)]),
        label_misfit=np.concatenate([dataset.label_misfit, np.asarray(misfit, dtype=float)]),
        provenance=provenance,
    )


def _json_misfit(misfit: float) -> float | str | None:
    """A misfit as strict JSON (which has no NaN or infinity)."""
    if math.isnan(misfit):
        return None
    return misfit if math.isfinite(misfit) else "no backbone at a measured amplitude"


def _grid_rows(
    dataset: BackboneDataset,
    curves: list,
    labels: np.ndarray,
    level_gain: float | None,
    scatter: ArrayLike | None,
    by_channel: dict[str, dict[str, float]],
) -> list[tuple]:
    """Per curve ``(name, label, row, observed, misfit, reason)`` on the amplitude grid.

    ``reason`` is None for a usable curve, else why it is left out; ``misfit`` is
    the frequency's. ``by_channel`` receives every value channel's misfit per curve.
    """
    spec, provenance = dataset.spec, dataset.provenance
    grid = spec.amplitudes_m
    if scatter is None:
        scatter = assembly_scatter(BackboneSet(curves), grid, level_gain=level_gain)
    scatter = np.asarray(scatter, dtype=float)
    if scatter.shape != (spec.n_levels, 3):
        raise ValueError(f"scatter must have shape ({spec.n_levels}, 3), got {scatter.shape}")
    inside = ~spec.outside_box(labels)
    harmonic = provenance["harmonic"]
    how = GridEvaluation(
        grid, harmonic["method"], harmonic["harmonics"], **provenance["evaluation"]
    )
    model = JointModel.from_dict(provenance["model"])
    own = np.zeros((len(curves), spec.n_levels, len(GRID_CHANNELS)))
    if inside.any():
        own[inside] = grid_backbones(model, list(spec.parameter_names), labels[inside], how)[0]
    columns = [GRID_CHANNELS.index(c) for c in spec.channels]
    frequency, mask = GRID_CHANNELS.index("frequency_hz"), GRID_CHANNELS.index(MASK_CHANNEL)
    rows = []
    for curve, label, label_backbone, in_box in zip(curves, labels, own, inside, strict=True):
        try:
            if not in_box:
                spec.require_in_box(label[None], f"labels of curve {curve.label!r}")
            values, observed = measured_on_grid(curve, grid, level_gain)
        except ValueError as exc:
            rows.append((curve.label, label, None, None, math.nan, str(exc)))
            continue
        if observed.sum() < 2:
            reason = "it covers fewer than two amplitudes of the grid"
            rows.append((curve.label, label, None, None, math.nan, reason))
            continue
        exists = label_backbone[:, mask] >= 0.5
        by_channel[curve.label] = {
            channel: label_misfit(
                values[:, j], observed, label_backbone[:, j], exists, scatter[:, j]
            )
            for j, channel in enumerate(GRID_CHANNELS[:3])
        }
        misfit = by_channel[curve.label][GRID_CHANNELS[frequency]]
        row = label_backbone.copy()
        row[observed, :3] = values[observed]
        row[observed, mask] = 1.0
        rows.append((curve.label, label, row[:, columns], observed, misfit, None))
    return rows


def _measured_on_levels(curve, levels: np.ndarray, level_gain: float | None) -> np.ndarray:
    """``(n_levels, 3)`` amplitude, frequency, damping of a measured curve on ``levels``."""
    own = point_base_acceleration(curve, level_gain)
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
