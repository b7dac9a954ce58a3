"""Phase-resonance campaigns of the independent simulator: a population of assemblies of one
joint, each held at a few levels as a PLL test holds it, measured with the noise of hold fits.

The conventions follow the studies' fast campaigns (assemblies drawn lognormally around the
joint, geometric levels jittered per assembly, noise that grows towards small amplitudes like a
sensor floor), but every number here comes from :mod:`independent.phase_resonance`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from identification.measurements.backbone import Backbone, BackboneSet
from independent.forces import (
    Clearance,
    Iwan,
    JointSpec,
    PowerLawDamping,
    PreloadedContact,
)
from independent.phase_resonance import (
    DEFAULT_BALANCE,
    BalanceSettings,
    phase_resonance_backbone,
)

__all__ = [
    "DEFAULT_AMPLITUDES_MM",
    "OUT_OF_CATALOGUE_JOINTS",
    "HoldNoise",
    "JointSpec",
    "PopulationScatter",
    "phase_resonance_campaign",
]

#: Nominal response amplitudes of a campaign's holds (mm): 10 geometric levels, 0.05–2 mm.
DEFAULT_AMPLITUDES_MM: tuple[float, ...] = tuple(np.geomspace(0.05, 2.0, 10).tolist())

#: What each hold lasts (s): a point's time stamp is the centre of its hold.
HOLD_S = 2.5


#: The lab's natural frequency at rest (Hz) and viscous damping ratio of the joints below.
_F0_HZ, _ZETA = 101.0, 0.003
_K0 = (2 * np.pi * _F0_HZ) ** 2


def _at_rest(stiffness_at_rest: float, *terms) -> JointSpec:
    """A joint whose stiffness at rest, its terms' included, is the 101 Hz one."""
    return JointSpec(np.sqrt(_K0 - stiffness_at_rest) / (2 * np.pi), _ZETA, terms)


#: Joints no catalogue effect is, at the sizes of the project's lab scenarios (an Iwan joint
#: of 10 % of the stiffness at rest slipping wholly at 3 mm; a ±0.3 mm clearance closing on
#: 15 % of it; a contact of 20 % of it lifting off at 0.3 mm; damping ∝ |v|^1.5), each on a
#: linear spring that keeps the frequency at rest at 101 Hz, ζ = 0.3 %. Their scatter in a
#: campaign is :attr:`PopulationScatter.sizes` on :attr:`~independent.forces.Force.size_fields`.
OUT_OF_CATALOGUE_JOINTS: dict[str, JointSpec] = {
    "iwan": _at_rest(0.1 * _K0, Iwan(0.1 * _K0, 0.1 * _K0 * 1e-3, chi=-0.5, n_sliders=12)),
    "clearance": _at_rest(0.0, Clearance(3e-4, 0.15 * _K0)),
    "contact": _at_rest(0.2 * _K0, PreloadedContact(0.2 * _K0, 0.2 * _K0 * 3e-4)),
    "power-law-damping": _at_rest(0.0, PowerLawDamping(6.2, 1.5)),
}


@dataclass(frozen=True)
class PopulationScatter:
    """How assemblies differ (lognormal spreads, standard deviations of the log).

    Attributes
    ----------
    stiffness
        Of the linear stiffness ``ω0²``.
    damping
        Of the viscous damping ratio.
    sizes
        Of every nonlinear term's sizes (:attr:`~independent.forces.Force.size_fields`).
    amplitude_jitter
        Of each hold's amplitude about its nominal level (the same voltage holds a
        different amplitude on each assembly).
    """

    stiffness: float = 0.005
    damping: float = 0.05
    sizes: float = 0.03
    amplitude_jitter: float = 0.05


@dataclass(frozen=True)
class HoldNoise:
    """Measurement noise of the hold fits, growing towards small amplitudes as a sensor floor
    makes it (``a_lo`` the campaign's smallest nominal amplitude, ``a`` the point's).

    Attributes
    ----------
    frequency_hz
        Frequency standard error at large amplitude; ``frequency_hz·(1 + √(a_lo/a))``.
    damping
        Relative damping-ratio standard error; ``damping·(1 + a_lo/a)·|D|``.
    harmonic
        Standard error of each real part of a harmonic, as a fraction of the fundamental;
        ``harmonic·(1 + a_lo/a)`` (carried as the points' ``harmonic_standard_error``); the
        mean offset (a displacement sensor's) has the same standard error times ``a``.
    """

    frequency_hz: float = 0.003
    damping: float = 0.005
    harmonic: float = 3e-4


