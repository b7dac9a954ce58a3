"""Generation for an N-mode model: one mode's phase-resonant backbone on an amplitude grid.

The N-mode twin of the amplitude-grid generation (:mod:`surrogates.dataset.generation`):
for every designed parameter set of a :class:`~identification.multimode.ModalModel`, the
backbone a phase-locked test holding mode ``m`` measures, on fixed amplitudes of that
mode's coordinate, from the N-mode harmonic balance
(:func:`pm_joint.forward.modal_harmonic.modal_backbone_numpy`, the forward model the
N-mode updating runs on, evaluated for many sets at once). The channels
(:data:`MODAL_CHANNELS`):

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

from collections.abc import Sequence
from datetime import UTC, datetime
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.artifacts import versions
from identification.multimode.model import ModalModel
from surrogates.dataset.container import ANALYTICAL, FORMAT, FORMAT_VERSION, BackboneDataset
from surrogates.dataset.design import sample_parameters
from surrogates.grid import MASK_REASONS, grid_counts, passed_curves
from surrogates.runtime import MASK_CHANNEL, OTHER_MODES_CHANNEL, SurrogateSpec

__all__ = ["MODAL_CHANNELS", "generate_modal_dataset", "modal_grid_backbones"]

#: The channels of an N-mode surrogate's datasets, in the order they are computed.
MODAL_CHANNELS = (
    "frequency_hz", "damping_ratio", "base_acceleration_m_s2", OTHER_MODES_CHANNEL, MASK_CHANNEL,
)  # fmt: skip
#: Parameter sets evaluated at once (memory: sets × amplitudes × modes × harmonics).
CHUNK = 256


def modal_grid_backbones(
    model: ModalModel,
    names: Sequence[str],
    parameters: np.ndarray,
    amplitudes_m: np.ndarray,
    mode: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Mode ``mode``'s backbones of parameter sets on the amplitude grid.

    Parameters
    ----------
    model
        Template model (structure, and the values of parameters not in ``names``).
    names
        Order of the parameter columns.
    parameters
        ``(n, len(names))`` parameter sets.
    amplitudes_m
        ``(A,)`` amplitudes of mode ``mode``'s coordinate (m), increasing.
    mode
        The locked mode, from 1.

    Returns
    -------
    values, reasons
        ``(n, A, 5)`` the :data:`MODAL_CHANNELS` (0 where masked); ``(n, A)`` int, 0 for a
        backbone point, else ``1 +`` the index of its reason in ``MASK_REASONS``.
    """
    from pm_joint.forward.modal_harmonic import modal_backbone_numpy, template_values

    participation = template_values(model)[f"mode{mode}.participation"]
    out = modal_backbone_numpy(model, parameters, list(names), amplitudes_m, mode=mode)
    frequency, damping = out.frequency_hz, out.damping_ratio
    omega = 2 * np.pi * frequency
    drive = 2 * omega**2 * amplitudes_m * damping / participation
    shares = np.asarray(out.energy_share)
    other = 1 - shares[..., mode - 1]
    settled = np.asarray(out.converged, dtype=bool) & np.isfinite(frequency + damping + other)
    powered = settled & (drive > 0)
    # A test stepping its level up holds a point only where its drive exceeds every drive
    # below it on the grid (the one-mode grid's "passed").
    highest_below = np.maximum.accumulate(np.where(powered, drive, -np.inf), axis=-1)
    highest_below = np.concatenate(
        [np.full((*drive.shape[:-1], 1), -np.inf), highest_below[..., :-1]], axis=-1
    )
    reachable = powered & (drive > highest_below)
    code = {reason: 1 + i for i, reason in enumerate(MASK_REASONS)}
    reasons = np.where(
        ~settled,
        code["no_solution"],
        np.where(~powered, code["no_power_input"], np.where(~reachable, code["passed"], 0)),
    )
    values = np.stack([frequency, damping, drive, other, reachable.astype(float)], axis=-1)
    values[~reachable, :4] = 0.0
    return values, reasons


def generate_modal_dataset(
    model: ModalModel,
    names: Sequence[str],
    bounds: ArrayLike,
    amplitudes_m: ArrayLike,
    *,
    mode: int,
    n: int = 500,
    sampler: str = "lhs",
    seed: int = 0,
) -> BackboneDataset:
    """Mode ``mode``'s backbones of ``n`` designed parameter sets on an amplitude grid.

    Parameters
    ----------
    model
        Template ModalModel.
    names
        The parameters that vary (the surrogate's inputs).
    bounds
        ``(len(names), 2)`` the box the sets are drawn in (the prior box of the updating).
    amplitudes_m
        The grid: amplitudes of mode ``mode``'s coordinate (m), increasing.
    mode
        The locked mode, from 1.
    n, sampler, seed
        The design (:func:`~surrogates.dataset.design.sample_parameters`).

    Returns
    -------
    BackboneDataset
        Every set kept (the mask says where a set has no backbone); channels
        :data:`MODAL_CHANNELS`; provenance as the one-mode generator's, with ``mode`` and
        ``model_format``.
    """
    names = list(names)
    box = np.asarray(bounds, dtype=float)
    grid = np.asarray(amplitudes_m, dtype=float)
    parameters = sample_parameters(box, n, sampler=sampler, seed=seed)
    chunks = [
        modal_grid_backbones(model, names, parameters[s : s + CHUNK], grid, mode)
        for s in range(0, n, CHUNK)
    ]
    values = np.concatenate([c[0] for c in chunks])
    reasons = np.concatenate([c[1] for c in chunks])
    spec = SurrogateSpec(tuple(names), box, channels=MODAL_CHANNELS, amplitudes_m=grid)
    provenance: dict[str, Any] = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "created": datetime.now(UTC).isoformat(timespec="seconds"),
        "model": model.to_dict(),
        "model_format": "pm-joint/ModalModel",
        "mode": mode,
        "names": names,
        "bounds": box.tolist(),
        "representation": "amplitude_grid",
        "channels": list(MODAL_CHANNELS),
        "method": "modal_harmonic",
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
