"""Campaign simulators of the studies.

* :func:`rig_campaign` (and :func:`draw_rig_campaign`, the campaign driver's draw of it): a
  rig preset's records — the PLL simulator through the preset's lab conditions, time
  integration with every harmonic — and the backbones extracted from them. The data of
  every validation study.
* :func:`simulated_campaign` (and :func:`draw_lab_campaign`): fast multi-harmonic-balance
  backbones with lab conditions. The criticism predicts with the same harmonic balance, so
  these are unit-level checks of the statistics (fast, the model class exact), never a
  validation study's data.
* :func:`synthetic_campaign` (a population's single-harmonic campaign) and
  :func:`pll_campaign` (the PLL simulator's backbones of a population), for the updating
  studies.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.harmonic import backbone as harmonic_backbone
from identification.analytical.pll import pll_backbones
from identification.effects import LINEAR_STIFFNESS, VISCOUS_DAMPING
from identification.effects.microslip import EFFECT as MICROSLIP
from identification.fitting.fitter import Fitter
from identification.measurements.backbone import Backbone, BackboneSet
from identification.measurements.extraction import extract_backbones
from identification.measurements.records import Record
from identification.model import JointModel
from identification.rig import RIG_PRESETS, rig_for_preset
from independent.campaigns import OUT_OF_CATALOGUE_JOINTS, phase_resonance_campaign

__all__ = [
    "NULL_CONDITIONS",
    "RIG_LEVEL_CHOICES",
    "draw_lab_campaign",
    "draw_rig_campaign",
    "first_fit",
    "independent_out_of_catalogue",
    "lab_conditions",
    "pll_campaign",
    "rig_campaign",
    "simulated_campaign",
    "synthetic_campaign",
]

#: Lab conditions of the null campaigns (options of :func:`simulated_campaign`): levels
#: stepped up and down, a distorting shaker (4 % 2nd, 3 % 3rd harmonic at most), the
#: controller ripple's leak into the hold fits' harmonics (up to 4e-5 of the fundamental:
#: twice the largest 3rd harmonic the hold fit left on ``lab-ripple``).
NULL_CONDITIONS: dict[str, dict[str, Any]] = {
    "up-down": {"up_down": True},
    "distorted": {"shaker_distortion": (0.04, 0.03)},
    "ripple": {"ripple_leak": 2e-5},
}


#: Shape parameters each assembly draws by ``nonlinear_spread`` as it draws the coefficients
#: (the microslip slip force); every other shape parameter keeps the model's value.
_DRAWN_SHAPES = (f"{MICROSLIP.name}.F_s",)


def simulated_campaign(
    model: JointModel,
    n_curves: int,
    seed: int,
    *,
    levels: int = 10,
    amplitude_range_mm: tuple[float, float] = (0.05, 2.0),
    stiffness_spread: float = 0.005,
    damping_spread: float = 0.05,
    nonlinear_spread: float = 0.03,
    amplitude_jitter: float = 0.05,
    frequency_noise_hz: float = 0.003,
    damping_noise: float = 0.005,
    harmonic_noise: float = 3e-4,
    up_down: bool = False,
    shaker_distortion: tuple[float, float] = (0.0, 0.0),
    ripple_leak: float = 0.0,
) -> BackboneSet:
    """A campaign of ``n_curves`` assemblies, fast: multi-harmonic-balance backbones.

    Each assembly draws its coefficients around ``model`` (lognormal: the linear
    stiffness by ``stiffness_spread``, the viscous damping by ``damping_spread``, every
    other coefficient by ``nonlinear_spread``); its points sit at geometric levels over
    ``amplitude_range_mm`` jittered by ``amplitude_jitter`` (the same voltage holds a
    different amplitude on each assembly). Measurement noise grows at small amplitude
    like a sensor noise floor does: frequency ``frequency_noise_hz·(1 + √(a_lo/a))``,
    damping ratio relative ``damping_noise·(1 + a_lo/a)``, harmonics ``harmonic_noise·(1 +
    a_lo/a)`` of the fundamental (its standard error is carried).

    Lab conditions (all off by default):

    * ``up_down``: the levels are stepped up, then down again (a second branch with its
      own amplitude jitter and noise; points carry their hold times).
    * ``shaker_distortion``: the largest 2nd and 3rd harmonic of the base acceleration
      (fractions of its fundamental). Each assembly's shaker draws its own, between
      half and all of it, with random phases, growing with the drive level from half
      to full; the response is driven by it (the harmonic balance's forcing) and each
      point carries the excitation harmonics it measured (with the harmonics' noise).
    * ``ripple_leak``: what the controller's frequency ripple leaves in the measured
      harmonics after the hold fit removed it (fraction of the fundamental): a bias
      locked to the response, of random size (up to twice this) and phase per assembly
      and order, the same at every level of that record.
    """
    rng = np.random.default_rng(seed)
    low, high = 1e-3 * np.asarray(amplitude_range_mm)
    nominal_m = np.geomspace(low, high, levels)
    branches = 2 if up_down else 1
    hold_s = 2.5
    linear_spread = {LINEAR_STIFFNESS: stiffness_spread, VISCOUS_DAMPING: damping_spread}
    spread = {
        name: linear_spread.get(name, nonlinear_spread)
        for name in model.parameter_names
        if "." not in name or name in _DRAWN_SHAPES
    }
    curves = []
    for i in range(n_curves):
        drawn = model.with_parameters(
            {n: model.parameters[n] * np.exp(s * rng.standard_normal()) for n, s in spread.items()}
        )
        jittered = [
            np.sort(nominal_m * np.exp(amplitude_jitter * rng.standard_normal(levels)))
            for _ in range(branches)
        ]
        a = np.concatenate([jittered[0], *[b[::-1] for b in jittered[1:]]])
        drive = np.concatenate([nominal_m, nominal_m[::-1]][:branches]) / high
        forcing = None  # the random streams of conditions left off are not drawn
        if np.any(shaker_distortion):
            shaker = np.asarray(shaker_distortion) * rng.uniform(0.5, 1.0, 2)
            phases = np.exp(2j * np.pi * rng.uniform(size=2))
            forcing = (0.5 + 0.5 * drive)[:, None] * (shaker * phases)[None, :]
        hb = harmonic_backbone(drawn, a, method="multi", harmonics=5, excitation_harmonics=forcing)
        if not hb.converged.all():
            raise RuntimeError(f"no periodic solution for assembly {i} of {model.equation()}")
        points = a.size
        ratio = low / a
        f_noise = frequency_noise_hz * (1 + np.sqrt(ratio))
        z_noise = damping_noise * (1 + ratio) * np.abs(hb.damping_ratio)
        h_noise = harmonic_noise * (1 + ratio)
        relative = (hb.harmonics_cos_m[:, 2:4] - 1j * hb.harmonics_sin_m[:, 2:4]) / a[:, None]
        leak = 0.0
        if ripple_leak:
            leak = ripple_leak * rng.uniform(0, 2, 2) * np.exp(2j * np.pi * rng.uniform(size=2))
        relative = (
            relative
            + leak
            + h_noise[:, None]
            * (rng.standard_normal((points, 2)) + 1j * rng.standard_normal((points, 2)))
        )
        measured_excitation = None
        if forcing is not None:
            measured_excitation = forcing + h_noise[:, None] * (
                rng.standard_normal((points, 2)) + 1j * rng.standard_normal((points, 2))
            )
        curves.append(
            Backbone(
                a,
                hb.frequency_hz + f_noise * rng.standard_normal(points),
                hb.damping_ratio + z_noise * rng.standard_normal(points),
                label=f"assembly{i + 1}",
                harmonics=relative,
                harmonic_standard_error=np.repeat(h_noise[:, None], 2, axis=1),
                excitation_harmonics=measured_excitation,
                time_s=hold_s * (np.arange(points) + 0.5),
            )
        )
    return BackboneSet(curves)


def draw_lab_campaign(
    truth: JointModel, n_curves: int, seed: int, k: int
) -> tuple[tuple[str, ...], int, BackboneSet]:
    """Campaign ``k`` of a study seeded ``seed``, drawn from its own seed.

    Parameters
    ----------
    truth
        The model the assemblies are drawn around.
    n_curves
        Assemblies of the campaign.
    seed, k
        The study's seed and the campaign's index in it.

    Returns
    -------
    conditions : tuple of str
        The lab conditions present (each of :data:`NULL_CONDITIONS` with probability ½).
    n_levels : int
        Levels per branch (5, 6 or 8).
    measured : BackboneSet
        The simulated campaign (:func:`simulated_campaign`).
    """
    draw = np.random.default_rng([seed, k, 7])
    present = tuple(name for name in NULL_CONDITIONS if draw.uniform() < 0.5)
    n_levels = int(draw.choice([5, 6, 8]))
    conditions = {o: v for name in present for o, v in NULL_CONDITIONS[name].items()}
    measured = simulated_campaign(
        truth, n_curves, seed=seed * 100_003 + k, levels=n_levels, **conditions
    )
    return present, n_levels, measured


#: Levels per branch a driven rig campaign draws from (as :func:`draw_lab_campaign` does).
RIG_LEVEL_CHOICES = (5, 6, 8)
#: Entries of a lab preset's settings that are physics, not conditions of the lab.
_PHYSICS = ("joints", "second_mode")


def rig_campaign(
    preset: str, n_curves: int, seed: Sequence[int], *, levels: int, hold_s: float = 2.5
) -> tuple[list[Record], BackboneSet]:
    """A campaign of ``n_curves`` assemblies on the rig of ``preset``, kept in memory.

    The rig (:func:`identification.rig.rig_for_preset`: the lab rig for ``lab-*``
    presets, with their artefacts) draws each assembly and its noise as
    :meth:`~identification.rig.Rig.write_campaign` does, assembly ``a`` (from 1) from the
    seeds ``[*seed, a]`` and ``[*seed, a, 1]``; the backbones are extracted from the
    records as a user's would be.

    Parameters
    ----------
    preset
        A rig preset (:data:`~identification.rig.RIG_PRESETS`).
    n_curves
        Assemblies (records).
    seed
        The seed sequence every assembly's seeds start with.
    levels
        Hold phases per record (per branch for an up-down schedule).
    hold_s
        Seconds of each hold.

    Returns
    -------
    records : list of Record
        One record per assembly.
    measured : BackboneSet
        Their backbones.
    """
    rig = rig_for_preset(preset, levels=levels, hold_s=hold_s)
    records = []
    for a in range(1, n_curves + 1):
        drawn, gain = rig.draw(np.random.default_rng([*seed, a]))
        name = f"Config{rig.config}_PRT_Assemb{a}"
        records.append(rig.simulate(drawn, gain, np.random.default_rng([*seed, a, 1]), name))
    return records, extract_backbones(records)


def lab_conditions(preset: str) -> tuple[str, ...]:
    """The lab conditions a preset sets (its :class:`~identification.rig.lab.LabRig`
    settings other than the physics); empty for the ideal rig's presets."""
    lab = RIG_PRESETS[preset].lab or {}
    return tuple(k for k, v in lab.items() if v and k not in _PHYSICS)


def draw_rig_campaign(
    preset: str, n_curves: int, seed: int, k: int
) -> tuple[tuple[str, ...], int, BackboneSet]:
    """Campaign ``k`` of a study seeded ``seed`` on the rig of ``preset``.

    Its levels per branch are drawn from :data:`RIG_LEVEL_CHOICES` (seed ``[seed, k, 7]``,
    as :func:`draw_lab_campaign` draws them); its assemblies from ``[seed, k, a]``
    (:func:`rig_campaign`).

    Returns
    -------
    conditions : tuple of str
        The preset's lab conditions (:func:`lab_conditions`).
    n_levels : int
        Levels per branch.
    measured : BackboneSet
        The campaign's backbones.
    """
    n_levels = int(np.random.default_rng([seed, k, 7]).choice(RIG_LEVEL_CHOICES))
    _, measured = rig_campaign(preset, n_curves, (seed, k), levels=n_levels)
    return lab_conditions(preset), n_levels, measured


def synthetic_campaign(
    model: JointModel,
    names: Sequence[str],
    log_mean: ArrayLike,
    log_spread: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    n_curves: int = 25,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    rng: np.random.Generator | int | None = None,
) -> tuple[BackboneSet, np.ndarray]:
    """Backbones of assemblies drawn from a known population, with measurement noise.

    Curve i has ``θ_i = θ0·exp(log_mean + log_spread·N(0, 1))`` (θ0 the template's
    values of ``names``, the hierarchical model's population), its
    single-harmonic backbone at ``amplitudes_m``, and independent Normal noise:
    ``frequency_noise_hz`` on each frequency, ``damping_noise`` relative on each
    damping ratio. Returns the curves and the θ_i ``(n_curves, len(names))``.
    """
    rng = np.random.default_rng(rng)
    theta0 = np.array([model.parameters[n] for n in names])
    eta = np.asarray(log_mean, float) + np.asarray(log_spread, float) * rng.standard_normal(
        (n_curves, theta0.size)
    )
    theta = theta0 * np.exp(eta)
    hb = harmonic_backbone(model, amplitudes_m, parameters=theta, names=names)
    if not hb.converged.all():
        raise ValueError(
            f"some draws of the population of {list(names)} have no backbone at every amplitude "
            "(no positive stiffness?): narrow log_spread or move log_mean"
        )
    frequency = hb.frequency_hz + frequency_noise_hz * rng.standard_normal(hb.frequency_hz.shape)
    damping = hb.damping_ratio * (1 + damping_noise * rng.standard_normal(hb.damping_ratio.shape))
    curves = [
        Backbone(hb.amplitude_m, f, d, label=f"assembly{i + 1}", source="synthetic_campaign")
        for i, (f, d) in enumerate(zip(frequency, damping, strict=True))
    ]
    return BackboneSet(curves), theta


def pll_campaign(
    model: JointModel,
    names: Sequence[str],
    theta: np.ndarray,
    excitation_levels: ArrayLike,
    *,
    frequency_noise_hz: float = 0.02,
    damping_noise: float = 0.02,
    noise_slope: float = -0.3,
    rng: np.random.Generator | int | None = None,
) -> BackboneSet:
    """Backbones of assemblies ``theta`` as the PLL simulator measures them, with noise.

    Each assembly is held at every base-acceleration level of
    ``excitation_levels`` (m/s²) under phase-locked-loop control
    (:func:`~identification.analytical.pll.pll_backbones`: time integration,
    every harmonic, not the single-harmonic balance the hierarchical model
    infers with). Noise grows towards small responses, as extraction noise
    does: ``frequency_noise_hz·(a/a_ref)^noise_slope`` on each frequency and
    the relative ``damping_noise`` times the same factor on each damping ratio
    (``a_ref`` the geometric mean of the campaign's amplitudes). Holds the
    loop did not lock are left out of their curve.
    """
    rng = np.random.default_rng(rng)
    result = pll_backbones(model, excitation_levels, theta, list(names), progress=False)
    locked = result.locked & np.isfinite(result.frequency_hz)
    amplitude = result.amplitude_m
    factor = (amplitude / np.exp(np.mean(np.log(amplitude[locked])))) ** noise_slope
    frequency = result.frequency_hz + frequency_noise_hz * factor * rng.standard_normal(
        amplitude.shape
    )
    damping = result.damping_ratio * (
        1 + damping_noise * factor * rng.standard_normal(amplitude.shape)
    )
    return BackboneSet(
        Backbone(
            amplitude[i, ok],
            frequency[i, ok],
            damping[i, ok],
            label=f"assembly{i + 1}",
            source="pll_campaign",
        )
        for i, ok in enumerate(locked)
    )


def first_fit(model: JointModel, measured: BackboneSet) -> JointModel:
    """The user's first fit: ``model``'s coefficients fitted to the frequency and damping of
    the backbones alone (the start a study criticises)."""
    return Fitter.from_backbones(measured.without_harmonics()).fit(model).model


def independent_out_of_catalogue(
    joint: str, seed: int, n_curves: int = 3
) -> tuple[BackboneSet, JointModel]:
    """A campaign of the independent simulator's out-of-catalogue ``joint``
    (:data:`independent.campaigns.OUT_OF_CATALOGUE_JOINTS`: its own balance and forces, its
    default levels, scatter and hold noise) and the linear-viscous pair fitted to it."""
    spec = OUT_OF_CATALOGUE_JOINTS[joint]
    measured = phase_resonance_campaign(spec, n_curves, seed)
    omega0 = float(spec.omega0_rad_s)
    linear = JointModel(
        {LINEAR_STIFFNESS: omega0**2, VISCOUS_DAMPING: 2 * spec.damping_ratio * omega0},
        name="linear",
    )
    return measured, first_fit(linear, measured)