def phase_resonance_campaign(
    joint: JointSpec,
    n_curves: int,
    seed: int,
    *,
    amplitudes_mm: Sequence[float] = DEFAULT_AMPLITUDES_MM,
    scatter: PopulationScatter = PopulationScatter(),
    noise: HoldNoise = HoldNoise(),
    up_down: bool = False,
    shaker_distortion: tuple[float, float] = (0.0, 0.0),
    ripple_leak: float = 0.0,
    settings: BalanceSettings = DEFAULT_BALANCE,
) -> BackboneSet:
    """A campaign of ``n_curves`` assemblies of ``joint``, as PLL hold fits measure it.

    Parameters
    ----------
    joint
        The nominal joint.
    n_curves
        Assemblies (one backbone each, labelled ``assembly1``, …).
    seed
        Seed of every random draw. Per assembly, in order: its joint
        (:meth:`JointSpec.drawn`: stiffness, damping, then each term's sizes), the
        amplitude jitter of each branch, its shaker and ripple (8 uniform numbers, drawn
        whether or not those conditions are on, so that a campaign with them and one without
        share assemblies and noise), then its noise (a ``(11, n_points)`` standard normal
        draw: frequency, damping ratio, the real and imaginary parts of harmonics 2 and 3,
        the mean offset, those of the excitation's harmonics 2 and 3).
    amplitudes_mm
        Nominal levels (mm); each assembly holds them jittered by
        ``scatter.amplitude_jitter``, in increasing order (then decreasing: ``up_down``).
    scatter
        Population scatter of the assemblies.
    noise
        Measurement noise; ``HoldNoise(0, 0, 0)`` gives the noise-free backbones.
    up_down
        Levels stepped up, then down again: a second branch, in decreasing order, with its
        own amplitude jitter and noise (points carry their hold times, so drift in time can
        be told from amplitude dependence).
    shaker_distortion
        The largest 2nd and 3rd harmonic of the base acceleration (fractions of its
        fundamental). Each assembly's shaker has its own, between half and all of it, with
        random phases, growing with the drive level (the nominal level over the largest) from
        half to full; the response is driven by it and each point carries the excitation
        harmonics it measured (with the harmonics' noise).
    ripple_leak
        What the controller's frequency ripple leaves in the measured response harmonics
        after the hold fit (fraction of the fundamental): a bias of random size (up to twice
        this) and phase per assembly and order, the same at every level.
    settings
        The harmonic balance's settings.

    Returns
    -------
    BackboneSet
        Per point: amplitude, frequency, damping ratio, harmonics 2 and 3 of the relative
        displacement with their standard errors, the mean offset and the hold's time.

    Raises
    ------
    RuntimeError
        When an assembly has no phase-resonant state at one of its amplitudes.
    """
    rng = np.random.default_rng(seed)
    nominal_m = 1e-3 * np.asarray(amplitudes_mm, dtype=float)
    low = nominal_m.min()
    joints, amplitudes, draws, shakers, leaks = [], [], [], [], []
    for _ in range(n_curves):
        joints.append(joint.drawn(rng, scatter.stiffness, scatter.damping, scatter.sizes))
        branches = [
            np.sort(
                nominal_m * np.exp(scatter.amplitude_jitter * rng.standard_normal(nominal_m.size))
            )
            for _ in range(2 if up_down else 1)
        ]
        amplitudes.append(np.concatenate([branches[0], *[b[::-1] for b in branches[1:]]]))
        shaker = np.asarray(shaker_distortion) * rng.uniform(0.5, 1.0, 2)
        shakers.append(shaker * np.exp(2j * np.pi * rng.uniform(size=2)))
        leaks.append(ripple_leak * rng.uniform(0, 2, 2) * np.exp(2j * np.pi * rng.uniform(size=2)))
        draws.append(rng.standard_normal((11, amplitudes[-1].size)))
    drive = np.concatenate([nominal_m, nominal_m[::-1]][: 2 if up_down else 1]) / nominal_m.max()
    forcing = (0.5 + 0.5 * drive)[None, :, None] * np.array(shakers)[:, None, :]
    truth = phase_resonance_backbone(
        joints,
        np.array(amplitudes),
        settings,
        excitation_harmonics=forcing if np.any(shaker_distortion) else None,
    )
    if not truth.converged.all():
        i = int(np.argmax(~truth.converged.all(axis=1)))
        raise RuntimeError(f"no phase-resonant state for assembly {i + 1} of {joint}")
    curves = []
    for i, (a, draw, leak) in enumerate(zip(amplitudes, draws, leaks, strict=True)):
        ratio = low / a
        damping = truth.damping_ratio[i]
        h_noise = noise.harmonic * (1 + ratio)
        measured_harmonics = leak + h_noise[:, None] * (draw[2:6:2] + 1j * draw[3:6:2]).T
        excitation = None
        if np.any(shaker_distortion):
            excitation = forcing[i] + h_noise[:, None] * (draw[7:11:2] + 1j * draw[8:11:2]).T
        curves.append(
            Backbone(
                a,
                truth.frequency_hz[i] + noise.frequency_hz * (1 + np.sqrt(ratio)) * draw[0],
                damping + noise.damping * (1 + ratio) * np.abs(damping) * draw[1],
                label=f"assembly{i + 1}",
                source="independent.phase_resonance",
                harmonics=truth.harmonics[i, :, :2] + measured_harmonics,
                harmonic_standard_error=np.repeat(h_noise[:, None], 2, axis=1),
                excitation_harmonics=excitation,
                mean_offset_m=truth.mean_offset_m[i] + h_noise * a * draw[6],
                time_s=HOLD_S * (np.arange(a.size) + 0.5),
            )
        )
    return BackboneSet(curves)
