"""Updating an N-mode :class:`~identification.multimode.ModalModel` on per-mode backbones.

The one-mode models of :mod:`pm_joint.inference.models`, mode by mode: each mode's
measured backbones (its frequency and damping ratio against its amplitude, the
``--modes N`` tables of ``pm-joint backbones``) are scored against that mode's
phase-resonant backbone from the N-mode equations held at it
(:mod:`pm_joint.forward.modal_harmonic`, ``mode=m``), every mode's on the same
parameter vector θ: as the differentiable graph for the hierarchical model and gradient
samplers (:class:`~pm_joint.forward.modal_harmonic.ModalHarmonicGraph`), as the recorded
program that compiles in seconds for population matching's Metropolis-type samplers
(:class:`~pm_joint.forward.modal_op.ModalHarmonicOp`, the same values).

:func:`build_modal_model`
    Population matching: uniform priors on θ and, per mode m, the
    backbone-amplitude potential ``backbone_mode{m}`` of that mode's measured
    population (:func:`~pm_joint.distributions.BackboneAmplitude`, a density fitted
    to that mode's curves at its own levels). The modes' densities are taken as
    independent: an assembly's scatter in one mode is not carried to the other.
:func:`modal_hierarchical_model`
    The hierarchical model: one θ per assembly (the curves of one record's modes
    share it: ``NAME mode 1``, ``NAME mode 2`` are assembly ``NAME``), drawn from
    the population distribution of :func:`~pm_joint.inference.models.hierarchical_model`;
    every mode's points at its amplitude levels are Normal around that mode's graph,
    each mode with its own noise per channel.

What is updated (:func:`modal_update_names`): each mode's linear frequency and
damping ratio and the joint elements' coefficients. Not the mode-shape entries
(the modal filter fixed them: the backbones are read through them), not the
participation factors (a phase-resonant backbone sees Γ·A only: they scale the
excitation, not the backbone) and not the polynomial couplings (the identification
selected them on the records' harmonics, which a backbone of frequency and damping
hardly sees; they stay at the template's values).
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd
import pymc as pm
import pytensor.tensor as pt

from identification.measurements.backbone import BackboneSet
from identification.multimode.model import ModalModel
from pm_joint.distributions import BackboneAmplitude, BackboneDensity, amplitude_levels
from pm_joint.forward import BACKBONE_COLUMNS, forward_model, modal_backbone_graph
from pm_joint.forward.modal_harmonic import ModalHarmonicGraph, template_values
from pm_joint.forward.modal_op import ModalHarmonicOp, Unrecordable
from pm_joint.inference.models import (
    HIERARCHICAL,
    POPULATION_MATCHING,
    check_varying,
    curve_points,
    observe_channel,
    population_theta,
    uniform_priors,
)

__all__ = [
    "MODAL_FORWARD",
    "build_modal_model",
    "modal_bounds",
    "modal_hierarchical_model",
    "modal_update_names",
    "posterior_mode",
    "read_mode_backbones",
]

#: The forward model of an N-mode updating (its name in the sampler table and the metadata).
MODAL_FORWARD = "modal_harmonic"
#: Relative half-width of the default prior box of a mode's linear frequency: a few
#: assembly scatters, well inside the gap to an internal resonance (1:2 at 3 % on the rig).
FREQUENCY_SPREAD = 0.02
#: Factor of the default prior box of a damping ratio, each side (a decay's damping is
#: known to within a factor, not a per cent).
DAMPING_FACTOR = 3.0
#: Relative half-width of the default prior box of a joint element's coefficient, as for
#: one mode (:data:`pm_joint.inference.models.DEFAULT_RELATIVE_SPREAD`).
ELEMENT_SPREAD = 0.5
#: Default number of amplitude levels per mode of the hierarchical model.
HIERARCHICAL_LEVELS = 12
_MODE_LABEL = re.compile(r"^(?P<assembly>.*) mode (?P<mode>\d+)$")


def read_mode_backbones(source: str | Path | pd.DataFrame) -> dict[int, BackboneSet]:
    """Each mode's measured backbones from a ``--modes N`` table (mode → BackboneSet).

    Both tables of ``pm-joint backbones --modes N`` are read: PLL holds (rows of a mode
    that the record did not lock carry no frequency and are left out) and free decays
    (curves ``NAME mode m``). A mode without a measured backbone is left out.

    Raises
    ------
    ValueError
        A table without a ``mode`` column (a one-mode table), or with no backbone of any mode.
    """
    table = source if isinstance(source, pd.DataFrame) else pd.read_csv(source)
    where = "table" if isinstance(source, pd.DataFrame) else str(source)
    if "mode" not in table.columns:
        raise ValueError(
            f"{where} has no 'mode' column: a one-mode backbone table (pm-joint backbones "
            "--modes N writes per-mode backbones)"
        )
    measured = {}
    for mode in sorted(int(m) for m in table["mode"].dropna().unique()):
        rows = table[(table["mode"] == mode) & table["frequency_hz"].notna()]
        if rows.empty:
            continue
        rows = rows.drop(columns=[c for c in ("mode", "hold") if c in rows.columns])
        measured[mode] = BackboneSet.from_table(rows, source=where)
    if not measured:
        raise ValueError(f"{where}: no mode has a measured backbone (no frequency in any row)")
    return measured


def modal_update_names(model: ModalModel) -> list[str]:
    """The parameters updated by default: each mode's frequency and damping ratio, then the
    joint elements' coefficients (see the module notes for what is held)."""
    names = []
    for m in range(1, model.n_modes + 1):
        names += [f"mode{m}.frequency_hz", f"mode{m}.damping_ratio"]
    return names + [e.label for e in model.elements]


