"""Generation for an N-mode model: one mode's phase-resonant backbone on an amplitude grid.

The N-mode twin of the amplitude-grid generation (:mod:`surrogates.dataset.generation`):
for every designed parameter set of a :class:`~identification.multimode.ModalModel`, the
backbone a phase-locked test holding mode ``m`` measures, on fixed amplitudes of that
mode's coordinate. What computes it is given (:data:`ModeEvaluation`;
:func:`pm_joint.modal_surrogate.mode_evaluation` runs the N-mode harmonic balance the
N-mode updating runs on, for many sets at once): this package does not import the
forward models. The channels (:data:`MODAL_CHANNELS`):

* ``frequency_hz`` and ``damping_ratio`` of the locked mode;
* ``base_acceleration_m_s2``, the drive the hold needs: the power balance
  ``ζ = Γ_m A / (2 ω² a)`` read backwards (``Γ_m`` the mode's base participation);
* ``other_modes_energy_share``: the share of the period-averaged linear modal energy in
  the other modes (:func:`identification.multimode.energy_shares`), how much of the hold
  is another mode's;
* ``has_backbone``, 0 where the point is masked, with the one-mode grid's reasons
  (:data:`surrogates.grid.MASK_REASONS`): the balance did not settle (near an internal
  resonance, see :mod:`pm_joint.forward.modal_harmonic`), no positive power input, or a
  drive below one a test stepping its level up has already passed.

Masked entries hold 0 in every value channel, as on the one-mode grid.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from datetime import UTC, datetime
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike

from identification.artifacts import versions
from surrogates.dataset.container import ANALYTICAL, FORMAT, FORMAT_VERSION, BackboneDataset
from surrogates.dataset.design import sample_parameters
from surrogates.grid import grid_counts, highest_before, mask_reasons, passed_curves
from surrogates.runtime import MASK_CHANNEL, OTHER_MODES_CHANNEL, SurrogateSpec

__all__ = [
    "MODAL_CHANNELS",
    "ModeBackbones",
    "ModeEvaluation",
    "generate_modal_dataset",
    "grid_values",
]

#: The channels of an N-mode surrogate's datasets, in the order they are computed.
MODAL_CHANNELS = (
    "frequency_hz", "damping_ratio", "base_acceleration_m_s2", OTHER_MODES_CHANNEL, MASK_CHANNEL,
)  # fmt: skip
#: Parameter sets evaluated at once (memory: sets × amplitudes × modes × harmonics).
CHUNK = 256


class ModeBackbones(NamedTuple):
    """One mode's backbones of parameter sets on the amplitude grid, each ``(n, A)``.

    Attributes
    ----------
    frequency_hz, damping_ratio
        The locked mode's frequency and damping ratio.
    drive_m_s2
        The base acceleration the hold needs.
    other_modes_energy_share
        The other modes' share of the linear modal energy.
    settled
        Where the balance settled (elsewhere the values are not a backbone).
    """

    frequency_hz: np.ndarray
    damping_ratio: np.ndarray
    drive_m_s2: np.ndarray
    other_modes_energy_share: np.ndarray
    settled: np.ndarray


#: Parameter sets ``(n, n_params)`` → :class:`ModeBackbones` on the dataset's grid.
ModeEvaluation = Callable[[np.ndarray], ModeBackbones]


def grid_values(backbones: ModeBackbones) -> tuple[np.ndarray, np.ndarray]:
    """The dataset's values and mask reasons of one mode's backbones.

    Returns
    -------
    values, reasons
        ``(n, A, 5)`` the :data:`MODAL_CHANNELS` (0 where masked); ``(n, A)`` int, 0 for a
        backbone point, else ``1 +`` the index of its reason in ``MASK_REASONS``.
    """
    frequency, damping = backbones.frequency_hz, backbones.damping_ratio
    drive, other = backbones.drive_m_s2, backbones.other_modes_energy_share
    settled = np.asarray(backbones.settled, dtype=bool) & np.isfinite(
        frequency + damping + drive + other
    )
    powered = settled & (drive > 0)
    # A test stepping its level up holds a point only where its drive exceeds every drive
    # below it on the grid (the one-mode grid's "passed").
    reachable = powered & (drive > highest_before(drive, powered))
    reasons = mask_reasons(settled, powered, ~reachable)
    values = np.stack([frequency, damping, drive, other, reachable.astype(float)], axis=-1)
    values[~reachable, :4] = 0.0
    return values, reasons


def generate_modal_dataset(
    evaluate: ModeEvaluation,
    names: Sequence[str],
    bounds: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    n: int = 500,
    sampler: str = "lhs",
    seed: int = 0,
    provenance: Mapping[str, Any] | None = None,
) -> BackboneDataset:
    """One mode's backbones of ``n`` designed parameter sets on an amplitude grid.

    Parameters
    ----------
    evaluate
        The mode's backbones of parameter sets on ``amplitudes_m``
        (:func:`pm_joint.modal_surrogate.mode_evaluation`: the N-mode balance).
    names
        The parameters that vary (the surrogate's inputs).
    bounds
        ``(len(names), 2)`` the box the sets are drawn in (the prior box of the updating).
    amplitudes_m
        The grid: amplitudes of the mode's coordinate (m), increasing.
    n, sampler, seed
        The design (:func:`~surrogates.dataset.design.sample_parameters`).
    provenance
        What made the backbones (model, mode, method), added to the dataset's provenance.

    Returns
    -------
    BackboneDataset
        Every set kept (the mask says where a set has no backbone); channels
        :data:`MODAL_CHANNELS`; provenance as the one-mode generator's.
    """
    names = list(names)
    box = np.asarray(bounds, dtype=float)
    grid = np.asarray(amplitudes_m, dtype=float)
    parameters = sample_parameters(box, n, sampler=sampler, seed=seed)
    chunks = [grid_values(evaluate(parameters[s : s + CHUNK])) for s in range(0, n, CHUNK)]
    values = np.concatenate([c[0] for c in chunks])
    reasons = np.concatenate([c[1] for c in chunks])
    spec = SurrogateSpec(tuple(names), box, channels=MODAL_CHANNELS, amplitudes_m=grid)
    provenance: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        **dict(provenance or {}),
        "names": names,
        "bounds": box.tolist(),
        "representation": "amplitude_grid",
        "channels": list(MODAL_CHANNELS),
        "sampler": sampler,
        "seed": seed,
        "amplitudes_m": grid.tolist(),
        "measured": {"added": [], "excluded": {}},
        "versions": versions(),
        "counts": grid_counts(reasons),
    }
    return BackboneDataset(
        X=parameters,
        Y=values,
        spec=spec,
        origin=np.full(n, ANALYTICAL),
        non_monotone=passed_curves(reasons),
        failed_parameters=np.empty((0, len(names))),
        failed_reasons=np.empty(0, dtype=str),
        provenance=provenance,
    )
