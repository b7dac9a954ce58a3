"""Simulators that share no code with the library: the independent data source of the tests
and studies.

They may import numpy, scipy and the library's record types
(:class:`~identification.measurements.backbone.Backbone`,
:class:`~identification.measurements.backbone.BackboneSet`) only, never a catalogue kernel, the
harmonic balance, numba code or the rig (``tests/test_independent.py`` checks it), so that data
they write test the library rather than repeat it.

* :mod:`independent.forces` — joint forces from their physical definitions, :class:`JointSpec`;
* :mod:`independent.phase_resonance` — the phase-resonance backbone by a harmonic balance of
  its own (12 harmonics, Broyden iterations from a finite-difference Jacobian), hysteresis
  loops closed in time, a distorted base acceleration if asked;
* :mod:`independent.campaigns` — populations of assemblies measured as PLL hold fits measure
  (defaults: the studies' fast campaigns' scatter and noise), the lab conditions, the
  out-of-catalogue joints of the lab scenarios;
* :mod:`independent.decays` — ring-downs and base-driven steady states by DOP853, one mode or
  several modes coupled through a joint and a modal potential, each mode's decay backbone;
* :mod:`independent.modal_resonance` — the phase-resonance backbone of one mode of several
  (a harmonic balance of its own, a distorted shaker if asked), every mode's participation;
* :mod:`independent.modal_pll` — phase-locked tests of several modes (a PI loop on the locked
  mode's phase, stepped levels, sensor noise, rounded time stamps) written as TRC folders.
"""

from independent.campaigns import (
    OUT_OF_CATALOGUE_JOINTS,
    HoldNoise,
    PopulationScatter,
    phase_resonance_campaign,
)
from independent.forces import CATALOGUE_FORCES, JointSpec, catalogue_joint
from independent.phase_resonance import BalanceSettings, phase_resonance_backbone

__all__ = [
    "CATALOGUE_FORCES",
    "OUT_OF_CATALOGUE_JOINTS",
    "BalanceSettings",
    "HoldNoise",
    "JointSpec",
    "PopulationScatter",
    "catalogue_joint",
    "phase_resonance_backbone",
    "phase_resonance_campaign",
]