def modal_bounds(
    model: ModalModel, names: Sequence[str], measured: Mapping[int, BackboneSet] | None = None
) -> dict[str, tuple[float, float]]:
    """The default uniform prior box: frequencies ±:data:`FREQUENCY_SPREAD`, damping ratios
    within a factor :data:`DAMPING_FACTOR`, other parameters ±:data:`ELEMENT_SPREAD`.

    With ``measured`` (each mode's backbones) a mode's damping-ratio box also takes in the
    damping ratios measured on that mode: an identification can give part of a mode's
    decay to other terms (couplings, joint elements) and its linear damping ratio be off by
    more than the factor, which the backbones, read at small amplitude, show.
    """
    template = template_values(model)
    bounds = {}
    for name in names:
        if name not in template:
            raise ValueError(f"unknown parameter {name!r}; the model has {list(template)}")
        value = template[name]
        if name.endswith(".frequency_hz"):
            spread = (1 - FREQUENCY_SPREAD, 1 + FREQUENCY_SPREAD)
        elif name.endswith(".damping_ratio"):
            spread = (1 / DAMPING_FACTOR, DAMPING_FACTOR)
        else:
            spread = (1 - ELEMENT_SPREAD, 1 + ELEMENT_SPREAD)
        if value == 0:
            raise ValueError(f"parameter {name!r} is 0 in the template: give its bounds")
        low, high = sorted(value * s for s in spread)
        bounds[name] = (float(low), float(high))
    for m, backbones in (measured or {}).items():
        name = f"mode{m}.damping_ratio"
        ratios = np.concatenate([b.damping_ratio for b in backbones])
        ratios = ratios[np.isfinite(ratios) & (ratios > 0)]
        if name in bounds and ratios.size:
            low, high = bounds[name]
            bounds[name] = (min(low, float(ratios.min())), max(high, float(ratios.max())))
    return bounds


def _checked_modes(model: ModalModel, measured: Mapping[int, BackboneSet]) -> list[int]:
    modes = sorted(measured)
    if not modes:
        raise ValueError("no measured backbones of any mode")
    wrong = [m for m in modes if not 1 <= m <= model.n_modes]
    if wrong:
        raise ValueError(f"backbones of mode(s) {wrong}, but the model has {model.n_modes} modes")
    return modes


