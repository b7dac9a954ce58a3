"""Updating an N-mode :class:`~identification.multimode.ModalModel` on per-mode backbones.

The one-mode models of :mod:`pm_joint.inference.models`, mode by mode: each mode's
measured backbones (its frequency and damping ratio against its amplitude, the
``--modes N`` tables of ``pm-joint backbones``) are scored against that mode's
phase-resonant backbone from the N-mode equations held at it
(:mod:`pm_joint.forward.modal_harmonic`, ``mode=m``), every mode's on the same
parameter vector θ: as the differentiable graph for the hierarchical model and gradient
samplers (:class:`~pm_joint.forward.modal_harmonic.ModalHarmonicGraph`), as the recorded
program that compiles in seconds for population matching's Metropolis-type samplers
(:class:`~pm_joint.forward.modal_op.ModalHarmonicOp`, the same values) — or, given an
N-mode surrogate (:class:`surrogates.modal.ModalSurrogate`, ``pm-joint train-surrogate``
with a ModalModel), each mode's trained network: its ONNX Op (population matching) or its
network as a pytensor graph (the hierarchical model, gradient samplers), as the one-mode
updating runs on a surrogate.

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
import math
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
import pymc as pm
import pytensor.tensor as pt

from identification.measurements.backbone import BackboneSet
from identification.multimode.model import ModalModel
from pm_joint.distributions import BackboneAmplitude, BackboneDensity, amplitude_levels
from pm_joint.forward import BACKBONE_COLUMNS, SurrogateGraph, forward_model, modal_backbone_graph
from pm_joint.forward.modal_harmonic import ModalHarmonicGraph, template_values
from pm_joint.forward.modal_op import ModalHarmonicOp, Unrecordable
from pm_joint.inference.models import (
    HIERARCHICAL,
    POPULATION_MATCHING,
    amplitudes_within_surrogate,
    check_varying,
    curve_points,
    observe_channel,
    population_draws,
    population_values,
    surrogate_bounds,
    uniform_priors,
)
from surrogates.modal import ModalSurrogate
from surrogates.runtime import SurrogateRuntime

__all__ = [
    "MODAL_FORWARD",
    "MODAL_SURROGATE_FORWARD",
    "build_modal_model",
    "draws_outside_box",
    "hierarchical_scales",
    "modal_bounds",
    "modal_hierarchical_model",
    "modal_update_names",
    "posterior_mode",
    "read_mode_backbones",
]

#: The forward model of an N-mode updating (its name in the sampler table and the metadata).
MODAL_FORWARD = "modal_harmonic"
#: The forward model of an N-mode updating on its surrogate.
MODAL_SURROGATE_FORWARD = "modal_surrogate"
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


def _checked_modes(
    model: ModalModel, measured: Mapping[int, BackboneSet], surrogate: ModalSurrogate | None
) -> list[int]:
    """The measured modes, checked against the model and the surrogate (if any)."""
    modes = sorted(measured)
    if not modes:
        raise ValueError("no measured backbones of any mode")
    wrong = [m for m in modes if not 1 <= m <= model.n_modes]
    if wrong:
        raise ValueError(f"backbones of mode(s) {wrong}, but the model has {model.n_modes} modes")
    if surrogate is not None:
        surrogate.check_model(model.content_sha256)
        untrained = [m for m in modes if m not in surrogate.runtimes]
        if untrained:
            raise ValueError(
                f"the surrogate {surrogate.source} has no network of mode(s) {untrained}, "
                f"which the campaign measured; it has modes {surrogate.modes}"
            )
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
    surrogate: ModalSurrogate | None = None,
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
    surrogate
        Each mode's backbone from its surrogate instead (trained for ``model``): the
        priors are its training box (or ``bounds``, inside it), each mode's levels those
        its grid covers (:func:`~pm_joint.inference.models.amplitudes_within_surrogate`),
        and its mask channel the probability that a backbone point exists, as for one mode.

    Returns
    -------
    pm.Model
        With the potentials ``backbone_mode{m}`` (predictions ``backbone_mode{m}_predicted``)
        and the attributes ``forward_ops`` and ``backbone_densities`` (by mode),
        ``population_model`` and ``modal_model``.
    """
    modes = _checked_modes(model, measured, surrogate)
    names = list(names or modal_update_names(model))
    if surrogate is not None:
        bounds = surrogate_bounds(surrogate.runtimes[modes[0]], names, bounds)
    bounds = dict(bounds or modal_bounds(model, names, measured))
    missing = [n for n in names if n not in bounds]
    if missing:
        raise ValueError(f"no prior bounds for {missing}")
    bounds = {n: bounds[n] for n in names}
    densities = dict(densities or {})
    ops = {}
    for m in modes:
        if m not in densities:
            levels = (
                amplitude_levels(measured[m])
                if surrogate is None
                else amplitudes_within_surrogate(measured[m], surrogate.runtimes[m])
            )
            densities[m] = BackboneDensity.fit(
                measured[m], levels, channels=channels, family=family
            )
        if surrogate is not None:
            ops[m] = forward_model(
                "surrogate", None, names, surrogate=surrogate.runtimes[m], native_graph=native_graph
            )
            continue
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
            # A surrogate says where the model has no backbone: a probability, as for one mode.
            mask = ops[m].has_backbone(theta) if surrogate is not None else None
            BackboneAmplitude(
                f"backbone_mode{m}", ops[m](theta), observed=measured[m], density=densities[m],
                has_backbone=mask,
            )  # fmt: skip
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
        cls,
        measured: BackboneSet,
        mode: int,
        owner: np.ndarray,
        n_levels: int,
        within_m: tuple[float, float] = (0.0, np.inf),
    ) -> _ModePoints:
        """The curves of ``mode`` (their assemblies ``owner``) at ``n_levels`` amplitudes
        spaced geometrically over the mode's measured range (its part ``within_m``)."""
        low = max(min(b.amplitude_range_m[0] for b in measured), within_m[0])
        high = min(max(b.amplitude_range_m[1] for b in measured), within_m[1])
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
    location_scale: float | Sequence[float] | None = None,
    population_scale: float | Sequence[float] | None = None,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    heteroscedastic: bool = True,
    relative_noise: Sequence[str] = ("damping_ratio",),
    centred: bool | Sequence[bool] = True,
    surrogate: ModalSurrogate | None = None,
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

    The priors' scales are per parameter (:func:`hierarchical_scales`, by default): a
    modal frequency is known to a few per cent, not the one-mode model's factor e^0.5,
    and a sampler that starts a frequency 60 % off (nutpie's jitter of ±1 on η) lands
    beyond an internal resonance, where the backbone folds or the network extrapolates:
    chains that never meet (r̂ 3 on the demo case's decays). The population is sampled
    in units of those scales (:func:`_scaled_population_theta`), so a start jittered by ±1
    moves a frequency by its prior scale.

    With ``surrogate`` each mode's graph is its surrogate's network in pytensor
    (:class:`~pm_joint.forward.SurrogateGraph`, compiled in seconds where the N-mode
    balance's loop takes minutes), linear in amplitude between its grid points, and the
    mode's levels lie inside its grid. Its training box keeps every assembly's parameters
    by a smooth wall (:func:`_training_box_wall`); :func:`draws_outside_box` counts the
    draws beyond it.
    """
    modes = _checked_modes(model, measured, surrogate)
    names = list(names or modal_update_names(model))
    template = template_values(model)
    check_varying(template, names, channels)
    assemblies, owner = assembly_labels(measured)
    runtimes = surrogate.runtimes if surrogate is not None else {}
    parts = [
        _ModePoints.read(measured[m], m, owner[m], n_levels, _grid_range(runtimes.get(m)))
        for m in modes
    ]
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
        location, population = hierarchical_scales(names)
        if location_scale is not None:
            location = np.broadcast_to(location_scale, len(names))
        if population_scale is not None:
            population = np.broadcast_to(population_scale, len(names))
        theta = _scaled_population_theta(theta0, names, location, population, centred)
        if surrogate is not None:
            _training_box_wall(theta, names, surrogate)
        predicted = {c: [] for c in channels}
        for part in parts:
            # Every assembly on the mode's levels, then each point picked from its own.
            backbone = _mode_graph(model, theta, names, part, runtimes.get(part.mode))
            for c in channels:
                column = backbone[..., BACKBONE_COLUMNS.index(c)]
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
         "centred": pm_model.centred, "modes": modes, "levels": n_levels,
         "forward": MODAL_FORWARD if surrogate is None else MODAL_SURROGATE_FORWARD}
    )  # fmt: skip
    pm_model.surrogate = surrogate
    return pm_model


#: Width of the surrogate's training-box wall, as a share of each parameter's box.
WALL_WIDTH = 0.01


def _training_box_wall(
    theta: pt.TensorVariable, names: Sequence[str], surrogate: ModalSurrogate
) -> None:
    """A potential that keeps every assembly's parameters in the surrogate's training box:
    0 inside, ``−½ (d / w)²`` at a distance ``d`` beyond it (``w`` :data:`WALL_WIDTH` of the
    box). A network's values beyond its box are extrapolation, not the model: without the
    wall the demo case's chains took the joint element to a sixth of the template's, where
    only the network's extrapolation fitted, and the N-mode balance does not. A smooth wall,
    not a hard bound, so that NUTS's trajectories that touch it turn back rather than
    diverge."""
    box = surrogate.box(list(names))
    width = WALL_WIDTH * (box[:, 1] - box[:, 0])
    beyond = pt.maximum(box[:, 0] - theta, 0) + pt.maximum(theta - box[:, 1], 0)
    pm.Potential("training_box_wall", -0.5 * pt.sum((beyond / width) ** 2))


def _scaled_population_theta(
    theta0: np.ndarray,
    names: Sequence[str],
    location: np.ndarray,
    population: np.ndarray,
    centred: np.ndarray,
) -> pt.TensorVariable:
    """:func:`~pm_joint.inference.models.population_theta`'s population, sampled in units of
    each parameter's prior scale: ``μ = s μ̃`` (``log_mean_std`` μ̃ standard normal),
    ``σ = p σ̃`` (``log_spread_std`` σ̃ half-normal), ``η = s η̃`` with ``η̃`` drawn from
    ``N(μ̃, (p/s) σ̃)`` by :func:`~pm_joint.inference.models.population_draws`; ``log_mean``,
    ``log_spread``, ``theta`` and ``{name}_population`` are its deterministics. The same
    distribution; a sampler's start jittered by ±1 in these units moves a frequency by its
    prior scale, not by 60 %."""
    mu_std = pm.Normal("log_mean_std", 0.0, 1.0, dims="parameter")
    sigma_std = pm.HalfNormal("log_spread_std", 1.0, dims="parameter")
    mu = pm.Deterministic("log_mean", location * mu_std, dims="parameter")
    pm.Deterministic("log_spread", population * sigma_std, dims="parameter")
    eta = location * population_draws(mu_std, population / location * sigma_std, centred, names)
    return population_values(theta0, names, mu, eta)


def hierarchical_scales(names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Per parameter, the scale of its population log-location's prior and of its
    log-spread's: a modal frequency :data:`FREQUENCY_SPREAD` and half that (assemblies
    scatter a few tenths of a per cent), a damping ratio ``log`` :data:`DAMPING_FACTOR` and
    0.2, a joint element :data:`ELEMENT_SPREAD` and 0.2 (the one-mode model's): the
    prior box of population matching in log units."""
    location, population = [], []
    for name in names:
        if name.endswith(".frequency_hz"):
            location.append(FREQUENCY_SPREAD)
            population.append(FREQUENCY_SPREAD / 2)
        elif name.endswith(".damping_ratio"):
            location.append(math.log(DAMPING_FACTOR))
            population.append(0.2)
        else:
            location.append(ELEMENT_SPREAD)
            population.append(0.2)
    return np.array(location), np.array(population)


def _grid_range(runtime: SurrogateRuntime | None) -> tuple[float, float]:
    """The amplitudes (m) a mode's surrogate covers (all without one)."""
    if runtime is None:
        return 0.0, np.inf
    return float(runtime.amplitudes_m[0]), float(runtime.amplitudes_m[-1])


def _mode_graph(
    model: ModalModel,
    theta: pt.TensorVariable,
    names: Sequence[str],
    part: _ModePoints,
    runtime: SurrogateRuntime | None,
) -> pt.TensorVariable:
    """``(assemblies, levels, 3)``: one mode's backbone of every assembly at its levels."""
    if runtime is None:
        return modal_backbone_graph(model, theta, names, part.grid, mode=part.mode).backbone
    grid = runtime.amplitudes_m
    # Linear in amplitude between the surrogate's grid points, a constant matrix: column j
    # interpolates the j-th unit vector.
    weights = np.stack([np.interp(part.grid, grid, unit) for unit in np.eye(grid.size)], axis=1)
    on_grid = SurrogateGraph(runtime, names)(theta)
    return pt.tensordot(on_grid, weights, axes=[[1], [1]]).transpose(0, 2, 1)


def draws_outside_box(idata: Any, surrogate: ModalSurrogate) -> float:
    """Share of the hierarchical posterior's per-assembly draws outside the surrogate's
    training box (where its network extrapolates)."""
    theta = idata.posterior["theta"]
    low, high = surrogate.box(list(theta["parameter"].values)).T
    values = theta.values
    return float(np.mean(np.any((values < low) | (values > high), axis=-1)))
