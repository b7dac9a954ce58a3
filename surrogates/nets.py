"""The paper's backbone networks: a 1D-CNN autoencoder and a parameter-to-latent FFNN.

Architecture (paper Tables 1–4), generalised to ``n_params`` inputs, ``n_levels``
grid points (the paper's 41 excitation levels, or the response amplitudes of an
amplitude grid) and ``n_channels`` backbone channels (2 in the paper: amplitude
and frequency; more here, e.g. the damping ratio)::

    Encoder  Conv1D(64, k5, same, elu) → Conv1D(32, k5, causal, dilation 4, elu)
             → Flatten → Dense(64, relu)
    Decoder  Dense(32·n_levels, relu) → Reshape(n_levels, 32)
             → Conv1D(64, k5, causal, dilation 4, elu) → Conv1D(n_channels, k5, same)
    FFNN     n_params → 4 × Dense(512, elu) → Dense(64)

Layout: every public module takes and returns backbones as ``(batch, n_levels,
n_channels)``, the dataset's (and Keras') channels-last layout. Inside, the
convolutions run channels-first ``(batch, channels, n_levels)`` as torch wants,
so Flatten and Reshape order their features (channel, grid point) where Keras
orders them (grid point, channel): the same function class and the same parameter counts,
but Keras weights would need that permutation to be loaded here.

Padding follows Keras: "same" pads ``(k − 1)·d / 2`` on each side, "causal" pads
``(k − 1)·d`` on the left only, so output point j sees input points ≤ j.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Literal

import numpy as np
import torch
from torch import nn
from torch.nn import functional

from surrogates.baselines import monomial_factors

__all__ = [
    "Autoencoder",
    "Decoder",
    "Encoder",
    "KerasConv1d",
    "LatentRegressor",
    "NetConfig",
    "PhysicalSurrogate",
    "decay_rate_channels",
    "network_sizes",
    "to_decay_rate",
]


@dataclass(frozen=True)
class NetConfig:
    """Sizes of the networks; the defaults are the paper's."""

    latent_dim: int = 64
    conv_filters: tuple[int, int] = (64, 32)
    kernel_size: int = 5
    dilation: int = 4
    ffnn_width: int = 512
    ffnn_depth: int = 4

    def __post_init__(self) -> None:
        sizes = (self.latent_dim, *self.conv_filters, self.ffnn_width, self.ffnn_depth)
        if min(sizes) < 1 or self.dilation < 1:
            raise ValueError(f"network sizes must be positive integers: {self}")
        if self.kernel_size < 1 or self.kernel_size % 2 == 0:
            raise ValueError(
                f"kernel_size must be odd for Keras 'same' padding: {self.kernel_size}"
            )
        object.__setattr__(self, "conv_filters", tuple(int(f) for f in self.conv_filters))

    def to_dict(self) -> dict:
        """Plain-JSON form."""
        return {**asdict(self), "conv_filters": list(self.conv_filters)}