def build_modal_model(
    model: ModalModel,
    measured: Mapping[int, BackboneSet],
    *,
    names: Sequence[str] | None = None,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    family: str = "copula",
    densities: Mapping[int, BackboneDensity] | None = None,
    n_grid: int = 41,
    native_graph: bool = False,
) -> pm.Model:
    """Population matching of an N-mode model, one backbone-amplitude potential per mode.

    Parameters
    ----------
    model
        Template ModalModel (the structure, and the values of parameters not updated).
    measured
        Each mode's measured backbones, by mode number from 1 (:func:`read_mode_backbones`).
    names
        Parameters to update (default :func:`modal_update_names`).
    bounds
        Uniform prior bounds (default :func:`modal_bounds` with the measured backbones).
    channels, family
        Of each mode's density (:meth:`BackboneDensity.fit
        <pm_joint.distributions.BackboneDensity.fit>`). Both channels by default: the
        damping ratios are updated, and only the damping channel informs them.
    densities
        Each mode's fitted density (then its levels, channels and family are used).
    n_grid
        Amplitude points of each mode's graph (the levels are added to them).
    native_graph
        Each mode's backbone as the differentiable graph
        (:class:`~pm_joint.forward.modal_harmonic.ModalHarmonicGraph`, for a gradient
        sampler); else as :class:`~pm_joint.forward.modal_op.ModalHarmonicOp`, the same
        values without a gradient, compiled in seconds instead of the graph's minutes (the
        graph still where the model has an element the Op cannot record).

    Returns
    -------
    pm.Model
        With the potentials ``backbone_mode{m}`` (predictions ``backbone_mode{m}_predicted``)
        and the attributes ``forward_ops`` and ``backbone_densities`` (by mode),
        ``population_model`` and ``modal_model``.
    """
    modes = _checked_modes(model, measured)
    names = list(names or modal_update_names(model))
    bounds = dict(bounds or modal_bounds(model, names, measured))
    missing = [n for n in names if n not in bounds]
    if missing:
        raise ValueError(f"no prior bounds for {missing}")
    bounds = {n: bounds[n] for n in names}
    densities = dict(densities or {})
    ops = {}
    for m in modes:
        if m not in densities:
            densities[m] = BackboneDensity.fit(
                measured[m], amplitude_levels(measured[m]), channels=channels, family=family
            )
        low, high = measured[m].common_range()
        levels = densities[m].amplitudes_m
        grid = np.union1d(np.linspace(0.5 * low, 1.2 * high, n_grid), levels)
        # The Op on the levels and the grid's first point (the interpolation gives NaN at its
        # first node): the potential reads the levels only, each point's value its own.
        ops[m] = _mode_forward(model, names, grid, [grid[0], *levels], m, native_graph)
    # No evaluation at the centre of the box before sampling, as build_model makes: the
    # graph's loop (where it is used) compiles for minutes, and a prediction that misses
    # the levels is a -inf at PyMC's first evaluation of the sampler's start, which says so.
    with pm.Model() as pm_model:
        theta = uniform_priors(bounds)
        for m in modes:
            BackboneAmplitude(
                f"backbone_mode{m}", ops[m](theta), observed=measured[m], density=densities[m]
            )
    pm_model.forward_ops = ops
    pm_model.backbone_densities = densities
    pm_model.population_model = POPULATION_MATCHING
    pm_model.modal_model = model
    return pm_model


def _mode_forward(
    model: ModalModel,
    names: Sequence[str],
    grid: np.ndarray,
    points: Sequence[float],
    mode: int,
    native_graph: bool,
) -> ModalHarmonicOp | ModalHarmonicGraph:
    """Mode ``mode``'s backbone: the Op on ``points`` unless the graph is asked for or needed;
    the graph on ``grid``."""
    if not native_graph:
        try:
            return ModalHarmonicOp(model, names, points, mode)
        except Unrecordable:
            pass  # an element with a special function: the graph, compiled as it is
    return forward_model(MODAL_FORWARD, model, names, amplitudes_m=grid, mode=mode)


def posterior_mode(pm_model: pm.Model) -> dict[str, np.ndarray] | None:
    """Where population matching's chains start: the posterior's mode, by Powell's method (no
    gradient) from the template's values; None where the template scores −inf.

    The population-matching posterior of an N-mode model is narrow against its prior box
    (each mode's density is fitted to few curves) and cut by the points where the N-mode
    graph does not settle (−inf): a chain started at the box's centre may walk to it for
    longer than its tuning. From its mode, the chains' agreement (r̂) judges the mixing.
    """
    template = template_values(pm_model.modal_model)
    start = {rv.name: np.asarray(template[rv.name]) for rv in pm_model.free_RVs}
    try:
        with pm_model:
            found = pm.find_MAP(start=start, method="Powell", progressbar=False)
    except pm.exceptions.SamplingError:
        return None
    return {rv.name: np.asarray(found[rv.name]) for rv in pm_model.free_RVs}


def assembly_labels(measured: Mapping[int, BackboneSet]) -> tuple[list[str], dict[int, np.ndarray]]:
    """The assemblies of per-mode curves (``NAME mode m`` is assembly ``NAME``; a curve
    without that suffix, a record that locked one mode, is an assembly of its own) and,
    per mode, the assembly index of each of its curves."""
    assemblies: list[str] = []
    index = {}
    for m in sorted(measured):
        rows = []
        for label in measured[m].labels:
            match = _MODE_LABEL.match(label)
            name = match["assembly"] if match and int(match["mode"]) == m else label
            if name not in assemblies:
                assemblies.append(name)
            rows.append(assemblies.index(name))
        index[m] = np.array(rows, dtype=int)
    return assemblies, index


