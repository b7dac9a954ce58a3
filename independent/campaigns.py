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
from independent.forces import JointSpec
from independent.phase_resonance import (
    DEFAULT_BALANCE,
    BalanceSettings,
    phase_resonance_backbone,
)

__all__ = [
    "DEFAULT_AMPLITUDES_MM",
    "HoldNoise",
    "JointSpec",
    "PopulationScatter",
    "phase_resonance_campaign",
]

#: Nominal response amplitudes of a campaign's holds (mm): 10 geometric levels, 0.05–2 mm.
DEFAULT_AMPLITUDES_MM: tuple[float, ...] = tuple(np.geomspace(0.05, 2.0, 10).tolist())

#: What each hold lasts (s): a point's time stamp is the centre of its hold.
HOLD_S = 2.5


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
        ``harmonic·(1 + a_lo/a)`` (carried as the points' ``harmonic_standard_error``).
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
        (:meth:`JointSpec.drawn`: stiffness, damping, then each term's sizes), its
        amplitude jitter, then its noise (frequency, damping ratio, harmonics' real and
        imaginary parts).
    amplitudes_mm
        Nominal levels (mm); each assembly holds them jittered by
        ``scatter.amplitude_jitter``, in increasing order.
    scatter
        Population scatter of the assemblies.
    noise
        Measurement noise; ``HoldNoise(0, 0, 0)`` gives the noise-free backbones.
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
    joints, amplitudes, noises = [], [], []
    for _ in range(n_curves):
        joints.append(joint.drawn(rng, scatter.stiffness, scatter.damping, scatter.sizes))
        jitter = scatter.amplitude_jitter * rng.standard_normal(nominal_m.size)
        amplitudes.append(np.sort(nominal_m * np.exp(jitter)))
        noises.append(rng.standard_normal((4, nominal_m.size, 2)))
    truth = phase_resonance_backbone(joints, np.array(amplitudes), settings)
    if not truth.converged.all():
        i = int(np.argmax(~truth.converged.all(axis=1)))
        raise RuntimeError(f"no phase-resonant state for assembly {i + 1} of {joint}")
    curves = []
    for i, (a, draw) in enumerate(zip(amplitudes, noises, strict=True)):
        ratio = low / a
        damping = truth.damping_ratio[i]
        h_noise = noise.harmonic * (1 + ratio)
        harmonics = truth.harmonics[i, :, :2] + h_noise[:, None] * (draw[2] + 1j * draw[3])
        curves.append(
            Backbone(
                a,
                truth.frequency_hz[i] + noise.frequency_hz * (1 + np.sqrt(ratio)) * draw[0, :, 0],
                damping + noise.damping * (1 + ratio) * np.abs(damping) * draw[1, :, 0],
                label=f"assembly{i + 1}",
                source="independent.phase_resonance",
                harmonics=harmonics,
                harmonic_standard_error=np.repeat(h_noise[:, None], 2, axis=1),
                mean_offset_m=truth.mean_offset_m[i],
                time_s=HOLD_S * (np.arange(a.size) + 0.5),
            )
        )
    return BackboneSet(curves)
