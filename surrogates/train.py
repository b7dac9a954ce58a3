"""Training the backbone surrogate: the paper's two-stage scheme plus a joint fine-tune.

1. **Autoencoder** on the scaled backbones (reconstruction loss).
2. **FFNN** from the unit-box parameters to the encoder's latents (latent MSE),
   the encoder frozen.
3. **Fine-tune** (ours, optional): FFNN + decoder end-to-end on the backbone
   loss, at a lower learning rate. Stage 2 only matches latents, and a small
   latent error can be amplified by the decoder; training the composition on
   the quantity that matters removes most of that error.

Scalings: parameters are min–max scaled with the training box (the spec's
bounds) to [0, 1]; what the networks learn (the backbones, or with a head its
residual) is standardised per (grid point, channel) by default, so that an error of
a given share of its spread weighs the same at every grid point, or per channel.
Both are folded into :class:`~surrogates.nets.PhysicalSurrogate`, the module
that is exported.

Loss: a weighted mean over the entries of a batch, ``Σ w·ℓ / Σ w``, with ``ℓ``
the squared error of a value channel, plus ``mask_weight`` times that of the
binary cross-entropy of the amplitude grid's mask channel (a logit inside the
network, a probability at its output). Early stopping follows what each part
leaves of a trivial prediction (the mask by its Brier score, see
``_BackboneLoss``). The weights (:meth:`~surrogates.dataset.BackboneDataset.loss_weights`)
are 0 where a value is masked or was not observed, so neutral targets teach
nothing; without weights every entry weighs 1 (plain MSE).

``head_degree`` (ours, optional): a per-(grid point, channel) polynomial regression on
the parameters (:class:`~surrogates.baselines.PolynomialBaseline`, 1: linear,
3: cubic), fitted to the training rows, is part of the graph and the networks
learn its residual, standardised by the residual's own spread; the autoencoder
then compresses only what the regression misses, at the precision it is missed
with.

``damping_target`` (ours, optional): ``"decay_rate"`` trains the head and the
networks on ``σ = 2π f ζ`` in place of the damping ratio ζ and the exported graph
returns ``ζ = σ / (2π f)`` with its own predicted frequency. ``σ`` is half the
equivalent viscous damping, free of the ``1/ω`` a polynomial in the stiffness
parameters fits poorly over a wide box (figures: ``bench/results/surrogate_wide_*.json``).

Every stage uses Adam (lr 1e-3; 1e-4 for the fine-tune; halved on plateaus),
mini-batches of 32 (Keras' default), a validation split with early stopping
that restores the best weights, and reports the validation Pearson coefficient
per epoch (in the scaled space, weighted entries of the value channels).
:func:`train_on_dataset` takes the splits of a dataset: train, validation for
early stopping, and an independent test split for the reported figures.
Runs are seeded: on CPU the same seed gives the same weights; on GPU cuDNN may
not be bitwise reproducible.
"""

from __future__ import annotations

import copy
import math
import time
import warnings
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Literal

import numpy as np
import torch
from numpy.typing import ArrayLike
from torch import nn
from tqdm.auto import tqdm

from surrogates.baselines import ROWS_PER_COEFFICIENT, PolynomialBaseline
from surrogates.dataset import MEASURED_PREFIX, BackboneDataset
from surrogates.evaluate import accuracy_report, backbone_metrics, channel_errors
from surrogates.nets import (
    Autoencoder,
    LatentRegressor,
    NetConfig,
    PhysicalSurrogate,
    decay_rate_channels,
    network_sizes,
    to_decay_rate,
)
from surrogates.runtime import MASK_CHANNEL, SurrogateSpec

__all__ = [
    "Surrogate",
    "TrainingConfig",
    "output_scaling",
    "stage_config",
    "train_on_dataset",
    "train_surrogate",
]