class KerasConv1d(nn.Module):
    """Conv1d with Keras' "same" or "causal" padding on channels-first input."""

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        kernel_size: int,
        padding: Literal["same", "causal"],
        dilation: int = 1,
    ) -> None:
        super().__init__()
        total = (kernel_size - 1) * dilation
        if padding == "same":
            self.pad = (total // 2, total - total // 2)
        elif padding == "causal":
            self.pad = (total, 0)
        else:
            raise ValueError(f"padding must be 'same' or 'causal', got {padding!r}")
        self.conv = nn.Conv1d(in_channels, out_channels, kernel_size, dilation=dilation)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.conv(functional.pad(x, self.pad))


class Encoder(nn.Module):
    """Backbone ``(batch, n_levels, n_channels)`` → latent ``(batch, latent_dim)``."""

    def __init__(self, n_levels: int, n_channels: int, config: NetConfig = NetConfig()) -> None:
        super().__init__()
        f1, f2 = config.conv_filters
        k, d = config.kernel_size, config.dilation
        self.conv1 = KerasConv1d(n_channels, f1, k, "same")
        self.conv2 = KerasConv1d(f1, f2, k, "causal", dilation=d)
        self.dense = nn.Linear(f2 * n_levels, config.latent_dim)

    def forward(self, backbone: torch.Tensor) -> torch.Tensor:
        h = functional.elu(self.conv1(backbone.transpose(1, 2)))
        h = functional.elu(self.conv2(h))
        return functional.relu(self.dense(h.flatten(1)))


class Decoder(nn.Module):
    """Latent ``(batch, latent_dim)`` → backbone ``(batch, n_levels, n_channels)``."""

    def __init__(self, n_levels: int, n_channels: int, config: NetConfig = NetConfig()) -> None:
        super().__init__()
        f1, f2 = config.conv_filters
        k, d = config.kernel_size, config.dilation
        self.n_levels, self.reshape_channels = n_levels, f2
        self.dense = nn.Linear(config.latent_dim, f2 * n_levels)
        self.conv1 = KerasConv1d(f2, f1, k, "causal", dilation=d)
        self.conv2 = KerasConv1d(f1, n_channels, k, "same")

    def forward(self, latent: torch.Tensor) -> torch.Tensor:
        h = functional.relu(self.dense(latent))
        h = h.reshape(-1, self.reshape_channels, self.n_levels)
        h = functional.elu(self.conv1(h))
        return self.conv2(h).transpose(1, 2)


class LatentRegressor(nn.Module):
    """The paper's FFNN: parameters scaled to [0, 1] → latent ``(batch, latent_dim)``."""

    def __init__(self, n_params: int, config: NetConfig = NetConfig()) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        width_in = n_params
        for _ in range(config.ffnn_depth):
            layers += [nn.Linear(width_in, config.ffnn_width), nn.ELU()]
            width_in = config.ffnn_width
        layers.append(nn.Linear(width_in, config.latent_dim))
        self.layers = nn.Sequential(*layers)

    def forward(self, parameters: torch.Tensor) -> torch.Tensor:
        return self.layers(parameters)


class Autoencoder(nn.Module):
    """Encoder followed by decoder: the first training stage."""

    def __init__(self, n_levels: int, n_channels: int, config: NetConfig = NetConfig()) -> None:
        super().__init__()
        self.encoder = Encoder(n_levels, n_channels, config)
        self.decoder = Decoder(n_levels, n_channels, config)

    def forward(self, backbone: torch.Tensor) -> torch.Tensor:
        return self.decoder(self.encoder(backbone))


def _float32(values: np.ndarray) -> torch.Tensor:
    return torch.as_tensor(np.asarray(values, dtype=np.float32))


class PhysicalSurrogate(nn.Module):
    """FFNN + decoder with the scalings folded in: physical parameters → physical backbones.

    The input is min–max scaled with the training box, ``u = (p − low) / (high − low)``;
    the network's output ``s(u) = decoder(ffnn(u))`` lives in the scaled space and
    is un-scaled with ``y = s · scale + offset`` (``offset``, ``scale``:
    ``(n_levels, n_channels)``). Two optional parts:

    ``head``
        ``(degree, coefficients (n_monomials, n_levels, n_channels))``: a
        polynomial in ``u`` per (grid point, channel) in physical units, the monomials
        of :func:`~surrogates.baselines.monomial_factors`;
        ``y = s · scale + offset + head(u)``, so the network learns the
        (standardised) residual of a regression, a baseline it must beat, rather
        than the whole curve. Each monomial is a product of ``degree`` factors
        ``u · select + offset`` (one-hot columns, or the constant 1), so the graph
        needs no gather.
    ``probability_channels``
        ``(n_channels,)`` booleans: those channels are logits in the scaled
        space and leave the graph through a sigmoid, as probabilities (the
        amplitude grid's ``has_backbone`` mask).
    ``decay_rate``
        ``(damping, frequency)`` channel indices: the networks and the head
        learn the damping channel as the decay rate ``σ = ζ·ω = 2π f ζ`` (1/s,
        :func:`to_decay_rate`), and the graph returns ``ζ = σ / (2π f)`` with
        the frequency it predicts itself.

    This is the graph that is exported to ONNX, so the artifact needs no pre- or
    post-processing (ops: Gemm/MatMul, Elu, Relu, Reshape, Conv, Transpose and
    elementwise arithmetic, plus Sigmoid with a probability channel).
    """

    def __init__(
        self,
        regressor: LatentRegressor,
        decoder: Decoder,
        bounds: np.ndarray,
        output_offset: np.ndarray,
        output_scale: np.ndarray,
        *,
        head: tuple[int, np.ndarray] | None = None,
        probability_channels: np.ndarray | None = None,
        decay_rate: tuple[int, int] | None = None,
    ) -> None:
        super().__init__()
        self.regressor, self.decoder = regressor, decoder
        bounds = np.asarray(bounds, dtype=np.float64)
        self.register_buffer("input_low", _float32(bounds[:, 0]))
        self.register_buffer("input_span", _float32(bounds[:, 1] - bounds[:, 0]))
        self.register_buffer("output_offset", _float32(output_offset))
        self.register_buffer("output_scale", _float32(output_scale))
        self.head_degree = 0 if head is None else int(head[0])
        if head is not None:
            factors = monomial_factors(bounds.shape[0], self.head_degree)
            select = np.zeros((self.head_degree, bounds.shape[0], len(factors)))
            for k, column in np.argwhere(factors.T > 0):
                select[k, factors[column, k] - 1, column] = 1.0
            coefficients = np.asarray(head[1], dtype=np.float64)
            self.register_buffer("head_select", _float32(select))
            self.register_buffer("head_offset", _float32((factors.T == 0).astype(float)))
            self.register_buffer(
                "head_weight", _float32(coefficients.reshape(coefficients.shape[0], -1))
            )
        self.has_probabilities = probability_channels is not None and bool(
            np.any(probability_channels)
        )
        if self.has_probabilities:
            selector = np.broadcast_to(
                np.asarray(probability_channels, dtype=float), np.shape(output_offset)
            )
            self.register_buffer("probability_selector", _float32(selector))
        self.decay_rate = None if decay_rate is None else tuple(int(i) for i in decay_rate)
        if self.decay_rate is not None:
            damping, frequency = np.eye(np.shape(output_offset)[-1])[list(self.decay_rate)]
            self.register_buffer("damping_selector", _float32(damping))
            # A column with 2π folded in: the product picks ω (rad/s) by MatMul, an op the
            # likelihood's ONNX → pytensor translation has (pm_joint.forward.surrogate).
            self.register_buffer("omega_selector", _float32(2 * np.pi * frequency[:, None]))

    def scale_parameters(self, parameters: torch.Tensor) -> torch.Tensor:
        """Physical parameters → the unit box the FFNN was trained on."""
        return (parameters - self.input_low) / self.input_span

    def head_part(self, unit_parameters: torch.Tensor) -> torch.Tensor:
        """The polynomial head's contribution in physical units."""
        features = unit_parameters @ self.head_select[0] + self.head_offset[0]
        for k in range(1, self.head_degree):
            features = features * (unit_parameters @ self.head_select[k] + self.head_offset[k])
        return (features @ self.head_weight).reshape(-1, *self.output_offset.shape)

    def scaled_backbones(self, unit_parameters: torch.Tensor) -> torch.Tensor:
        """Unit-box parameters → the networks' output, in the training (scaled) space."""
        return self.decoder(self.regressor(unit_parameters))

    def forward(self, parameters: torch.Tensor) -> torch.Tensor:
        unit = self.scale_parameters(parameters)
        physical = self.scaled_backbones(unit) * self.output_scale + self.output_offset
        if self.head_degree:
            physical = physical + self.head_part(unit)
        if self.decay_rate is not None:
            # ζ = σ / ω, ω from the predicted frequency; a divisor of 1 elsewhere (no gather).
            omega = physical @ self.omega_selector
            physical = physical / (1 + self.damping_selector * (omega - 1))
        if not self.has_probabilities:
            return physical
        # Elementwise select (no gather/concat): the graph stays within simple ONNX ops.
        return physical + self.probability_selector * (torch.sigmoid(physical) - physical)


def decay_rate_channels(channels: tuple[str, ...]) -> tuple[int, int] | None:
    """``(damping, frequency)`` indices in ``channels`` for a decay-rate target (None: no damping).

    Raises
    ------
    ValueError
        When the channels hold a damping ratio but no frequency to convert it with.
    """
    if "damping_ratio" not in channels:
        return None
    if "frequency_hz" not in channels:
        raise ValueError(
            f"a decay-rate damping target needs the frequency channel too, got {channels}: "
            "train with damping_target='ratio'"
        )
    return channels.index("damping_ratio"), channels.index("frequency_hz")


def to_decay_rate(
    backbones: np.ndarray, weights: np.ndarray, channels: tuple[int, int]
) -> tuple[np.ndarray, np.ndarray]:
    """The damping channel as the decay rate ``σ = 2π f ζ`` (1/s), and the weights for it.

    ``channels``: ``(damping, frequency)`` indices (:func:`decay_rate_channels`).
    ``(n, n_levels, n_channels)`` backbones and weights; a damping entry whose
    frequency has no weight (not observed) gets weight 0, as its rate is unknown.
    Why: the single-harmonic damping ratio is ``ζ(a) = c_eq(a) / (2ω(a))`` with
    the equivalent viscous damping ``c_eq`` linear in the damping terms'
    coefficients, so ``σ = c_eq / 2`` carries no division by the
    stiffness-dependent ``ω``, which a polynomial in the parameters (the head)
    fits poorly over a wide box (figures: ``bench/results/surrogate_wide_*.json``).
    """
    damping, frequency = channels
    rate, weights = np.array(backbones, dtype=float), np.array(weights, dtype=float)
    rate[..., damping] *= 2 * np.pi * rate[..., frequency]
    weights[..., damping] = np.where(weights[..., frequency] > 0, weights[..., damping], 0.0)
    return rate, weights


def network_sizes(model: PhysicalSurrogate, autoencoder: Autoencoder, config: NetConfig) -> dict:
    """Layer widths and parameter counts of a surrogate's networks (for sidecars and benches)."""

    def count(module: nn.Module) -> int:
        return int(sum(p.numel() for p in module.parameters()))

    n_levels, n_channels = model.output_offset.shape
    n_params = model.input_low.numel()
    return {
        "input": [int(n_levels), int(n_channels)],
        "latent": config.latent_dim,
        "conv_filters": list(config.conv_filters),
        "kernel_size": config.kernel_size,
        "dilation": config.dilation,
        "ffnn": [int(n_params), *[config.ffnn_width] * config.ffnn_depth, config.latent_dim],
        "head_degree": model.head_degree,
        "damping_target": "ratio" if model.decay_rate is None else "decay_rate",
        "parameters": {
            "encoder": count(autoencoder.encoder),
            "decoder": count(autoencoder.decoder),
            "ffnn": count(model.regressor),
            "exported": count(model),
        },
    }
