"""Training the backbone surrogate: the paper's two-stage scheme plus a joint fine-tune.

1. **Autoencoder** on the scaled backbones (reconstruction MSE).
2. **FFNN** from the unit-box parameters to the encoder's latents (latent MSE),
   the encoder frozen.
3. **Fine-tune** (ours, optional): FFNN + decoder end-to-end on the backbone
   MSE, at a lower learning rate. Stage 2 only matches latents, and a small
   latent error can be amplified by the decoder; training the composition on
   the quantity that matters removes most of that error.

Scalings: parameters are min–max scaled with the training box (the spec's
bounds) to [0, 1]; backbones are standardised per (level, channel) by default,
so that a 1 % error weighs the same at every excitation level, or per channel.
Both are folded into :class:`~surrogates.nets.PhysicalSurrogate`, the module
that is exported.

Every stage uses Adam (lr 1e-3; 1e-4 for the fine-tune; halved on plateaus),
MSE, mini-batches of 32 (Keras' default), a validation split with early stopping
that restores the best weights, and reports the validation Pearson coefficient per epoch (in the
scaled space).
Runs are seeded: on CPU the same seed gives the same weights; on GPU cuDNN may
not be bitwise reproducible.
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import numpy as np
import torch
from torch import nn
from tqdm.auto import tqdm

from surrogates.evaluate import backbone_metrics
from surrogates.nets import Autoencoder, LatentRegressor, NetConfig, PhysicalSurrogate
from surrogates.runtime import SurrogateSpec

__all__ = ["Surrogate", "TrainingConfig", "output_scaling", "train_surrogate"]


@dataclass(frozen=True)
class TrainingConfig:
    """How to train; the defaults are the paper's where it says, ours where not.

    ``max_epochs`` bounds the autoencoder and FFNN stages, ``finetune_epochs``
    the fine-tune (``0`` gives the paper's pure two-stage model); early stopping
    ends a stage after ``patience`` epochs without a better validation loss.
    ``lr_decay_patience`` (epochs without improvement) halves the learning rate
    on plateaus, down to 1 % of it (None: the paper's constant rate). The
    defaults (400 + 400 + 200 epochs with the decay) are as accurate on the
    trc-like benchmark (``bench/surrogate.py``) as 3000 constant-rate epochs per
    stage with early stopping, in about a quarter of the time. ``threads`` sets
    torch's CPU threads for the training (None: leave torch's setting).
    """

    net: NetConfig = field(default_factory=NetConfig)
    max_epochs: int = 400
    finetune_epochs: int = 200
    patience: int = 200
    batch_size: int = 32
    learning_rate: float = 1e-3
    finetune_learning_rate: float = 1e-4
    lr_decay_patience: int | None = 20
    lr_decay_factor: float = 0.5
    validation_fraction: float = 0.2
    output_scaling: Literal["level", "channel"] = "level"
    seed: int = 0
    device: str | None = None
    threads: int | None = 1
    progress: bool = True

    def __post_init__(self) -> None:
        if not 0.0 < self.validation_fraction < 1.0:
            raise ValueError(f"validation_fraction must be in (0, 1): {self.validation_fraction}")
        if self.output_scaling not in ("level", "channel"):
            raise ValueError(
                f"output_scaling must be 'level' or 'channel': {self.output_scaling!r}"
            )
        if not 0.0 < self.lr_decay_factor < 1.0 or (self.lr_decay_patience or 0) < 0:
            raise ValueError(
                f"lr_decay_factor must be in (0, 1) and lr_decay_patience >= 0: {self}"
            )
        if min(self.max_epochs, self.patience, self.batch_size) < 1 or self.finetune_epochs < 0:
            raise ValueError(f"epochs, patience and batch size must be positive: {self}")

    def to_dict(self) -> dict[str, Any]:
        """Plain-JSON form (the device is left out: it does not change the model)."""
        data = asdict(self)
        data["net"] = self.net.to_dict()
        del data["device"], data["progress"]
        return data


@dataclass
class Surrogate:
    """A trained surrogate: the torch model with everything needed to export it.

    Attributes
    ----------
    spec
        Parameters, box, levels and channels.
    model
        Physical parameters → physical backbones (on CPU, eval mode).
    autoencoder
        The stage-1 autoencoder (its decoder is the model's decoder).
    config
        The training configuration.
    history
        Per stage, one record per epoch: ``epoch``, ``loss``, ``val_loss``,
        ``val_pearson``, ``learning_rate``.
    metrics
        :func:`~surrogates.evaluate.backbone_metrics` on the validation split.
    n_train, n_validation
        Curves used to fit and to stop early.
    train_seconds
        Wall time of the whole training.
    """

    spec: SurrogateSpec
    model: PhysicalSurrogate
    autoencoder: Autoencoder
    config: TrainingConfig
    history: dict[str, list[dict[str, float]]]
    metrics: dict[str, Any]
    n_train: int
    n_validation: int
    train_seconds: float

    def predict(self, parameters: Any) -> np.ndarray:
        """Backbones ``(n, n_levels, n_channels)`` for physical ``(n, n_params)`` parameters."""
        array = self.spec.check_parameters(parameters)
        with torch.no_grad():
            return self.model(torch.from_numpy(array.astype(np.float32))).double().numpy()

    @property
    def best_epochs(self) -> dict[str, int]:
        """Per stage, the epoch whose weights were kept (lowest validation loss)."""
        return {
            stage: min(records, key=lambda r: r["val_loss"])["epoch"]
            for stage, records in self.history.items()
        }

    @property
    def output_offset(self) -> np.ndarray:
        """``(n_levels, n_channels)`` offset of the output scaling."""
        return self.model.output_offset.numpy().astype(np.float64)

    @property
    def output_scale(self) -> np.ndarray:
        """``(n_levels, n_channels)`` scale of the output scaling."""
        return self.model.output_scale.numpy().astype(np.float64)


def output_scaling(
    backbones: np.ndarray, mode: Literal["level", "channel"] = "level"
) -> tuple[np.ndarray, np.ndarray]:
    """Offset and scale, each ``(n_levels, n_channels)``, that standardise backbones.

    ``"level"`` standardises every (level, channel) over the curves, ``"channel"``
    every channel over curves and levels. A spread of zero (a constant entry)
    falls back to the channel's spread, then to 1, so the scaling stays invertible.
    """
    if mode == "level":
        offset, scale = backbones.mean(axis=0), backbones.std(axis=0)
    elif mode == "channel":
        offset = np.broadcast_to(backbones.mean(axis=(0, 1)), backbones.shape[1:]).copy()
        scale = np.broadcast_to(backbones.std(axis=(0, 1)), backbones.shape[1:]).copy()
    else:
        raise ValueError(f"output scaling must be 'level' or 'channel', got {mode!r}")
    channel_scale = backbones.std(axis=(0, 1))
    fallback = np.where(channel_scale > 0, channel_scale, 1.0)
    tiny = 1e-9 * fallback
    return offset, np.where(scale > tiny, scale, fallback)


def train_surrogate(
    parameters: np.ndarray,
    backbones: np.ndarray,
    spec: SurrogateSpec,
    config: TrainingConfig | None = None,
) -> Surrogate:
    """Train a backbone surrogate on a dataset of curves.

    Parameters
    ----------
    parameters
        ``(n, n_params)`` physical parameters, inside ``spec.bounds``.
    backbones
        ``(n, n_levels, n_channels)`` backbones on ``spec.levels``, SI units.
    spec
        Names, box, levels and channels of the dataset.
    config
        Training options; :class:`TrainingConfig` defaults when None.

    Returns
    -------
    Surrogate
        The trained model (on CPU) with its scalers, history and validation metrics.
    """
    config = config or TrainingConfig()
    x = spec.check_parameters(parameters, "training parameters")
    y = spec.check_backbones(backbones, "training backbones")
    if x.shape[0] != y.shape[0]:
        raise ValueError(f"{x.shape[0]} parameter vectors but {y.shape[0]} backbones")
    spec.require_in_box(x, "training parameters", hint="; widen the spec's bounds")
    n_validation = max(1, round(config.validation_fraction * len(x)))
    if len(x) - n_validation < 2:
        raise ValueError(f"{len(x)} curves are too few to train and validate on")
    device = torch.device(config.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    if config.threads is not None:
        # These nets are small: extra CPU threads only add synchronisation, and
        # on a busy machine OpenMP's spinning threads slow training tenfold.
        torch.set_num_threads(config.threads)
    start = time.perf_counter()

    rng = np.random.default_rng(config.seed)
    order = rng.permutation(len(x))
    valid, train = order[:n_validation], order[n_validation:]
    offset, scale = output_scaling(y[train], config.output_scaling)

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        autoencoder = Autoencoder(spec.n_levels, spec.n_channels, config.net)
        regressor = LatentRegressor(spec.n_params, config.net)
    model = PhysicalSurrogate(regressor, autoencoder.decoder, spec.bounds, offset, scale)
    model.to(device)
    autoencoder.to(device)

    unit_x = torch.as_tensor(
        (x - spec.bounds[:, 0]) / np.ptp(spec.bounds, axis=1), dtype=torch.float32, device=device
    )
    scaled_y = torch.as_tensor((y - offset) / scale, dtype=torch.float32, device=device)
    shuffle = torch.Generator().manual_seed(config.seed)
    stage = _StageRunner(config, shuffle, train, valid)

    history = {
        "autoencoder": stage.run(
            "autoencoder", autoencoder, scaled_y, scaled_y, config.learning_rate, config.max_epochs
        )
    }
    with torch.no_grad():
        autoencoder.eval()
        latents = autoencoder.encoder(scaled_y)
    history["ffnn"] = stage.run(
        "ffnn", regressor, unit_x, latents, config.learning_rate, config.max_epochs
    )
    if config.finetune_epochs:
        history["finetune"] = stage.run(
            "finetune",
            model,
            unit_x,
            scaled_y,
            config.finetune_learning_rate,
            config.finetune_epochs,
            forward=model.scaled_backbones,  # FFNN + decoder, in the scaled space
        )

    model.cpu().eval()
    autoencoder.cpu().eval()
    surrogate = Surrogate(
        spec, model, autoencoder, config, history, {}, len(train), n_validation, 0.0
    )
    surrogate.metrics = backbone_metrics(surrogate.predict(x[valid]), y[valid], spec)
    surrogate.train_seconds = time.perf_counter() - start
    return surrogate


@dataclass
class _StageRunner:
    """Mini-batch Adam with early stopping, shared by the three stages."""

    config: TrainingConfig
    shuffle: torch.Generator
    train: np.ndarray
    valid: np.ndarray

    def run(
        self,
        name: str,
        module: nn.Module,
        inputs: torch.Tensor,
        targets: torch.Tensor,
        learning_rate: float,
        max_epochs: int,
        forward: Callable[[torch.Tensor], torch.Tensor] | None = None,
    ) -> list[dict[str, float]]:
        """Train ``module``'s parameters on ``forward(inputs) ≈ targets`` (forward: the module)."""
        forward = forward or module
        device = inputs.device
        train = torch.as_tensor(self.train, device=device)
        x_valid = inputs[torch.as_tensor(self.valid, device=device)]
        y_valid = targets[torch.as_tensor(self.valid, device=device)]
        optimizer = torch.optim.Adam(module.parameters(), lr=learning_rate)
        scheduler = None
        if self.config.lr_decay_patience is not None:
            scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
                optimizer,
                factor=self.config.lr_decay_factor,
                patience=self.config.lr_decay_patience,
                min_lr=1e-2 * learning_rate,
            )
        loss_fn = nn.functional.mse_loss
        best_loss, best_state, since_best = math.inf, None, 0
        history: list[dict[str, float]] = []
        bar = tqdm(range(max_epochs), desc=name, disable=not self.config.progress, leave=False)
        for epoch in bar:
            module.train()
            permutation = train[torch.randperm(train.numel(), generator=self.shuffle).to(device)]
            total = 0.0
            for batch in permutation.split(self.config.batch_size):
                optimizer.zero_grad(set_to_none=True)
                loss = loss_fn(forward(inputs[batch]), targets[batch])
                loss.backward()
                optimizer.step()
                total += loss.item() * batch.numel()
            module.eval()
            with torch.no_grad():
                predicted = forward(x_valid)
                val_loss = loss_fn(predicted, y_valid).item()
                val_pearson = _pearson(predicted, y_valid)
            record = {
                "epoch": epoch,
                "loss": total / train.numel(),
                "val_loss": val_loss,
                "val_pearson": val_pearson,
                "learning_rate": optimizer.param_groups[0]["lr"],
            }
            if scheduler is not None:
                scheduler.step(val_loss)
            history.append(record)
            bar.set_postfix(
                loss=f"{record['loss']:.3g}", val=f"{val_loss:.3g}", r=f"{val_pearson:.5f}"
            )
            if val_loss < best_loss:
                best_loss, since_best = val_loss, 0
                best_state = copy.deepcopy(module.state_dict())
            else:
                since_best += 1
                if since_best >= self.config.patience:
                    break
        bar.close()
        module.load_state_dict(best_state)
        module.eval()
        return history


def _pearson(predicted: torch.Tensor, target: torch.Tensor) -> float:
    a, b = predicted.flatten(), target.flatten()
    a, b = a - a.mean(), b - b.mean()
    return float((a @ b) / (a.norm() * b.norm()).clamp_min(1e-30))