@dataclass(frozen=True)
class TrainingConfig:
    """How to train; the defaults are the paper's where it says, ours where not.

    ``max_epochs`` bounds the autoencoder and FFNN stages, ``finetune_epochs``
    the fine-tune (``0`` gives the paper's pure two-stage model); early stopping
    ends a stage after ``patience`` epochs without a better validation loss.
    ``lr_decay_patience`` (epochs without improvement) halves the learning rate
    on plateaus, down to 1 % of it (None: the paper's constant rate). The
    defaults (400 + 400 + 200 epochs with the decay) were chosen on the
    trc-like benchmark (``bench/surrogate.py``, results in ``bench/results/``),
    where they match far longer constant-rate training. ``threads`` sets
    torch's CPU threads for the training (None: leave torch's setting).
    ``head_degree`` (0: none, the paper's) adds a per-(grid point, channel) polynomial
    regression of that degree to the graph and trains the networks on its
    residual (see the module docstring).
    ``validation_fraction`` applies when no validation rows are given.
    ``mask_weight`` scales the mask's cross-entropy against the value channels'
    squared error (in the scaled space) in the training loss: with an equal
    weight, on the test box of ``tests/test_surrogate_grid.py``, the mask agreed
    with the harmonic balance's no better than a linear probability.
    ``damping_target`` (``"decay_rate"``: ours): the head and the networks learn
    the damping channel as the decay rate ``σ = 2π f ζ`` and the graph divides by
    its own predicted ``2π f`` (:func:`~surrogates.nets.to_decay_rate`); needs the
    frequency channel beside the damping ratio. ``"ratio"``: ζ as it is (the paper's).
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
    head_degree: int = 0
    mask_weight: float = 4.0
    damping_target: Literal["ratio", "decay_rate"] = "ratio"
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
        if not (math.isfinite(self.mask_weight) and self.mask_weight >= 0):
            raise ValueError(f"mask_weight must be finite and ≥ 0: {self.mask_weight}")
        if self.head_degree not in (0, 1, 2, 3, 4):
            raise ValueError(f"head_degree must be 0 (none), 1, 2, 3 or 4: {self.head_degree}")
        if self.damping_target not in ("ratio", "decay_rate"):
            raise ValueError(
                f"damping_target must be 'ratio' or 'decay_rate': {self.damping_target!r}"
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
        Parameters, box, grid and channels.
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
        Errors on the validation split (the one that stopped training early:
        not an independent figure): :func:`~surrogates.evaluate.backbone_metrics`
        on excitation levels, :func:`~surrogates.evaluate.channel_errors` on the
        amplitude grid.
    n_train, n_validation
        Curves used to fit and to stop early.
    train_seconds
        Wall time of the whole training.
    data
        Where the curves came from (:func:`train_on_dataset`): the dataset's
        hash, its counts per origin and split, and the measured curves that were
        training or validation data (``measured_in_training``); empty when
        trained on bare arrays.
    test_report
        :func:`~surrogates.evaluate.accuracy_report` on the dataset's test split
        (:func:`train_on_dataset`), or None.
    head_carried_degree
        ``(n_levels, n_channels)`` the degree the polynomial head carries at each
        grid point (:attr:`~surrogates.baselines.PolynomialBaseline.carried_degree`;
        lower than ``config.head_degree`` where masked values leave too few
        training rows; 0 in the mask channel, which has no head), or None without a head.
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
    data: dict[str, Any] = field(default_factory=dict)
    test_report: dict[str, Any] | None = None
    head_carried_degree: np.ndarray | None = None

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

    @property
    def sizes(self) -> dict[str, Any]:
        """Layer widths and parameter counts (:func:`~surrogates.nets.network_sizes`)."""
        return network_sizes(self.model, self.autoencoder, self.config.net)


def output_scaling(
    backbones: np.ndarray,
    mode: Literal["level", "channel"] = "level",
    weights: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Offset and scale, each ``(n_levels, n_channels)``, that standardise backbones.

    ``"level"`` standardises every (grid point, channel) over the curves, ``"channel"``
    every channel over curves and grid points, each over the entries with weight > 0
    (all without ``weights``). A spread of zero (a constant entry) or an entry
    without weighted values falls back to the channel's, then to 1, so the
    scaling stays invertible.
    """
    if mode not in ("level", "channel"):
        raise ValueError(f"output scaling must be 'level' or 'channel', got {mode!r}")
    used = np.ones(backbones.shape, bool) if weights is None else np.asarray(weights) > 0
    values = np.where(used, backbones, np.nan)
    with warnings.catch_warnings():  # all-NaN slices are the fallback's business
        warnings.simplefilter("ignore", RuntimeWarning)
        channel_offset = np.nan_to_num(np.nanmean(values, axis=(0, 1)))
        channel_scale = np.nanstd(values, axis=(0, 1))
        if mode == "level":
            offset, scale = np.nanmean(values, axis=0), np.nanstd(values, axis=0)
        else:
            offset = np.broadcast_to(channel_offset, backbones.shape[1:]).copy()
            scale = np.broadcast_to(channel_scale, backbones.shape[1:]).copy()
    fallback = np.where(channel_scale > 0, channel_scale, 1.0)
    tiny = 1e-9 * fallback
    offset = np.where(np.isfinite(offset), offset, channel_offset)
    return offset, np.where(np.isfinite(scale) & (scale > tiny), scale, fallback)


