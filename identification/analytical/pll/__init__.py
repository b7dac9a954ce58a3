"""Phase-locked-loop (PLL) phase-resonance simulator.

A time-domain virtual phase-resonance test of a base-excited
:class:`~identification.model.JointModel`, ``ẍ + f(x, ẋ) = −a_base(t)``, as the
TRC rig and NLtest run it: an oscillator drives the shaker, a phase detector
measures the response's fundamental harmonic, a PI controller moves the
frequency until the response sits at phase resonance, and the excitation level
is stepped with smooth ramps; each hold phase gives one backbone point.

The package, one concept a module:

:mod:`~identification.analytical.pll.config`
    The test's settings (:class:`PLLConfig`), the loop's gains
    (:class:`PLLGains`, :func:`design_gains`) and its target phase
    (:func:`target_phase_deg`).
:mod:`~identification.analytical.pll.integrator`
    The equation of motion and its RK4 step, sub-stepped for stability
    (:func:`stable_substeps`).
:mod:`~identification.analytical.pll.open_loop`
    The response to a prescribed base acceleration (:func:`simulate_base_excitation`).
:mod:`~identification.analytical.pll.loop`
    The loop, shared with the N-mode PLL (:mod:`identification.multimode.pll`):
    the settings, control and run-state layouts and their values from a
    :class:`PLLConfig`, excitation samples, phase detector, controller, lock
    detector, measurement, and the level-by-level recorded run.
:mod:`~identification.analytical.pll.closed_loop`
    The PLL itself, its conventions (phases, detector, controller, level
    schedule, backbone point) and results (:func:`simulate_pll`,
    :class:`PLLResult`, :class:`PLLTimeSeries`).
:mod:`~identification.analytical.pll.batch`
    Many parameter sets at once, here or on an executor (:func:`pll_backbones`).
"""

from identification.analytical.pll.batch import pll_backbones
from identification.analytical.pll.closed_loop import PLLResult, PLLTimeSeries, simulate_pll
from identification.analytical.pll.config import (
    REFERENCES,
    SENSING,
    PLLConfig,
    PLLGains,
    design_gains,
    target_phase_deg,
)
from identification.analytical.pll.integrator import stable_substeps
from identification.analytical.pll.open_loop import simulate_base_excitation

__all__ = [
    "REFERENCES",
    "SENSING",
    "PLLConfig",
    "PLLGains",
    "PLLResult",
    "PLLTimeSeries",
    "design_gains",
    "pll_backbones",
    "simulate_base_excitation",
    "simulate_pll",
    "stable_substeps",
    "target_phase_deg",
]
