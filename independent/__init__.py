"""Simulators that share no code with the library: the independent data source of the tests
and studies.

They may import numpy, scipy and the library's record types
(:class:`~identification.measurements.backbone.Backbone`,
:class:`~identification.measurements.backbone.BackboneSet`) only, never a catalogue kernel, the
harmonic balance, numba code or the rig (``tests/test_independent.py`` checks it), so that data
they write test the library rather than repeat it.

* :mod:`independent.forces` — joint forces from their physical definitions, :class:`JointSpec`;
* :mod:`independent.phase_resonance` — the phase-resonance backbone by a harmonic balance of
  its own (many harmonics, finite-difference Newton), hysteresis loops closed in time;
* :mod:`independent.campaigns` — populations of assemblies measured as PLL hold fits measure;
* :mod:`independent.decays` — ring-downs by DOP853, one mode or several coupled modes.
"""

from independent.campaigns import HoldNoise, PopulationScatter, phase_resonance_campaign
from independent.forces import CATALOGUE_FORCES, JointSpec
from independent.phase_resonance import BalanceSettings, phase_resonance_backbone

__all__ = [
    "CATALOGUE_FORCES",
    "BalanceSettings",
    "HoldNoise",
    "JointSpec",
    "PopulationScatter",
    "phase_resonance_backbone",
    "phase_resonance_campaign",
]