class _ModePoints(NamedTuple):
    """One mode's points in the hierarchical model: its amplitude levels ``grid``, and per
    point the assembly, the level's index, the amplitude (m) and each channel's value."""

    mode: int
    grid: np.ndarray
    assembly: np.ndarray
    level: np.ndarray
    amplitude: np.ndarray
    values: dict[str, np.ndarray]

    @classmethod
    def read(
        cls, measured: BackboneSet, mode: int, owner: np.ndarray, n_levels: int
    ) -> _ModePoints:
        """The curves of ``mode`` (their assemblies ``owner``) at ``n_levels`` amplitudes
        spaced geometrically over the mode's measured range."""
        low = min(b.amplitude_range_m[0] for b in measured)
        high = max(b.amplitude_range_m[1] for b in measured)
        grid = np.geomspace(low, high, n_levels)
        curve, amplitude, values = curve_points(measured, grid)
        level = np.clip(np.searchsorted(grid, amplitude), 0, grid.size - 1)
        return cls(mode, grid, owner[curve], level, amplitude, values)


def modal_hierarchical_model(
    model: ModalModel,
    measured: Mapping[int, BackboneSet],
    names: Sequence[str] | None = None,
    *,
    n_levels: int = HIERARCHICAL_LEVELS,
    location_scale: float = 0.5,
    population_scale: float = 0.2,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    heteroscedastic: bool = True,
    relative_noise: Sequence[str] = ("damping_ratio",),
    centred: bool | Sequence[bool] = True,
) -> pm.Model:
    """Per-assembly parameters of an N-mode model from a population distribution.

    The population part is :func:`~pm_joint.inference.models.hierarchical_model`'s
    (``θ = θ0 exp(η)``, ``log_mean``, ``log_spread``, ``theta`` per assembly,
    ``{name}_population``), over the assemblies of :func:`assembly_labels`. Each mode's
    curves are read at ``n_levels`` amplitudes spaced geometrically over that mode's
    measured range (a curve at the levels inside its own range), and every point is
    Normal around its assembly's graph held at that mode, with the noise of
    :func:`~pm_joint.inference.models.observe_channel` per mode (dims ``group``, one per
    mode). No truncation correction: the N-mode graph is a single-harmonic balance of
    the joint elements with first-order couplings, its own approximation (see
    :mod:`pm_joint.forward.modal_harmonic`). The data ``curve_index`` (assembly) and
    ``mode_index`` (from 0) say whose each point is.
    """
    modes = _checked_modes(model, measured)
    names = list(names or modal_update_names(model))
    template = template_values(model)
    check_varying(template, names, channels)
    assemblies, owner = assembly_labels(measured)
    parts = [_ModePoints.read(measured[m], m, owner[m], n_levels) for m in modes]
    assembly = np.concatenate([p.assembly for p in parts])
    group = np.concatenate([np.full(p.amplitude.size, g) for g, p in enumerate(parts)])
    amplitude = np.concatenate([p.amplitude for p in parts])
    values = {c: np.concatenate([p.values[c] for p in parts]) for c in channels}
    theta0 = np.array([template[n] for n in names])
    centred = np.broadcast_to(np.asarray(centred, dtype=bool), (len(names),))
    # Relative to each mode's own geometric-mean amplitude: the slope of a mode's noise.
    log_relative_amplitude = np.log(amplitude)
    for g in range(len(modes)):
        log_relative_amplitude[group == g] -= np.mean(np.log(amplitude[group == g]))
    coords = {"curve": assemblies, "parameter": names, "point": np.arange(amplitude.size),
              "group": [f"mode {m}" for m in modes]}  # fmt: skip
    with pm.Model(coords=coords) as pm_model:
        theta = population_theta(theta0, names, location_scale, population_scale, centred)
        predicted = {c: [] for c in channels}
        for part in parts:
            # Every assembly on the mode's levels, then each point picked from its own.
            tensors = modal_backbone_graph(model, theta, names, part.grid, mode=part.mode)
            for c in channels:
                column = tensors.backbone[..., BACKBONE_COLUMNS.index(c)]
                predicted[c].append(column[part.assembly, part.level])
        pm.Data("amplitude_m", amplitude, dims="point")
        pm.Data("curve_index", assembly, dims="point")
        pm.Data("mode_index", group, dims="point")
        for c in channels:
            observe_channel(
                c, pt.concatenate(predicted[c]), values[c], np.zeros(amplitude.size),
                log_relative_amplitude, heteroscedastic=heteroscedastic,
                relative=c in relative_noise, groups=group,
            )  # fmt: skip
    pm_model.population_model = HIERARCHICAL
    pm_model.modal_model = model
    pm_model.varying = names
    pm_model.centred = [n for n, c in zip(names, centred, strict=True) if c]
    pm_model.hierarchical_options = json.dumps(
        {"relative_noise": [c for c in channels if c in relative_noise], "truncation": None,
         "centred": pm_model.centred, "modes": modes, "levels": n_levels}
    )  # fmt: skip
    return pm_model
