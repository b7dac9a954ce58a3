"""Running an exported backbone surrogate on onnxruntime, without torch.

An exported surrogate is a folder with two files::

    surrogate.onnx   one graph: physical parameters (batch, n_params), float32
                     → physical backbones (batch, n_levels, n_channels), float32
    surrogate.json   the sidecar: format, parameter names/order and training box,
                     the grid (excitation levels or response amplitudes), channels
                     with units, scalers, network sizes, test figures and versions,
                     and the SHA-256 of surrogate.onnx

A backbone is sampled on one of two grids (:attr:`SurrogateSpec.representation`):

``"amplitude_grid"``
    Fixed response amplitudes (m). Every parameter vector has a value there: the
    channels are the frequency, the damping ratio and the base-acceleration
    amplitude the backbone needs at that amplitude, plus ``has_backbone``, the
    probability that the model has a backbone point there that a test stepping
    its level up reaches (0 where there is no periodic solution, no positive
    power input, or the level needed is below one already passed). Value
    channels are meaningful only where ``has_backbone`` ≥ 0.5. An N-mode model's
    surrogate (one per mode, :mod:`surrogates.modal`) adds
    ``other_modes_energy_share``, the share of the hold's energy in the other modes.
``"excitation_levels"``
    Fixed base-acceleration levels (m/s²), as a test steps its shaker: the
    response amplitude is an output. Undefined for a parameter vector that
    cannot reach a level, so such vectors are dropped from its datasets.

:class:`SurrogateSpec` is the contract both files share (it is also what
training takes); :class:`SurrogateRuntime` loads the pair, checks that they
belong together and refuses parameters outside the training box unless told
otherwise. This module must stay importable without torch: the sampler's worker
processes load surrogates and should not pay for (or need) torch.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import onnxruntime

from identification.artifacts import check_sha256, sha256_bytes, sha256_json

__all__ = [
    "CHANNEL_UNITS",
    "FORMAT",
    "FORMAT_VERSION",
    "MASK_CHANNEL",
    "MODEL_FILE",
    "OTHER_MODES_CHANNEL",
    "REPRESENTATION_CHANNELS",
    "SIDECAR_FILE",
    "SurrogateRuntime",
    "SurrogateSpec",
]

FORMAT = "pm-joint/Surrogate"
FORMAT_VERSION = 2
MODEL_FILE = "surrogate.onnx"
SIDECAR_FILE = "surrogate.json"

#: Backbone channels a surrogate may predict, with their (SI) units.
CHANNEL_UNITS = {
    "amplitude_m": "m",
    "frequency_hz": "Hz",
    "damping_ratio": "1",
    "base_acceleration_m_s2": "m/s^2",
    "has_backbone": "1",
    "other_modes_energy_share": "1",
}
#: The mask channel of the amplitude grid: probability that a backbone point exists.
MASK_CHANNEL = "has_backbone"
#: An N-mode surrogate's channel: the share of the linear modal energy in the modes not
#: locked (:mod:`surrogates.dataset.modal`).
OTHER_MODES_CHANNEL = "other_modes_energy_share"
#: Channels each representation allows (the grid's own quantity is not a channel).
REPRESENTATION_CHANNELS = {
    "excitation_levels": ("amplitude_m", "frequency_hz", "damping_ratio"),
    "amplitude_grid": (
        "frequency_hz", "damping_ratio", "base_acceleration_m_s2", MASK_CHANNEL,
        OTHER_MODES_CHANNEL,
    ),
}  # fmt: skip

Extrapolate = Literal["raise", "flag", "allow"]
_EXTRAPOLATE = ("raise", "flag", "allow")


@dataclass(frozen=True, eq=False)
class SurrogateSpec:
    """What a surrogate maps from and to.

    Parameters
    ----------
    parameter_names
        Input parameters, in the order of the parameter vector.
    bounds
        ``(n_params, 2)`` training box, ``[low, high]`` per parameter (SI).
    levels
        The fixed excitation levels of every backbone, increasing, in
        ``level_unit`` (``"excitation_levels"`` representation); None with
        ``amplitudes_m``. The name is the sidecar's key.
    channels
        Backbone channels, names from :data:`REPRESENTATION_CHANNELS` of the
        representation; the amplitude grid needs :data:`MASK_CHANNEL`.
    level_unit
        Unit of ``levels`` (base-acceleration amplitude by default).
    amplitudes_m
        The fixed response amplitudes (m) of every backbone, increasing
        (``"amplitude_grid"`` representation); give this or ``levels``.
    """

    parameter_names: tuple[str, ...]
    bounds: np.ndarray
    levels: np.ndarray | None = None
    channels: tuple[str, ...] = ("amplitude_m", "frequency_hz")
    level_unit: str = "m/s^2"
    amplitudes_m: np.ndarray | None = None

    def __post_init__(self) -> None:
        names = tuple(str(n) for n in self.parameter_names)
        if not names or len(set(names)) != len(names):
            raise ValueError(f"parameter names must be non-empty and unique: {names}")
        bounds = np.array(self.bounds, dtype=np.float64)
        if bounds.shape != (len(names), 2):
            raise ValueError(f"bounds must have shape ({len(names)}, 2), got {bounds.shape}")
        for name, (low, high) in zip(names, bounds, strict=True):
            if not (math.isfinite(low) and math.isfinite(high) and low < high):
                raise ValueError(
                    f"bounds of parameter {name!r} must be finite, low < high: [{low}, {high}]"
                )
        if (self.levels is None) == (self.amplitudes_m is None):
            raise ValueError("give either levels (m/s²) or amplitudes_m (m), not both or neither")
        grid_name = "levels" if self.amplitudes_m is None else "amplitudes_m"
        grid = np.array(getattr(self, grid_name), dtype=np.float64)
        if grid.ndim != 1 or grid.size < 2 or not np.all(np.isfinite(grid)):
            raise ValueError(f"{grid_name} must be a finite 1-D array of >= 2 values: {grid}")
        if np.any(np.diff(grid) <= 0):
            raise ValueError(f"{grid_name} must be strictly increasing")
        if grid_name == "amplitudes_m" and grid[0] <= 0:
            raise ValueError(f"amplitudes_m must be positive: {grid}")
        channels = tuple(str(c) for c in self.channels)
        allowed = REPRESENTATION_CHANNELS[self.representation]
        unknown = [c for c in channels if c not in allowed]
        if unknown or not channels or len(set(channels)) != len(channels):
            raise ValueError(
                f"channels of the {self.representation} representation must be unique names "
                f"from {list(allowed)}, got {channels}"
            )
        if self.representation == "amplitude_grid" and (
            MASK_CHANNEL not in channels or len(channels) < 2
        ):
            raise ValueError(
                f"an amplitude grid needs the mask channel {MASK_CHANNEL!r} and at least one "
                f"value channel, got {channels}"
            )
        bounds.flags.writeable = grid.flags.writeable = False
        object.__setattr__(self, "parameter_names", names)
        object.__setattr__(self, "bounds", bounds)
        object.__setattr__(self, grid_name, grid)
        object.__setattr__(self, "channels", channels)

    @property
    def representation(self) -> str:
        """``"amplitude_grid"`` or ``"excitation_levels"`` (see the module docstring)."""
        return "excitation_levels" if self.amplitudes_m is None else "amplitude_grid"

    @property
    def grid(self) -> np.ndarray:
        """The points of every backbone: ``levels`` (m/s²) or ``amplitudes_m`` (m)."""
        return self.levels if self.amplitudes_m is None else self.amplitudes_m

    @property
    def n_params(self) -> int:
        return len(self.parameter_names)

    @property
    def n_levels(self) -> int:
        """Grid points per backbone: excitation levels, or amplitudes of the amplitude grid."""
        return self.grid.size

    @property
    def n_channels(self) -> int:
        return len(self.channels)

    @property
    def backbone_shape(self) -> tuple[int, int]:
        """``(n_levels, n_channels)``: one backbone."""
        return self.n_levels, self.n_channels

    @property
    def value_channels(self) -> tuple[str, ...]:
        """The channels that carry a physical value (all but the mask)."""
        return tuple(c for c in self.channels if c != MASK_CHANNEL)

    def channel_index(self, channel: str) -> int:
        """Position of ``channel`` in the last axis of a backbone array."""
        if channel not in self.channels:
            raise ValueError(f"channel {channel!r} is not predicted; channels: {self.channels}")
        return self.channels.index(channel)

    def check_parameters(self, parameters: Any, what: str = "parameters") -> np.ndarray:
        """``parameters`` as a finite float64 ``(n, n_params)`` array, else ValueError."""
        array = np.asarray(parameters, dtype=np.float64)
        if array.ndim == 1:
            array = array[None, :]
        if array.ndim != 2 or array.shape[1] != self.n_params:
            raise ValueError(
                f"{what}: expected vectors of {self.n_params} parameters "
                f"({', '.join(self.parameter_names)}), got shape {np.shape(parameters)}"
            )
        bad = ~np.isfinite(array)
        if bad.any():
            row, col = np.argwhere(bad)[0]
            raise ValueError(
                f"{what}: parameter {self.parameter_names[col]!r} is not finite "
                f"({array[row, col]}) in row {row}"
            )
        return array

    def outside_box(self, parameters: np.ndarray) -> np.ndarray:
        """Boolean mask of the rows of a checked ``(n, n_params)`` array outside the box."""
        low, high = self.bounds[:, 0], self.bounds[:, 1]
        return np.any((parameters < low) | (parameters > high), axis=1)

    def require_in_box(
        self, parameters: np.ndarray, what: str = "parameters", hint: str = ""
    ) -> None:
        """Raise ValueError naming the first parameter outside its training bound."""
        for row, vector in enumerate(parameters):
            for name, value, (low, high) in zip(
                self.parameter_names, vector, self.bounds, strict=True
            ):
                if value < low or value > high:
                    side, bound = ("lower", low) if value < low else ("upper", high)
                    raise ValueError(
                        f"{what}: parameter {name!r} = {value:.6g} in row {row} is outside the "
                        f"training box ({side} bound {bound:.6g}){hint}"
                    )

    def check_backbones(self, backbones: Any, what: str = "backbones") -> np.ndarray:
        """``backbones`` as a finite float64 ``(n, n_levels, n_channels)`` array."""
        array = np.asarray(backbones, dtype=np.float64)
        if array.ndim != 3 or array.shape[1:] != self.backbone_shape:
            raise ValueError(
                f"{what}: expected shape (n, {self.n_levels}, {self.n_channels}) "
                f"for levels x channels {self.channels}, got {array.shape}"
            )
        bad = ~np.isfinite(array)
        if bad.any():
            row, point, channel = np.argwhere(bad)[0]
            raise ValueError(
                f"{what}: channel {self.channels[channel]!r} is not finite at "
                f"level {point} of curve {row}"
            )
        if MASK_CHANNEL in self.channels:
            mask = array[..., self.channel_index(MASK_CHANNEL)]
            if np.any((mask < 0) | (mask > 1)):
                raise ValueError(f"{what}: channel {MASK_CHANNEL!r} must lie in [0, 1]")
        return array

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (as written in the sidecar)."""
        grid = (
            {"levels": self.levels.tolist(), "level_unit": self.level_unit}
            if self.amplitudes_m is None
            else {"amplitudes_m": self.amplitudes_m.tolist()}
        )
        return {
            "representation": self.representation,
            "parameter_names": list(self.parameter_names),
            "bounds": self.bounds.tolist(),
            **grid,
            "channels": list(self.channels),
            "channel_units": {c: CHANNEL_UNITS[c] for c in self.channels},
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> SurrogateSpec:
        """Inverse of :meth:`to_dict` (a sidecar without a representation has excitation levels)."""
        representation = data.get("representation", "excitation_levels")
        if representation not in REPRESENTATION_CHANNELS:
            raise ValueError(
                f"surrogate spec: representation must be one of {list(REPRESENTATION_CHANNELS)}, "
                f"got {representation!r}"
            )
        grid = "levels" if representation == "excitation_levels" else "amplitudes_m"
        missing = [k for k in ("parameter_names", "bounds", grid, "channels") if k not in data]
        if missing:
            raise ValueError(f"surrogate spec lacks {', '.join(missing)}")
        for key in ("parameter_names", "channels"):
            if not isinstance(data[key], list | tuple):
                raise ValueError(f"surrogate spec: {key} must be a list, got {data[key]!r}")
        arrays = {}
        for key in ("bounds", grid):
            try:
                arrays[key] = np.asarray(data[key], dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(
                    f"surrogate spec: {key} must be numbers, got {data[key]!r}"
                ) from None
        return cls(
            parameter_names=tuple(data["parameter_names"]),
            bounds=arrays["bounds"],
            channels=tuple(data["channels"]),
            level_unit=data.get("level_unit", "m/s^2"),
            **{grid: arrays[grid]},
        )


class SurrogateRuntime:
    """An exported surrogate on onnxruntime: physical parameters → physical backbones.

    Picklable: it keeps the model bytes and builds the (unpicklable) inference
    session lazily, once per process.

    Parameters
    ----------
    model_bytes
        The ONNX graph.
    metadata
        The sidecar's content; its ``onnx.sha256`` must match ``model_bytes``.
    source
        Where the pair came from, for error messages.
    extrapolate
        Default for :meth:`predict`: ``"raise"`` (ValueError for parameters
        outside the training box), ``"flag"`` (also return the out-of-box mask)
        or ``"allow"``.
    threads
        onnxruntime intra- and inter-op threads; 1 suits one sampler chain per core.
    """

    def __init__(
        self,
        model_bytes: bytes,
        metadata: Mapping[str, Any],
        *,
        source: str = "<memory>",
        extrapolate: Extrapolate = "raise",
        threads: int = 1,
    ) -> None:
        if not isinstance(metadata, Mapping) or metadata.get("format") != FORMAT:
            found = metadata.get("format") if isinstance(metadata, Mapping) else metadata
            raise ValueError(f"{source}: not a {FORMAT} sidecar (format {found!r})")
        version = metadata.get("format_version", 0)
        if not isinstance(version, int) or isinstance(version, bool):
            raise ValueError(f"{source}: format_version must be an integer, got {version!r}")
        if version > FORMAT_VERSION:
            raise ValueError(
                f"{source}: format version {version} is newer "
                f"than this pm-joint reads ({FORMAT_VERSION})"
            )
        recorded = metadata.get("content_sha256")
        if recorded is not None:
            content = {k: v for k, v in metadata.items() if k != "content_sha256"}
            try:
                actual = sha256_json(content)
            except ValueError:  # NaN has no canonical form: not the content that was hashed
                actual = "(content with NaN or infinity)"
            check_sha256(recorded, actual, source, "the sidecar's content")
        graph_entry = metadata.get("onnx", {})
        if not isinstance(graph_entry, Mapping):
            raise ValueError(f"{source}: sidecar entry 'onnx' must be an object")
        expected = graph_entry.get("sha256")
        actual = sha256_bytes(model_bytes)
        if expected != actual:
            raise ValueError(
                f"{source}: hash mismatch: the ONNX graph has SHA-256 {actual}, "
                f"the sidecar records {expected}; the files do not belong together "
                "or one was modified"
            )
        try:
            self.spec = SurrogateSpec.from_dict(metadata)
        except ValueError as error:
            raise ValueError(f"{source}: sidecar: {error}") from None
        self.metadata = dict(metadata)
        self.source = source
        self.extrapolate = _check_extrapolate(extrapolate)
        self.threads = int(threads)
        self._model_bytes = bytes(model_bytes)
        self._session: onnxruntime.InferenceSession | None = None
        self._check_graph()

    @classmethod
    def load(cls, folder: str | Path, **options: Any) -> SurrogateRuntime:
        """Load ``folder/surrogate.onnx`` with its sidecar ``folder/surrogate.json``."""
        folder = Path(folder)
        sidecar = folder / SIDECAR_FILE
        try:
            metadata = json.loads(sidecar.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ValueError(f"{sidecar}: no surrogate sidecar here") from None
        except json.JSONDecodeError as error:
            raise ValueError(f"{sidecar}: not valid JSON ({error})") from None
        model = folder / metadata.get("onnx", {}).get("file", MODEL_FILE)
        if not model.is_file():
            raise ValueError(f"{model}: the ONNX graph named by {sidecar} is missing")
        return cls(model.read_bytes(), metadata, source=str(model), **options)

    # -- the session ---------------------------------------------------------

    @property
    def session(self) -> onnxruntime.InferenceSession:
        """The inference session, built on first use in each process."""
        if self._session is None:
            options = onnxruntime.SessionOptions()
            options.intra_op_num_threads = self.threads
            options.inter_op_num_threads = self.threads
            options.execution_mode = onnxruntime.ExecutionMode.ORT_SEQUENTIAL
            self._session = onnxruntime.InferenceSession(
                self._model_bytes, options, providers=["CPUExecutionProvider"]
            )
        return self._session

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_session": None}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    def _check_graph(self) -> None:
        try:
            inputs, outputs = self.session.get_inputs(), self.session.get_outputs()
        except Exception as error:  # onnxruntime raises its own types for unreadable graphs
            raise ValueError(f"{self.source}: onnxruntime cannot load the graph: {error}") from None
        spec = self.spec
        problem = None
        if len(inputs) != 1 or len(outputs) != 1:
            problem = f"the graph has {len(inputs)} inputs and {len(outputs)} outputs, not 1 and 1"
        elif list(inputs[0].shape[1:]) != [spec.n_params] or len(inputs[0].shape) != 2:
            problem = (
                f"the graph takes {inputs[0].shape}, the sidecar names {spec.n_params} parameters"
            )
        elif list(outputs[0].shape[1:]) != list(spec.backbone_shape) or len(outputs[0].shape) != 3:
            problem = (
                f"the graph returns {outputs[0].shape}, the sidecar describes "
                f"{spec.n_levels} levels x {spec.n_channels} channels"
            )
        elif isinstance(inputs[0].shape[0], int) or isinstance(outputs[0].shape[0], int):
            problem = "the graph's batch axis is not dynamic"
        if problem:
            raise ValueError(f"{self.source}: sidecar does not match the graph: {problem}")
        self._input_name = inputs[0].name

    # -- predictions ---------------------------------------------------------

    @property
    def model_bytes(self) -> bytes:
        """The serialised ONNX graph the session runs (read-only)."""
        return self._model_bytes

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return self.spec.parameter_names

    @property
    def bounds(self) -> np.ndarray:
        return self.spec.bounds

    @property
    def levels(self) -> np.ndarray | None:
        """Excitation levels (m/s²) of an ``"excitation_levels"`` surrogate, else None."""
        return self.spec.levels

    @property
    def amplitudes_m(self) -> np.ndarray | None:
        """Response amplitudes (m) of an ``"amplitude_grid"`` surrogate, else None."""
        return self.spec.amplitudes_m

    @property
    def channels(self) -> tuple[str, ...]:
        return self.spec.channels

    def predict(
        self, parameters: Any, *, extrapolate: Extrapolate | None = None
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Backbones for parameter vectors.

        Parameters
        ----------
        parameters
            ``(n, n_params)`` or one ``(n_params,)`` vector, physical units, in the
            order of :attr:`parameter_names`.
        extrapolate
            Overrides the runtime's default (see the class docstring).

        Returns
        -------
        backbones
            float64 ``(n, n_levels, n_channels)``, or ``(n_levels, n_channels)``
            for a single vector.
        outside
            Only with ``extrapolate="flag"``: boolean mask, ``(n,)`` (or a
            scalar for a single vector), True where a row is outside the box.
        """
        mode = _check_extrapolate(self.extrapolate if extrapolate is None else extrapolate)
        single = np.ndim(parameters) == 1
        array = self.spec.check_parameters(parameters)
        outside = self.spec.outside_box(array)
        if mode == "raise" and outside.any():
            self.spec.require_in_box(
                array,
                hint="; the surrogate would extrapolate (extrapolate='flag' or 'allow' "
                "accepts that)",
            )
        feed = {self._input_name: array.astype(np.float32)}
        backbones = self.session.run(None, feed)[0].astype(np.float64)
        if single:
            backbones, outside = backbones[0], outside[0]
        return (backbones, outside) if mode == "flag" else backbones

    def channel(
        self, name: str, parameters: Any, *, extrapolate: Extrapolate | None = None
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """One channel of :meth:`predict`: ``(n, n_levels)`` (or ``(n_levels,)``)."""
        index = self.spec.channel_index(name)
        result = self.predict(parameters, extrapolate=extrapolate)
        if isinstance(result, tuple):
            return result[0][..., index], result[1]
        return result[..., index]

    def amplitude_m(self, parameters: Any, **options: Any) -> np.ndarray | tuple:
        """Response amplitude (m) per excitation level."""
        return self.channel("amplitude_m", parameters, **options)

    def frequency_hz(self, parameters: Any, **options: Any) -> np.ndarray | tuple:
        """Backbone frequency (Hz) per grid point."""
        return self.channel("frequency_hz", parameters, **options)

    def has_backbone(self, parameters: Any, **options: Any) -> np.ndarray | tuple:
        """Per amplitude: True where the predicted backbone exists (mask probability ≥ 0.5)."""
        result = self.channel(MASK_CHANNEL, parameters, **options)
        if isinstance(result, tuple):
            return result[0] >= 0.5, result[1]
        return result >= 0.5

    def __repr__(self) -> str:
        return (
            f"SurrogateRuntime({self.source!r}, parameters={list(self.parameter_names)}, "
            f"levels={self.spec.n_levels}, channels={list(self.channels)})"
        )


def _check_extrapolate(mode: str) -> Extrapolate:
    if mode not in _EXTRAPOLATE:
        raise ValueError(f"extrapolate must be one of {_EXTRAPOLATE}, got {mode!r}")
    return mode  # type: ignore[return-value]