def train_surrogate(
    parameters: np.ndarray,
    backbones: np.ndarray,
    spec: SurrogateSpec,
    config: TrainingConfig | None = None,
    *,
    weights: np.ndarray | None = None,
    validation_index: np.ndarray | None = None,
) -> Surrogate:
    """Train a backbone surrogate on curves.

    Parameters
    ----------
    parameters
        ``(n, n_params)`` physical parameters, inside ``spec.bounds``.
    backbones
        ``(n, n_levels, n_channels)`` backbones on ``spec.grid``, SI units.
    spec
        Names, box, grid and channels of the data.
    config
        Training options; :class:`TrainingConfig` defaults when None.
    weights
        ``(n, n_levels, n_channels)`` loss weight of every entry (0: not a
        target; :meth:`~surrogates.dataset.BackboneDataset.loss_weights`); None:
        all 1. Masked value entries also enter the autoencoder as the neutral
        scaled value 0.
    validation_index
        Rows that stop training early (never fitted); None: a seeded
        ``config.validation_fraction`` of the rows.

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
    w = np.ones(y.shape) if weights is None else np.asarray(weights, dtype=float)
    if w.shape != y.shape or not np.all(np.isfinite(w) & (w >= 0)):
        raise ValueError(f"weights must be finite, ≥ 0 and shaped {y.shape}, got {w.shape}")
    rng = np.random.default_rng(config.seed)
    if validation_index is None:
        n_validation = max(1, round(config.validation_fraction * len(x)))
        order = rng.permutation(len(x))
        valid, train = order[:n_validation], order[n_validation:]
    else:
        valid = np.unique(np.asarray(validation_index, dtype=int))
        if valid.size == 0 or valid.min() < 0 or valid.max() >= len(x):
            raise ValueError(f"validation_index must name rows of the {len(x)} curves")
        train = rng.permutation(np.setdiff1d(np.arange(len(x)), valid))
    if train.size < 2:
        raise ValueError(f"{len(x)} curves are too few to train and validate on")
    device = torch.device(config.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    if config.threads is not None:
        # These nets are small: extra CPU threads only add synchronisation, and
        # on a busy machine OpenMP's spinning threads slow training tenfold.
        torch.set_num_threads(config.threads)
    start = time.perf_counter()

    probability = np.array([c == MASK_CHANNEL for c in spec.channels])
    # What the head and the networks fit: the curves, with the damping as a decay rate
    # when asked (its weights then also need the frequency observed).
    rate = decay_rate_channels(spec.channels) if config.damping_target == "decay_rate" else None
    target, fit_w = (y, w) if rate is None else to_decay_rate(y, w, rate)
    head = None
    if config.head_degree:
        regression = PolynomialBaseline.fit(
            spec, x[train], target[train], fit_w[train], config.head_degree
        )
        regression.coefficients[..., probability] = 0.0  # the mask stays the network's alone
        head = (config.head_degree, regression.coefficients)
        carried = np.where(probability, 0, regression.carried_degree)
        short = (carried[:, ~probability] < config.head_degree).any(axis=1)
        if short.any():
            # A lower degree at a few grid points is a step in accuracy along the curve.
            degree = config.head_degree
            coefficients = math.comb(spec.n_params + degree, degree)
            warnings.warn(
                f"the degree-{degree} head carries a lower degree at {int(short.sum())} of "
                f"{spec.n_levels} grid points (indices {np.flatnonzero(short).tolist()}): "
                f"fewer than {ROWS_PER_COEFFICIENT} × {coefficients} training rows with a "
                "value there; train on more curves",
                stacklevel=2,
            )
    # What the networks learn, standardised: the curves, or the head's residual (taken
    # in float64 here: in the network's float32 it would cancel).
    learnt = target if head is None else target - regression.predict(x)
    offset, scale = output_scaling(learnt[train], config.output_scaling, fit_w[train])
    offset[:, probability], scale[:, probability] = 0.0, 1.0  # the mask: a logit, as it is
    neutral = np.zeros(y.shape, bool)
    if probability.any():
        neutral[..., ~probability] = (y[..., probability] < 0.5).any(axis=-1, keepdims=True)
    scaled = np.where(neutral, 0.0, (learnt - offset) / scale)
    unit = (x - spec.bounds[:, 0]) / np.ptp(spec.bounds, axis=1)

    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(config.seed)
        autoencoder = Autoencoder(spec.n_levels, spec.n_channels, config.net)
        regressor = LatentRegressor(spec.n_params, config.net)
    model = PhysicalSurrogate(
        regressor, autoencoder.decoder, spec.bounds, offset, scale,
        head=head, probability_channels=probability, decay_rate=rate,
    )  # fmt: skip
    model.to(device)
    autoencoder.to(device)

    unit_x = torch.as_tensor(unit, dtype=torch.float32, device=device)
    scaled_y = torch.as_tensor(scaled, dtype=torch.float32, device=device)
    loss_weights = torch.as_tensor(fit_w, dtype=torch.float32, device=device)
    shuffle = torch.Generator().manual_seed(config.seed)
    stage = _StageRunner(config, shuffle, train, valid)
    loss = _BackboneLoss(torch.as_tensor(probability, device=device), config.mask_weight)

    history = {
        "autoencoder": stage.run(
            "autoencoder", autoencoder, scaled_y, scaled_y, config.learning_rate,
            config.max_epochs, loss=loss, weights=loss_weights,
        )
    }  # fmt: skip
    with torch.no_grad():
        autoencoder.eval()
        latents = autoencoder.encoder(scaled_y)
    history["ffnn"] = stage.run(
        "ffnn", regressor, unit_x, latents, config.learning_rate, config.max_epochs
    )
    if config.finetune_epochs:
        history["finetune"] = stage.run(
            "finetune", model, unit_x, scaled_y, config.finetune_learning_rate,
            config.finetune_epochs,
            forward=model.scaled_backbones,  # FFNN + decoder, in the scaled space
            loss=loss, weights=loss_weights,
        )  # fmt: skip

    model.cpu().eval()
    autoencoder.cpu().eval()
    surrogate = Surrogate(
        spec, model, autoencoder, config, history, {}, len(train), len(valid), 0.0,
        head_carried_degree=None if head is None else carried,
    )  # fmt: skip
    predicted = surrogate.predict(x[valid])
    surrogate.metrics = (
        backbone_metrics(predicted, y[valid], spec)
        if spec.representation == "excitation_levels"
        else channel_errors(predicted, y[valid], w[valid], spec)
    )
    surrogate.train_seconds = time.perf_counter() - start
    return surrogate


def stage_config(
    config: TrainingConfig | None, *, seed: int, progress: bool, max_epochs: int | None
) -> TrainingConfig:
    """The training of ``pm-joint train-surrogate``: ``config`` or the stage's default (the
    paper's network on the residual of a cubic head, the damping learnt as a decay rate), with
    the run's seed and progress, and ``max_epochs`` capping every stage."""
    config = config or TrainingConfig(head_degree=3, damping_target="decay_rate")
    config = replace(config, seed=seed, progress=progress)
    if max_epochs is not None:
        config = replace(
            config, max_epochs=max_epochs, patience=max_epochs, finetune_epochs=max_epochs // 2
        )
    return config


