"""The virtual test rig: phase-resonance records of a known ground truth.

:class:`Rig` (:mod:`identification.rig.rig`) simulates and writes records in the
TRC layout with the ideal PLL simulator, :class:`ForceRig`
(:mod:`identification.rig.force`) the same test driven by a measured force, in
the column layout; :class:`LabRig`
(:mod:`identification.rig.lab`) measures like a laboratory: shaker distortion,
a rippling multiply-and-low-pass PLL, drift, dropouts
(:mod:`identification.rig.conditions`) and joint physics outside the catalogue
(:mod:`identification.rig.joints`); :class:`ModalRig`
(:mod:`identification.rig.modal_rig`) writes the two-mode virtual TRC (bending and
torsion, every lab artefact, PLL campaigns and free decays).
:mod:`identification.rig.presets` holds the named scenarios of all of them.
"""

from typing import Any

from identification.rig.force import ForceRig
from identification.rig.lab import LabAssembly, LabRig
from identification.rig.modal_rig import (
    ModalRecordTruth,
    ModalRig,
    ModeBackboneTruth,
    plate_shapes,
    read_modal_ground_truth,
)
from identification.rig.presets import (
    HIDDEN_EFFECT_SCENARIOS,
    LAB_HIDDEN_SCENARIOS,
    LAB_NULL_SCENARIOS,
    LAB_OUT_OF_CATALOGUE_SCENARIOS,
    MODAL_RIG_PRESETS,
    RIG_PRESETS,
    RigPreset,
)
from identification.rig.rig import (
    GROUND_TRUTH_FILE,
    RecordTruth,
    Rig,
    first_bending_shape,
    levels_for_amplitudes,
    read_ground_truth,
    trc_channels,
)


def rig_for_preset(name: str, levels: int = 10, **options: Any) -> Rig | ModalRig:
    """The rig of a named preset: a :class:`ModalRig` for several modes, a :class:`LabRig`
    for lab scenarios, else a :class:`Rig`.

    ``levels`` is the number of hold phases; other keywords as :meth:`Rig.preset`
    (:meth:`ModalRig.preset`: ``ratio``, ``test``, ``mode`` as well).
    """
    if name in MODAL_RIG_PRESETS:
        return ModalRig.preset(name, levels=levels, **options)
    if name not in RIG_PRESETS:
        names = [*RIG_PRESETS, *MODAL_RIG_PRESETS]
        raise ValueError(f"unknown rig preset {name!r}; available: {', '.join(names)}")
    engine = LabRig if RIG_PRESETS[name].lab is not None else Rig
    return engine.preset(name, levels=levels, **options)


__all__ = [
    "GROUND_TRUTH_FILE",
    "HIDDEN_EFFECT_SCENARIOS",
    "LAB_HIDDEN_SCENARIOS",
    "LAB_NULL_SCENARIOS",
    "LAB_OUT_OF_CATALOGUE_SCENARIOS",
    "MODAL_RIG_PRESETS",
    "RIG_PRESETS",
    "ForceRig",
    "LabAssembly",
    "LabRig",
    "ModalRecordTruth",
    "ModalRig",
    "ModeBackboneTruth",
    "RecordTruth",
    "Rig",
    "RigPreset",
    "first_bending_shape",
    "levels_for_amplitudes",
    "plate_shapes",
    "read_ground_truth",
    "read_modal_ground_truth",
    "rig_for_preset",
    "trc_channels",
]
