"""Settings of a virtual phase-resonance test: the PLL's configuration and gains.

:class:`PLLConfig` holds what a test is run with (sampling, sensed response,
lock and settling criteria, ramps, frequency range), :class:`PLLGains` the PI
gains and detector bandwidth, which :func:`design_gains` places in closed form
(see :mod:`identification.analytical.pll.closed_loop` for the loop they close),
and :func:`target_phase_deg` the phase the loop locks on.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

SENSING = ("displacement", "velocity", "acceleration")
REFERENCES = ("force", "base_velocity")

#: Phase of each response at phase resonance relative to the effective force −a_base (deg).
_RESONANT_PHASE_VS_FORCE_DEG = {"displacement": -90.0, "velocity": 0.0, "acceleration": 90.0}
#: Phase of each reference signal relative to the effective force −a_base (deg).
_REFERENCE_VS_FORCE_DEG = {"force": 0.0, "base_velocity": 90.0}
#: −a_base leads a_base = A sin θ (the detector's zero) by 180°.
_FORCE_VS_EXCITATION_DEG = 180.0

#: Closed-loop pole p of the PLL is kept within [ω₀/100, ω₀/30].
_POLE_LIMITS = (1.0 / 100.0, 1.0 / 30.0)
#: Default cap on RK4 sub-steps per sample.
_MAX_SUBSTEPS = 1000


def target_phase_deg(sensing: str, reference: str = "force") -> float:
    """Phase of the sensed response at phase resonance relative to ``reference`` (deg).

    >>> target_phase_deg("displacement"), target_phase_deg("velocity", "base_velocity")
    (-90.0, -90.0)
    """
    if sensing not in SENSING:
        raise ValueError(f"sensing must be one of {SENSING}, got {sensing!r}")
    if reference not in REFERENCES:
        raise ValueError(f"reference must be one of {REFERENCES}, got {reference!r}")
    return _RESONANT_PHASE_VS_FORCE_DEG[sensing] - _REFERENCE_VS_FORCE_DEG[reference]


@dataclass(frozen=True)
class PLLGains:
    """PI gains and phase-detector bandwidth of the PLL.

    Attributes
    ----------
    kp
        Proportional gain (rad/s of frequency per rad of phase error, 1/s).
    ki
        Integral gain (1/s²).
    detector_bandwidth
        Bandwidth ``ω_f`` of the adaptive Fourier detector (rad/s); LMS step ``μ = 2ω_f``.
    """

    kp: float
    ki: float
    detector_bandwidth: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            _check_positive(f"PLLGains.{f.name}", value)


def design_gains(
    natural_frequency_hz: float, damping_ratio: float, bandwidth_ratio: float = 6.0
) -> PLLGains:
    """Closed-form PLL gains: the linearised loop's three poles at ``−p``.

    Parameters
    ----------
    natural_frequency_hz
        Resonance frequency ``ω₀/2π`` the loop will track.
    damping_ratio
        Linear modal damping ratio ζ (``σ = ζω₀``, may be ≤ 0).
    bandwidth_ratio
        ``p = bandwidth_ratio · σ``, kept within ``[ω₀/100, ω₀/30]``.
    """
    if not (math.isfinite(natural_frequency_hz) and natural_frequency_hz > 0):
        raise ValueError(f"natural_frequency_hz must be finite and > 0, got {natural_frequency_hz}")
    if not math.isfinite(damping_ratio):
        raise ValueError(f"damping_ratio must be finite, got {damping_ratio}")
    if not (math.isfinite(bandwidth_ratio) and bandwidth_ratio > 0):
        raise ValueError(f"bandwidth_ratio must be finite and > 0, got {bandwidth_ratio}")
    kp, ki, bandwidth = _pole_placement(
        2.0 * math.pi * natural_frequency_hz, damping_ratio, bandwidth_ratio
    )
    return PLLGains(float(kp), float(ki), float(bandwidth))


def _pole_placement(omega0, damping_ratio, bandwidth_ratio):
    """Vectorised core of :func:`design_gains` (rad/s inputs)."""
    sigma = damping_ratio * omega0
    p = np.clip(bandwidth_ratio * sigma, _POLE_LIMITS[0] * omega0, _POLE_LIMITS[1] * omega0)
    bandwidth = 3.0 * p - sigma
    return 3.0 * p**2 / bandwidth - sigma, p**3 / bandwidth, bandwidth


@dataclass(frozen=True)
class PLLConfig:
    """Settings of a virtual phase-resonance test.

    Attributes
    ----------
    fs
        Sampling (and controller) rate (Hz); the integrator step is ``1/fs``.
    sensing
        Response the detector sees: ``"displacement"``, ``"velocity"`` or
        ``"acceleration"`` (relative to the base).
    reference
        Signal the reported response phase is measured against: ``"force"``
        (−a_base) or ``"base_velocity"`` (as on the TRC rig).
    n_periods
        Periods measured at the end of each hold (NLtest uses 70 on test records).
    lock_tolerance_deg
        Largest phase error of a locked period.
    settling_tolerance
        Largest relative distance of the response amplitude from its steady
        state in a locked period, estimated as (relative change per period) /
        (2π·damping ratio); the damping ratio is biased by about as much.
    lock_periods
        Consecutive locked periods before the measurement starts.
    max_hold_s
        Longest hold (settling plus measurement) before a level is given up as
        unlocked; it must cover a few amplitude time constants ``1/(ζω)``
        (about 0.3 s for ζ = 0.5 % at 100 Hz).
    ramp_s
        Duration of the raised-cosine ramp between levels.
    initial_frequency_hz
        Oscillator start frequency; default the model's linear frequency.
    gains
        PI gains and detector bandwidth; default :func:`design_gains` from the
        model's linear frequency and viscous damping.
    bandwidth_ratio
        Closed-loop pole over modal bandwidth for the default gains.
    harmonics
        Harmonics fitted by the adaptive Fourier detector (≥ 1).
    frequency_limits
        Oscillator frequency range as multiples of the initial frequency.
    max_displacement_m
        ``|x|`` beyond this counts as divergence.
    max_substeps
        Most RK4 sub-steps per sample the stability check may ask for; a model
        needing more raises ValueError (raise ``v_reg`` or ``fs``).
    """

    fs: float = 10_000.0
    sensing: str = "displacement"
    reference: str = "force"
    n_periods: int = 20
    lock_tolerance_deg: float = 1.0
    settling_tolerance: float = 0.005
    lock_periods: int = 10
    max_hold_s: float = 10.0
    ramp_s: float = 0.1
    initial_frequency_hz: float | None = None
    gains: PLLGains | None = None
    bandwidth_ratio: float = 6.0
    harmonics: int = 3
    frequency_limits: tuple[float, float] = (0.5, 2.0)
    max_displacement_m: float = 0.05
    max_substeps: int = _MAX_SUBSTEPS

    def __post_init__(self) -> None:
        target_phase_deg(self.sensing, self.reference)  # validates both names
        for name in ("n_periods", "lock_periods", "harmonics", "max_substeps"):
            value = getattr(self, name)
            if not isinstance(value, int | np.integer) or isinstance(value, bool) or value < 1:
                raise ValueError(f"PLLConfig.{name} must be an integer ≥ 1, got {value!r}")
        positive = ("fs", "lock_tolerance_deg", "settling_tolerance", "max_hold_s")
        for name in (*positive, "bandwidth_ratio", "max_displacement_m"):
            _check_positive(f"PLLConfig.{name}", getattr(self, name))
        if not (math.isfinite(self.ramp_s) and self.ramp_s >= 0):
            raise ValueError(f"PLLConfig.ramp_s must be finite and ≥ 0, got {self.ramp_s!r}")
        if self.lock_tolerance_deg >= 90:
            raise ValueError(
                f"PLLConfig.lock_tolerance_deg must be < 90, got {self.lock_tolerance_deg}"
            )
        if self.initial_frequency_hz is not None:
            _check_positive("PLLConfig.initial_frequency_hz", self.initial_frequency_hz)
        if self.gains is not None and not isinstance(self.gains, PLLGains):
            raise ValueError(f"PLLConfig.gains must be a PLLGains or None, got {self.gains!r}")
        limits = self.frequency_limits
        if not (
            isinstance(limits, tuple | list)
            and len(limits) == 2
            and all(isinstance(v, numbers.Real) for v in limits)
            and 0 < limits[0] < 1 < limits[1] < math.inf
        ):
            raise ValueError(
                f"PLLConfig.frequency_limits must be (low, high) with 0 < low < 1 < high, "
                f"got {self.frequency_limits!r}"
            )


def _check_positive(name: str, value: Any) -> None:
    real = isinstance(value, numbers.Real) and not isinstance(value, bool)
    if not (real and math.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
