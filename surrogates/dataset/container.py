"""The dataset record: parameter vectors, their backbones on a fixed grid, its file.

A :class:`BackboneDataset` is saved as one ``.npz`` with a JSON provenance
record (model, names, box, levels, method, seed, sampler, versions, counts) and
a SHA-256 of its content that :meth:`BackboneDataset.load` checks.
"""

from __future__ import annotations

import dataclasses
import io
import json
import zipfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.artifacts import atomic_write_bytes, sha256_bytes
from surrogates.runtime import MASK_CHANNEL, SurrogateSpec

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
