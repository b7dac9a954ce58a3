"""An N-mode model's surrogate: one exported backbone surrogate per mode, and their index.

A phase-locked test holds one mode at a time, so an N-mode model has N backbones, each on
the amplitudes of its own mode's coordinate. Its surrogate is a folder::

    modal_surrogate.json   the index: format, the modes, the shared parameter names, the
                           ModalModel's content hash, each mode's folder
    mode1/                 a one-mode surrogate folder (surrogate.onnx + surrogate.json,
    mode2/                 :mod:`surrogates.runtime`) of mode m's backbone: frequency,
    …                      damping ratio, drive, the other modes' energy share and the mask
                           on mode m's amplitude grid (:mod:`surrogates.dataset.modal`)

Each mode's network is the paper's (1D-CNN autoencoder of the backbone and a feed-forward
map from the parameters to its code), trained and exported as for one mode, every mode on
the same parameter vector and box. Torch-free, as :mod:`surrogates.runtime`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from identification.artifacts import atomic_write_text
from surrogates.runtime import SIDECAR_FILE, SurrogateRuntime

__all__ = ["INDEX_FILE", "MODAL_FORMAT", "ModalSurrogate", "is_modal_surrogate"]

MODAL_FORMAT = "pm-joint/ModalSurrogate"
MODAL_FORMAT_VERSION = 1
INDEX_FILE = "modal_surrogate.json"


def is_modal_surrogate(folder: str | Path) -> bool:
    """Whether ``folder`` holds an N-mode surrogate (its index file)."""
    return (Path(folder) / INDEX_FILE).is_file()


def mode_folder(folder: str | Path, mode: int) -> Path:
    """Where mode ``mode``'s surrogate lives in an N-mode surrogate's folder."""
    return Path(folder) / f"mode{mode}"


@dataclass(frozen=True, eq=False)
class ModalSurrogate:
    """The surrogates of an N-mode model's backbones, one per mode.

    Attributes
    ----------
    runtimes
        Mode number (from 1) → that mode's :class:`~surrogates.runtime.SurrogateRuntime`.
    model_sha256
        Content hash of the ModalModel the surrogates were trained for.
    source
        The folder it was loaded from (None: not loaded from one).
    """

    runtimes: dict[int, SurrogateRuntime]
    model_sha256: str
    source: Path | None = None

    def __post_init__(self) -> None:
        if not self.runtimes:
            raise ValueError("an N-mode surrogate needs at least one mode's surrogate")
        first = next(iter(self.runtimes.values()))
        for mode, runtime in self.runtimes.items():
            if runtime.parameter_names != first.parameter_names or not np.array_equal(
                runtime.spec.bounds, first.spec.bounds
            ):
                raise ValueError(
                    f"mode {mode}'s surrogate takes {list(runtime.parameter_names)} in another "
                    "box than the first mode's: every mode's surrogate must share parameters "
                    "and box"
                )
            if runtime.amplitudes_m is None:
                raise ValueError(f"mode {mode}'s surrogate is not on an amplitude grid")

    @property
    def modes(self) -> list[int]:
        return sorted(self.runtimes)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(self.runtimes[self.modes[0]].parameter_names)

    @property
    def bounds(self) -> dict[str, tuple[float, float]]:
        """The shared training box, by parameter name."""
        box = self.runtimes[self.modes[0]].spec.bounds
        pairs = zip(self.parameter_names, box, strict=True)
        return {name: (float(low), float(high)) for name, (low, high) in pairs}

    def box(self, names: list[str] | tuple[str, ...]) -> np.ndarray:
        """``(len(names), 2)`` the training box's low and high of the named parameters."""
        bounds = self.bounds
        return np.array([bounds[n] for n in names])

    def write_index(self, folder: str | Path) -> Path:
        """Write ``folder/modal_surrogate.json`` beside the modes' folders."""
        index = {
            "format": MODAL_FORMAT,
            "format_version": MODAL_FORMAT_VERSION,
            "created": datetime.now(UTC).isoformat(timespec="seconds"),
            "modes": self.modes,
            "folders": {str(m): mode_folder(".", m).name for m in self.modes},
            "parameter_names": list(self.parameter_names),
            "model_sha256": self.model_sha256,
        }
        path = Path(folder) / INDEX_FILE
        atomic_write_text(path, json.dumps(index, indent=2) + "\n")
        return path

    @classmethod
    def load(cls, folder: str | Path) -> ModalSurrogate:
        """Load the index and every mode's surrogate (each checks its own hash)."""
        folder = Path(folder)
        path = folder / INDEX_FILE
        if not path.is_file():
            raise FileNotFoundError(f"{folder} holds no N-mode surrogate ({INDEX_FILE})")
        index: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
        if index.get("format") != MODAL_FORMAT:
            raise ValueError(f"{path}: format {index.get('format')!r}, expected {MODAL_FORMAT!r}")
        if index.get("format_version") != MODAL_FORMAT_VERSION:
            raise ValueError(
                f"{path}: format version {index.get('format_version')}, this code reads "
                f"{MODAL_FORMAT_VERSION}"
            )
        runtimes = {}
        for mode in index["modes"]:
            sub = folder / index["folders"][str(mode)]
            if not (sub / SIDECAR_FILE).is_file():
                raise FileNotFoundError(f"{path}: mode {mode}'s surrogate {sub} is missing")
            runtimes[int(mode)] = SurrogateRuntime.load(sub)
        surrogate = cls(runtimes, str(index["model_sha256"]), folder)
        if list(surrogate.parameter_names) != list(index["parameter_names"]):
            raise ValueError(f"{path}: the modes' surrogates do not take the index's parameters")
        return surrogate

    def check_model(self, model_sha256: str) -> None:
        """Raise ValueError when the surrogates were trained for another ModalModel."""
        if model_sha256 != self.model_sha256:
            raise ValueError(
                f"the N-mode surrogate {self.source} was trained for the ModalModel with "
                f"content hash {self.model_sha256[:12]}…, not this one ({model_sha256[:12]}…): "
                "train it again for this model"
            )