def train_on_dataset(
    dataset: BackboneDataset,
    config: TrainingConfig | None = None,
    *,
    scatter: Mapping[str, ArrayLike] | None = None,
) -> Surrogate:
    """Train on a dataset's splits: fit on train, stop early on validation, report on test.

    The dataset needs its splits (:meth:`~surrogates.dataset.BackboneDataset.with_splits`);
    the loss weights are its :meth:`~surrogates.dataset.BackboneDataset.loss_weights`.
    The returned surrogate carries :func:`~surrogates.evaluate.accuracy_report` on
    the test split (with ``scatter``, the assembly standard deviation per grid
    point and channel, for the ratios to it) and, in ``data``, the counts and the
    measured curves that were training or validation data.
    """
    train, valid = dataset.in_split("train"), dataset.in_split("validation")
    if dataset.in_split("test").size == 0:
        raise ValueError("the dataset's test split is empty: no independent figure possible")
    rows = np.concatenate([train, valid])
    surrogate = train_surrogate(
        dataset.X[rows], dataset.Y[rows], dataset.spec, config,
        weights=dataset.loss_weights()[rows],
        validation_index=np.arange(train.size, rows.size),
    )  # fmt: skip
    measured = dataset.is_measured
    misfit_by_channel = dataset.provenance.get("measured", {}).get("label_misfit_by_channel", {})
    surrogate.data = {
        "dataset_sha256": dataset.content_hash,
        "counts": dataset.provenance.get("counts", {}),
        "splits": dataset.split_counts(),
        "measured_in_training": [
            str(o).removeprefix(MEASURED_PREFIX) for o in dataset.origin[rows][measured[rows]]
        ],
        "measured_in_test": [
            str(o).removeprefix(MEASURED_PREFIX)
            for o in dataset.origin[measured & (dataset.partition == "test")]
        ],
        "measured_excluded": dataset.provenance.get("measured", {}).get("excluded", {}),
        # Per measured curve: its split, loss weight and label misfit (assembly SDs) in
        # frequency, which the weight follows.
        "measured_curves": {
            str(o).removeprefix(MEASURED_PREFIX): {
                "split": str(split),
                "weight": float(weight),
                "label_misfit": float(misfit) if math.isfinite(misfit) else None,
            }
            for o, split, weight, misfit in zip(
                dataset.origin[measured],
                dataset.partition[measured],
                dataset.weight[measured],
                dataset.label_misfit[measured],
                strict=True,
            )
        },
        # Every offered curve's label misfit in each value channel (assembly SDs).
        "label_misfit_by_channel": misfit_by_channel,
        # Why the amplitude grid spans what it does (surrogates.grid.measured_grid), if known.
        "grid": dataset.provenance.get("grid"),
    }
    surrogate.test_report = accuracy_report(dataset, surrogate.predict, scatter=scatter)
    return surrogate


