"""Which parameters a hierarchical model can let vary from assembly to assembly.

A parameter whose assembly-to-assembly change does not move a curve beyond the
scatter of the measured curves cannot be learnt per assembly: its per-curve
values are set by the prior, and in the centred hierarchical model they couple
with the population spread into a funnel that NUTS crawls through (on the full
demo's campaign with every SINDy coefficient varying, far slower than the demo
itself). Such parameters are held at the template's values and
the rest vary.

The choice is a subset selection by QR with column pivoting (Golub & Van Loan,
*Matrix Computations*, §5.4.2) on the single-harmonic backbone's sensitivity:
columns are ``∂(channel)/∂ log θ`` at the template over the measured curves'
common amplitude range, scaled by a plausible relative change of one assembly's
parameter (``relative_change``) and divided by the assembly scatter of the channel
at each amplitude. The pivoted diagonal ``|R_kk|`` is how far the k-th parameter
moves the curves, in scatter units, in the direction none of the parameters picked
before it can imitate; parameters with ``|R_kk| ≥ 1`` vary.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg

from identification.analytical.harmonic import backbone
from identification.measurements.backbone import BackboneSet
from identification.model import JointModel
from surrogates.grid import assembly_scatter

__all__ = ["VaryingChoice", "varying_parameters"]

#: Channels of the single-harmonic backbone and their column in ``assembly_scatter``.
_SCATTER_COLUMN = {"frequency_hz": 0, "damping_ratio": 1}


@dataclass(frozen=True)
class VaryingChoice:
    """The parameters that vary, those held at the template, and why.

    ``reach`` is each parameter's ``|R_kk|``: how far (in assembly-scatter
    units, over the common amplitude range) a ``relative_change`` of it moves the
    curves in the direction the parameters picked before it cannot imitate.
    """

    varying: list[str]
    held: list[str]
    reach: dict[str, float]
    relative_change: float

    def text(self) -> str:
        """One sentence for a report."""
        if not self.held:
            return (
                f"every parameter varies from assembly to assembly: a {self.relative_change:.0%} "
                "change of each moves the curves beyond the assembly scatter"
            )
        return (
            f"varying from assembly to assembly: {', '.join(self.varying)}; held at the "
            f"template's values: {', '.join(self.held)} (a {self.relative_change:.0%} change of "
            "each, beyond what the varying ones can imitate, moves the curves by less than the "
            "assembly scatter, so their per-assembly values would be set by the prior)"
        )


def varying_parameters(
    model: JointModel,
    measured: BackboneSet,
    names: Sequence[str],
    *,
    channels: Sequence[str] = ("frequency_hz", "damping_ratio"),
    relative_change: float = 0.2,
    n_amplitudes: int = 12,
) -> VaryingChoice:
    """Split ``names`` into those the measured curves inform per assembly and the rest.

    Parameters
    ----------
    model
        Template: the structure and the values the sensitivities are taken at.
    measured
        Measured backbones, at least 3 overlapping (for the scatter).
    names
        Candidates (non-zero in the template).
    channels
        Channels of the hierarchical likelihood.
    relative_change
        A plausible assembly-to-assembly relative change of a parameter (the
        hierarchical model's default population scale is 0.2 in log).
    n_amplitudes
        Log-spaced amplitudes over the curves' common range.

    Returns
    -------
    VaryingChoice
        ``varying`` in the template's order; at least the parameter that moves the
        curves most varies.
    """
    names = list(names)
    low, high = measured.common_range()
    amplitudes_m = np.geomspace(low, high, n_amplitudes)
    scatter = assembly_scatter(measured, amplitudes_m)
    theta0 = np.array([model.parameters[n] for n in names], dtype=float)
    step = 1e-3  # in log θ: small against any curvature of the backbone, large against rounding
    sets = np.repeat(theta0[None, :], 2 * len(names), axis=0)
    for j in range(len(names)):
        sets[2 * j, j] *= np.exp(step)
        sets[2 * j + 1, j] *= np.exp(-step)
    curves = backbone(model, amplitudes_m, parameters=sets, names=names, method="single")
    rows = []
    for channel in channels:
        values = getattr(curves, channel)
        spread = scatter[:, _SCATTER_COLUMN[channel]]
        # An amplitude where fewer than 3 curves give a scatter borrows the median one; a
        # channel identical on every curve has none, and any change of it shows.
        spread = np.where(np.isfinite(spread), spread, np.nanmedian(spread))
        floor = 1e-9 * np.nanmax(np.abs(values))
        spread = np.where(np.isfinite(spread) & (spread > floor), spread, floor)
        slope = (values[0::2] - values[1::2]) / (2 * step)  # (parameter, amplitude)
        rows.append(slope * relative_change / spread)
    jacobian = np.nan_to_num(np.concatenate(rows, axis=1).T, nan=0.0, posinf=0.0, neginf=0.0)
    _, r, order = scipy.linalg.qr(jacobian, mode="economic", pivoting=True)
    reach = {names[k]: float(abs(r[i, i])) if i < r.shape[0] else 0.0 for i, k in enumerate(order)}
    keep = {names[order[0]]} | {n for n, v in reach.items() if v >= 1.0}
    return VaryingChoice(
        varying=[n for n in names if n in keep],
        held=[n for n in names if n not in keep],
        reach=reach,
        relative_change=relative_change,
    )
