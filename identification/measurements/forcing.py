"""The modal forcing gain of a force-driven test, from the record's own decay.

A force-driven test measures the force ``F`` (N) at the driving point; the
1-DOF model is mass-normalised, ``ẍ + f(x, ẋ) = g·F``, with the modal forcing
gain ``g`` (1/kg: the mode's participation at the driving point over its
modal mass). The frequency and amplitude of a backbone point do not depend on
``g``; its power-balance damping ratio does, linearly: ``D = g·d`` with ``d``
the damping a gain of 1 gives (:func:`identification.measurements.extraction.hold_point`).
At phase resonance ``g`` cannot be told from the damping by the holds alone
(the force is in phase with the velocity, so ``g·F`` and ``c·ẋ`` look alike).

A free decay measures the damping without any force
(:mod:`identification.measurements.decay`), in the same power-balance sense.
Where a record has both (a ring-down after its last hold, as a lab records
it), every hold near resonance whose amplitude the decay passes through gives
``g = D_decay(a) / d``; :func:`forcing_gain_from_decay` takes their median.
So free-decay, base-driven and force-driven data of one structure meet in the
same modal units. Without a decay the gain must be stated (1/kg).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import make_interp_spline, make_smoothing_spline

from identification.measurements.backbone import Backbone

__all__ = ["NEAR_RESONANCE_DEG", "ForcingGain", "forcing_gain_from_decay", "record_forcing_gain"]

#: Holds within this phase error of resonance compare their damping with the decay's.
NEAR_RESONANCE_DEG = 15.0


@dataclass(frozen=True)
class ForcingGain:
    """A modal forcing gain estimated from a decay.

    Attributes
    ----------
    gain
        Median of the per-hold estimates (1/kg).
    spread
        Their relative spread (1.4826 × median absolute deviation over the median).
    n_holds
        Holds that gave an estimate.
    """

    gain: float
    spread: float
    n_holds: int


def forcing_gain_from_decay(
    amplitude_m: np.ndarray,
    damping_per_gain: np.ndarray,
    phase_error_deg: np.ndarray,
    decay: Backbone,
) -> ForcingGain:
    """The gain that makes the holds' power-balance damping the decay's (see the module notes).

    Parameters
    ----------
    amplitude_m, damping_per_gain, phase_error_deg
        Per hold: amplitude, damping at a gain of 1 (kg), phase error.
    decay
        The decay's backbone; its damping is smoothed along the amplitude
        (a smoothing spline, its roughness chosen by generalised cross-validation).

    Raises
    ------
    ValueError
        When no hold near resonance lies in the decay's amplitude range.
    """
    order = np.argsort(decay.amplitude_m)
    a, damping = decay.amplitude_m[order], decay.damping_ratio[order]
    keep = np.concatenate(([True], np.diff(a) > 0))
    a, damping = a[keep], damping[keep]
    # Along log(a): decays sample the amplitude geometrically, and the spline's
    # cross-validation needs an abscissa of order one.
    spline = (make_smoothing_spline(np.log(a), damping) if a.size >= 5
              else make_interp_spline(np.log(a), damping, k=1))  # fmt: skip

    def smooth(values: np.ndarray) -> np.ndarray:
        return spline(np.log(values))

    amplitude_m = np.asarray(amplitude_m, dtype=float)
    inside = (
        (amplitude_m >= a[0])
        & (amplitude_m <= a[-1])
        & (np.abs(phase_error_deg) <= NEAR_RESONANCE_DEG)
        & (np.asarray(damping_per_gain) > 0)
    )
    if not inside.any():
        raise ValueError(
            f"no hold near resonance lies in the decay's amplitude range "
            f"({1e3 * a[0]:.4g}–{1e3 * a[-1]:.4g} mm), so the modal forcing gain cannot be "
            "measured; state it (--forcing-gain, 1/kg)"
        )
    estimates = smooth(amplitude_m[inside]) / np.asarray(damping_per_gain)[inside]
    gain = float(np.median(estimates))
    spread = float(1.4826 * np.median(np.abs(estimates - gain)) / gain)
    return ForcingGain(gain, spread, int(inside.sum()))


def record_forcing_gain(record, n_periods: int = 70, harmonics: int = 3) -> ForcingGain:
    """The forcing gain of a force-driven record from its holds and its decay.

    Raises
    ------
    ValueError
        Naming the record: no decay after the excitation stops (then the gain
        must be stated), or no hold in the decay's range.
    """
    from identification.measurements.decay import extract_decay_backbone
    from identification.measurements.extraction import hold_points

    where = record.path or record.name
    try:
        decay = extract_decay_backbone(record, harmonics=harmonics)
    except ValueError as exc:
        raise ValueError(
            f"{where}: the modal forcing gain (1/kg) that turns the measured force into the "
            "power balance is unknown and the record has no usable decay to measure it "
            f"from ({str(exc).removeprefix(f'{where}: ')}); state it with --forcing-gain "
            "or record a ring-down after the excitation stops"
        ) from None
    points, _ = hold_points(record, n_periods, harmonics, strict=False, forcing_gain=1.0,
                            test="phase-resonance")  # fmt: skip
    try:
        return forcing_gain_from_decay(
            np.array([p.amplitude_m for p in points]),
            np.array([p.damping_ratio for p in points]),
            np.array([p.phase_error_deg for p in points]),
            decay,
        )
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
