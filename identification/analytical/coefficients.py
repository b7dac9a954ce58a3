"""Coefficients of many parameter sets of one model structure, as the kernels take them.

A :class:`CoefficientTable` is built from one template model plus override columns
(no model per set): the memoryless terms as catalogue indices, coefficients and
shape values, and the hysteretic term (the Jenkins element) as its coefficient and
shape values. The single- and multi-harmonic balances
(:mod:`~identification.analytical.single_harmonic`,
:mod:`~identification.analytical.multi_harmonic`) and the PLL simulation read it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from identification.effects import CATALOGUE, HYSTERETIC, LINEAR_STIFFNESS
from identification.model import JointModel
from identification.parameter_sets import checked_column, checked_sets

__all__ = ["CoefficientTable", "coefficient_table", "small_amplitude_stiffness"]


@dataclass(frozen=True)
class CoefficientTable:
    """Per-set coefficient arrays of one model structure.

    Attributes
    ----------
    indices
        Catalogue indices of the memoryless terms, ``(n_terms,)``.
    coefficients
        ``(n_sets, n_terms)`` coefficients ``c_i``.
    shapes
        ``(n_sets, n_terms, 2)`` shape parameters ``(p0, p1)`` of the force kernels.
    hysteretic
        ``(n_sets, 3)``: coefficient and shape values ``(p0, p1)`` of the hysteretic
        term, for the Jenkins element ``k_t``, ``F_s`` (zeros if absent). Also
        readable as ``microslip``.
    has_hysteretic
        Whether the model has the hysteretic term (also ``has_microslip``).
    """

    indices: np.ndarray
    coefficients: np.ndarray
    shapes: np.ndarray
    hysteretic: np.ndarray
    has_hysteretic: bool

    @property
    def n_sets(self) -> int:
        return self.coefficients.shape[0]

    @property
    def microslip(self) -> np.ndarray:
        """:attr:`hysteretic` under its earlier name."""
        return self.hysteretic

    @property
    def has_microslip(self) -> bool:
        """:attr:`has_hysteretic` under its earlier name."""
        return self.has_hysteretic

    def hysteretic_shape(self, *, keepdims: bool = False) -> dict[str, np.ndarray]:
        """The hysteretic term's shape values per set, by name (``keepdims``: ``(n_sets, 1)``)."""
        return {
            name: self.hysteretic[:, 1 + slot, None] if keepdims else self.hysteretic[:, 1 + slot]
            for slot, name in enumerate(HYSTERETIC.shape)
        }


def coefficient_table(
    model: JointModel,
    parameters: ArrayLike | None = None,
    names: Sequence[str] | None = None,
) -> CoefficientTable:
    """Coefficient arrays of ``model`` with the named parameters overridden per set.

    Parameters
    ----------
    model
        Template model; its structure (effects) is shared by all sets.
    parameters
        ``(n_sets, len(names))`` values; None gives the single set of ``model``.
    names
        Parameter names as in :attr:`JointModel.parameter_names`.
    """
    indices, coefficients, shapes = model.kernel_arrays()
    hysteretic = np.array(model.microslip_arrays(), dtype=float)
    has_hysteretic = model.hysteretic_term is not None
    checked = checked_sets(parameters, names)
    if checked is None:
        return CoefficientTable(
            indices, coefficients[None], shapes[None], hysteretic[None], has_hysteretic
        )
    values, names = checked
    n_sets = values.shape[0]
    arrays = {
        "coefficients": np.repeat(coefficients[None], n_sets, axis=0),
        "shapes": np.repeat(shapes[None], n_sets, axis=0),
        "hysteretic": np.repeat(hysteretic[None], n_sets, axis=0),
    }
    locations = _parameter_locations(model)
    for column, name in enumerate(names):
        column_values = checked_column(values, column, name, model.parameter_names)
        is_shape = "." in name
        if is_shape and np.any(column_values <= 0):
            row = np.flatnonzero(column_values <= 0)[0]
            raise ValueError(
                f"shape parameter {name!r} must be > 0, set {row} has {column_values[row]}"
            )
        array, position = locations[name]
        arrays[array][(slice(None), *position)] = column_values
    return CoefficientTable(indices, **arrays, has_hysteretic=has_hysteretic)


def _parameter_locations(model: JointModel) -> dict[str, tuple[str, tuple[int, ...]]]:
    """Table array and index (after the set axis) of every parameter of ``model``."""
    locations = {}
    for term in model.stateful_terms:
        locations[term.effect] = ("hysteretic", (0,))
        for slot, shape_name in enumerate(CATALOGUE[term.effect].shape):
            locations[f"{term.effect}.{shape_name}"] = ("hysteretic", (1 + slot,))
    memoryless = [t for t in model.terms if not t.hysteretic]
    for i, term in enumerate(memoryless):
        locations[term.effect] = ("coefficients", (i,))
        for slot, shape_name in enumerate(CATALOGUE[term.effect].shape):
            locations[f"{term.effect}.{shape_name}"] = ("shapes", (i, slot))
    return {name: locations[name] for name in model.parameter_names}


def small_amplitude_stiffness(table: CoefficientTable) -> np.ndarray:
    """Small-amplitude stiffness per set (1/s²): linear term plus the stuck hysteretic element."""
    linear_index = CATALOGUE[LINEAR_STIFFNESS].index
    k = table.coefficients[:, table.indices == linear_index].sum(axis=1)
    return k + HYSTERETIC.stuck_stiffness(table.hysteretic[:, 0], table.hysteretic_shape())