class _BackboneLoss:
    """Squared error on value channels plus ``mask_weight`` × BCE on probability channels.

    Each part is a weighted mean over its own entries, ``Σ w·ℓ / Σ w``. Early
    stopping and the learning-rate schedule follow :meth:`monitor`, which adds
    each part's share of what a trivial prediction leaves: the value part over
    the targets' mean square, the mask's Brier score (bounded, unlike the
    cross-entropy of a sharp no-backbone boundary, which keeps rising with the
    logits' confidence while the agreement holds) over the prevalence's ``q(1 − q)``.
    """

    def __init__(self, probability: torch.Tensor, mask_weight: float = 1.0) -> None:
        self.probability, self.mask_weight = probability, mask_weight

    def _values(self, predicted, target, weights) -> torch.Tensor:
        value = ~self.probability
        w = weights[..., value]
        squared = (predicted[..., value] - target[..., value]) ** 2
        return (w * squared).sum() / w.sum().clamp_min(1e-12)

    def __call__(
        self, predicted: torch.Tensor, target: torch.Tensor, weights: torch.Tensor
    ) -> torch.Tensor:
        values = self._values(predicted, target, weights)
        if not self.probability.any():
            return values
        w = weights[..., self.probability]
        bce = nn.functional.binary_cross_entropy_with_logits(
            predicted[..., self.probability], target[..., self.probability].clamp(0.0, 1.0),
            reduction="none",
        )  # fmt: skip
        return values + self.mask_weight * (w * bce).sum() / w.sum().clamp_min(1e-12)

    def monitor(
        self, predicted: torch.Tensor, target: torch.Tensor, weights: torch.Tensor
    ) -> torch.Tensor:
        """Unexplained shares of the value and mask parts, summed (what early stopping follows)."""
        trivial = self._values(torch.zeros_like(target), target, weights).clamp_min(1e-12)
        score = self._values(predicted, target, weights) / trivial
        if not self.probability.any():
            return score
        w = weights[..., self.probability]
        truth = target[..., self.probability].clamp(0.0, 1.0)
        brier = (w * (torch.sigmoid(predicted[..., self.probability]) - truth) ** 2).sum()
        prevalence = (w * truth).sum() / w.sum().clamp_min(1e-12)
        spread = (prevalence * (1 - prevalence)).clamp_min(1e-2)
        return score + brier / w.sum().clamp_min(1e-12) / spread


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
        loss: Callable[..., torch.Tensor] | None = None,
        weights: torch.Tensor | None = None,
    ) -> list[dict[str, float]]:
        """Train ``module``'s parameters on ``forward(inputs) ≈ targets`` (forward: the module).

        ``loss(predicted, target, weights)`` with ``weights`` shaped like the
        targets; default the mean squared error.
        """
        forward = forward or module
        device = inputs.device
        if weights is None:
            weights = torch.ones_like(targets)
        loss_fn = loss or (lambda p, t, w: nn.functional.mse_loss(p, t))
        monitor = loss.monitor if isinstance(loss, _BackboneLoss) else loss_fn
        train = torch.as_tensor(self.train, device=device)
        valid = torch.as_tensor(self.valid, device=device)
        x_valid, y_valid, w_valid = inputs[valid], targets[valid], weights[valid]
        value = (
            ~loss.probability
            if isinstance(loss, _BackboneLoss)
            else torch.ones(targets.shape[-1], dtype=torch.bool, device=device)
        )
        optimizer = torch.optim.Adam(module.parameters(), lr=learning_rate)
        scheduler = None
        if self.config.lr_decay_patience is not None:
            scheduler = torch.optim.lr_scheduler.ReduceLROnPlateau(
                optimizer,
                factor=self.config.lr_decay_factor,
                patience=self.config.lr_decay_patience,
                min_lr=1e-2 * learning_rate,
            )
        best_loss, best_state, since_best = math.inf, None, 0
        history: list[dict[str, float]] = []
        bar = tqdm(range(max_epochs), desc=name, disable=not self.config.progress, leave=False)
        for epoch in bar:
            module.train()
            permutation = train[torch.randperm(train.numel(), generator=self.shuffle).to(device)]
            total = 0.0
            for batch in permutation.split(self.config.batch_size):
                optimizer.zero_grad(set_to_none=True)
                batch_loss = loss_fn(forward(inputs[batch]), targets[batch], weights[batch])
                batch_loss.backward()
                optimizer.step()
                total += batch_loss.item() * batch.numel()
            module.eval()
            with torch.no_grad():
                predicted = forward(x_valid)
                val_loss = monitor(predicted, y_valid, w_valid).item()
                used = (w_valid > 0) & value if predicted.ndim == 3 else w_valid > 0
                val_pearson = _pearson(predicted[used], y_valid[used])
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
