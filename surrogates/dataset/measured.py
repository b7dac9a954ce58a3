"""Measured curves in a dataset: their parameter labels and their place on the grid.

The paper trained on 25 measured + 475 analytical curves. :func:`record_labels`
labels each measured record with the parameters of its own fit;
:func:`add_measured` puts each labelled curve on the dataset's grid: on
excitation levels it is interpolated onto the levels when it covers them, else
excluded with the reason; on the amplitude grid it enters where it covers the
grid, with its label's misfit (:mod:`surrogates.labels`) deciding whether and
with what weight.
"""

from __future__ import annotations

import dataclasses
import json
import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.measurements.backbone import BackboneSet
from identification.measurements.records import Record
from identification.model import JointModel
from identification.sindy import identify
from surrogates.dataset.container import _ALL_CHANNELS, MEASURED_PREFIX, BackboneDataset
from surrogates.grid import (
    GRID_CHANNELS,
    GridEvaluation,
    assembly_scatter,
    grid_backbones,
    measured_on_grid,
    point_base_acceleration,
)
from surrogates.labels import MisfitPolicy, label_misfit, misfit_weight
from surrogates.runtime import MASK_CHANNEL


def record_labels(
    records: Sequence[Record], model: JointModel, names: Sequence[str], **options: Any
) -> np.ndarray:
    """Parameters of each record alone: least squares on the model's own terms.

    The paper labels its measured backbones by identifying each record; with
    the model's support fixed (no thresholding) that is a well-posed fit of
    the same parameters, record by record. Shape parameters keep the model's
    values. Returns ``(n_records, len(names))``, rows in the order of ``records``
    (the labels :func:`add_measured` takes). ``options`` go to the identification
    (its preprocessing: ``edge_periods``, ``band_hz``).
    """
    shapes = {t.effect: dict(t.shape) for t in model.terms if t.shape}
    rows = []
    for record in records:
        fitted = identify(record, model.effects, threshold=None, shapes=shapes, **options).model
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


def _measured_on_levels(curve, excitation_m_s2: np.ndarray, level_gain: float | None) -> np.ndarray:
    """``(n_levels, 3)`` amplitude, frequency, damping of a measured curve on the levels."""
    own = point_base_acceleration(curve, level_gain)
    own, inverse = np.unique(own, return_inverse=True)
    counts = np.bincount(inverse)
    points = np.stack([curve.amplitude_m, curve.frequency_hz, curve.damping_ratio], axis=-1)
    points = np.stack([np.bincount(inverse, weights=p) / counts for p in points.T], axis=-1)
    tolerance = 1e-9 * excitation_m_s2[-1]
    if (
        own.size < 2
        or own[0] > excitation_m_s2[0] + tolerance
        or own[-1] < excitation_m_s2[-1] - tolerance
    ):
        raise ValueError(
            f"it covers levels {own[0]:.4g}–{own[-1]:.4g} m/s², the dataset needs "
            f"{excitation_m_s2[0]:.4g}–{excitation_m_s2[-1]:.4g} m/s²"
        )
    return np.stack([np.interp(excitation_m_s2, own, p) for p in points.T], axis=-1)
