"""The virtual test rig: phase-resonance records of a known ground truth.

:class:`Rig` (:mod:`identification.rig.rig`) simulates and writes records in the
TRC layout; :mod:`identification.rig.presets` holds the named scenarios.
"""

from identification.rig.presets import HIDDEN_EFFECT_SCENARIOS, RIG_PRESETS, RigPreset
from identification.rig.rig import (
    GROUND_TRUTH_FILE,
    RecordTruth,
    Rig,
    first_bending_shape,
    levels_for_amplitudes,
    read_ground_truth,
    trc_channels,
)

__all__ = [
    "GROUND_TRUTH_FILE",
    "HIDDEN_EFFECT_SCENARIOS",
    "RIG_PRESETS",
    "RecordTruth",
    "Rig",
    "RigPreset",
    "first_bending_shape",
    "levels_for_amplitudes",
    "read_ground_truth",
    "trc_channels",
]
