"""Labels that agree with their curves: how far a measured curve's label misfits it.

A measured curve enters a surrogate's training data with a label, the parameter
vector of a fit to that curve (the paper's construction). If the label's own
backbone misses the curve by more than the assemblies differ from each other,
the pair teaches the network a mapping the model cannot produce. The **label
misfit** is that distance in assembly standard deviations: the RMS over the
curve's grid amplitudes of ``(label backbone − curve) / scatter``, with the
scatter of :func:`~surrogates.grid.assembly_scatter`. It is infinite when the
label's model has no backbone at an amplitude the curve was measured at.

A :data:`MisfitPolicy` says what happens to a curve beyond ``threshold``:
``"exclude"`` leaves it out, ``"downweight"`` scales its loss weight by
``(threshold / misfit)²`` (an infinite misfit leaves it out), ``"keep"`` keeps it
at weight 1. Every curve's misfit is reported either way.
"""

from __future__ import annotations

import math
from typing import Literal

import numpy as np

__all__ = ["MISFIT_POLICIES", "MisfitPolicy", "label_misfit", "misfit_weight"]

MisfitPolicy = Literal["exclude", "downweight", "keep"]
MISFIT_POLICIES = ("exclude", "downweight", "keep")


def label_misfit(
    measured: np.ndarray,
    observed: np.ndarray,
    label: np.ndarray,
    label_exists: np.ndarray,
    scatter: np.ndarray,
) -> float:
    """RMS misfit of a label's backbone against its curve, in assembly standard deviations.

    Parameters
    ----------
    measured, observed
        ``(n_amplitudes,)`` the curve's values on the grid and where it covers it.
    label, label_exists
        ``(n_amplitudes,)`` the label's backbone on the grid and where it has one.
    scatter
        ``(n_amplitudes,)`` assembly standard deviation (NaN where unknown).

    Returns
    -------
    float
        NaN where no observed amplitude has a known scatter; infinity where the
        label has no backbone at an observed amplitude.
    """
    usable = observed & np.isfinite(scatter) & (scatter > 0)
    if not usable.any():
        return math.nan
    if np.any(usable & ~label_exists):
        return math.inf
    z = (label[usable] - measured[usable]) / scatter[usable]
    return float(np.sqrt(np.mean(z**2)))


def misfit_weight(misfit: float, threshold: float, policy: MisfitPolicy) -> float | None:
    """The loss weight of a curve with this misfit, or None to leave it out.

    A misfit that could not be computed (NaN) keeps weight 1: the check has no
    say without a scatter, which the caller reports.
    """
    if policy not in MISFIT_POLICIES:
        raise ValueError(f"misfit policy must be one of {MISFIT_POLICIES}, got {policy!r}")
    if not (math.isfinite(threshold) and threshold > 0):
        raise ValueError(f"misfit threshold must be finite and > 0, got {threshold}")
    if math.isnan(misfit) or misfit <= threshold or policy == "keep":
        return 1.0
    weight = 0.0 if policy == "exclude" else (threshold / misfit) ** 2
    return weight if weight > 0 else None  # a curve that weighs nothing is left out
