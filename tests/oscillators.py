"""The test suite's reference oscillator and its populations, written once.

Every test that needs "a 100 Hz Duffing panel" or "a few assemblies around it" builds it here, so
the figures the tests quote (0.4 % damping, k3 = 1e10 N/(kg·m²), ...) mean the same thing in
every file. Imported as a plain module (pytest puts ``tests/`` on the path); the fixtures in
``conftest.py`` are built from these functions.
"""

from collections.abc import Sequence

import numpy as np

from identification.analytical import harmonic
from identification.measurements.backbone import Backbone, BackboneSet
from identification.model import JointModel

#: Natural angular frequency of the reference panel (rad/s): 100 Hz.
OMEGA_100_HZ = 2 * np.pi * 100.0
#: Response amplitudes (m) of the shared Duffing population: 0.05–1.5 mm, where the 100 Hz panel
#: with k3 = 1e10 hardens by about 1 %.
POPULATION_AMPLITUDES_M = np.linspace(5e-5, 1.5e-3, 30)


def duffing(
    cubic_stiffness: float = 1e10,
    damping_ratio: float | None = 0.004,
    stiffness_scale: float = 1.0,
    natural_frequency_hz: float = 100.0,
    **terms,
) -> JointModel:
    """A mass-normalised Duffing oscillator, plus any further catalogue terms.

    Parameters
    ----------
    cubic_stiffness
        Coefficient of x³ (1/(m²·s²)).
    damping_ratio
        Viscous damping ratio ζ of the linear oscillator; ``None`` leaves the viscous term out.
    stiffness_scale
        Factor on the linear stiffness ω₀² (an assembly's stiffness scatter).
    natural_frequency_hz
        Linear natural frequency before ``stiffness_scale``.
    **terms
        Further effects by catalogue name (they replace the defaults of the same name).
    """
    omega = 2 * np.pi * natural_frequency_hz
    coefficients: dict = {"linear_stiffness": omega**2 * stiffness_scale}
    if damping_ratio is not None:
        coefficients["viscous_damping"] = 2 * damping_ratio * omega
    coefficients["cubic_stiffness"] = cubic_stiffness
    coefficients.update(terms)
    return JointModel(coefficients)


def duffing_population(
    stiffness_scales: Sequence[float],
    cubic_stiffnesses: Sequence[float],
    amplitudes_m: np.ndarray,
    label: str = "c",
) -> BackboneSet:
    """Harmonic-balance backbones of Duffing assemblies, one per (scale, k3) pair."""
    curves = []
    for i, (scale, cubic) in enumerate(zip(stiffness_scales, cubic_stiffnesses, strict=True)):
        hb = harmonic.backbone(duffing(cubic, stiffness_scale=scale), amplitudes_m)
        curves.append(
            Backbone(hb.amplitude_m, hb.frequency_hz, hb.damping_ratio, label=f"{label}{i}")
        )
    return BackboneSet(curves)


def scattered_duffing_population(
    assemblies: int,
    amplitudes_m: np.ndarray,
    stiffness_spread: float = 0.01,
    cubic_spread: float = 0.2,
    seed: int = 0,
) -> BackboneSet:
    """Assemblies with normal relative scatter of the linear and cubic stiffness around 1e10."""
    draws = np.random.default_rng(seed).standard_normal((assemblies, 2))
    scales = 1 + stiffness_spread * draws[:, 0]
    cubics = 1e10 * (1 + cubic_spread * draws[:, 1])
    return duffing_population(scales, cubics, amplitudes_m)


def measured_curve(
    hb, rng: np.random.Generator, noise_hz: float, noise_zeta: float, label: str
) -> Backbone:
    """A model backbone as a test would measure it: Gaussian noise on frequency and damping.

    ``hb`` is a harmonic-balance result (``amplitude_m``, ``frequency_hz``, ``damping_ratio``);
    the caller's ``rng`` draws the frequency noise, then the damping noise, so a caller that
    also draws assembly scatter from it keeps its own order of draws.
    """
    n = np.size(hb.amplitude_m)
    return Backbone(
        hb.amplitude_m,
        hb.frequency_hz + noise_hz * rng.standard_normal(n),
        hb.damping_ratio + noise_zeta * rng.standard_normal(n),
        label=label,
    )
