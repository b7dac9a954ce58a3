"""Which models a resonance test admits: a backbone with positive damping at every tested amplitude.

A resonance test measures positive damping at every level (the shaker feeds
power in). Only candidates whose backbone exists with positive damping over the
tested amplitudes (:func:`admissible`, over :func:`tested_amplitudes`) compete
in the model selection (:mod:`.selection`); a model without damping, or one
whose damping turns negative at small amplitudes, cannot be run under a
phase-locked loop however small its regression error.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical import harmonic
from identification.measurements.signals import Kinematics, amplitude_envelope
from identification.model import JointModel


def admissible(model: JointModel, amplitudes_m: ArrayLike) -> bool:
    """Whether ``model`` has a phase-resonant backbone with positive damping at every amplitude.

    A resonance test measures positive damping at every level (the shaker
    feeds power in), so a model without damping, or whose damping turns
    negative inside the tested range, contradicts the data, however small its
    regression error, and a phase-locked loop cannot run it there.
    Single-harmonic balance (:func:`identification.analytical.harmonic.backbone`).
    """
    if not model.terms:
        return False
    result = harmonic.backbone(model, amplitudes_m)
    return bool(np.all(result.converged) and np.all(result.damping_ratio > 0))


def tested_amplitudes(kins: Sequence[Kinematics], n: int = 16) -> np.ndarray:
    """Amplitudes (m) spanning the records: 2nd percentile to largest of the envelope.

    The low percentile leaves out the start-up from rest, where no level is held.
    """
    envelope = np.concatenate(
        [amplitude_envelope(k.displacement, k.sampling_rate_hz, k.band_hz[0] / 4)[k.valid]
         for k in kins]
    )  # fmt: skip
    return np.geomspace(np.percentile(envelope, 2), envelope.max(), n)
