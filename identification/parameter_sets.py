"""Parameter sets: rows of values for a template model's named parameters.

The batched solvers (the one-mode coefficient table, the N-mode arrays) take a
template model and an ``(n_sets, n_names)`` matrix of overrides, one column per
parameter name; this module checks such a matrix and its columns the same way
for both.
"""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["checked_column", "checked_sets"]


def checked_sets(
    parameters: ArrayLike | None, names: Sequence[str] | None
) -> tuple[np.ndarray, list[str]] | None:
    """The values as an ``(n_sets, len(names))`` float array and the names as a list.

    Returns None when neither is given (the template's single set); ValueError when
    only one is given, the shape does not match the names, or a name repeats.
    """
    if parameters is None:
        if names is not None:
            raise ValueError("names given without parameters")
        return None
    if names is None:
        raise ValueError("parameters given without names (the column names)")
    names = list(names)
    values = np.asarray(parameters, dtype=float)
    if values.ndim != 2 or values.shape[1] != len(names) or values.shape[0] == 0:
        raise ValueError(
            f"parameters must have shape (n_sets, {len(names)}) for names {names}, "
            f"got {values.shape}"
        )
    if len(set(names)) != len(names):
        raise ValueError(f"parameter names repeat: {names}")
    return values, names


def checked_column(
    values: np.ndarray, column: int, name: str, known: Collection[str]
) -> np.ndarray:
    """Column ``column`` of ``values``, the parameter ``name``; ValueError if ``name`` is
    not among the model's ``known`` parameters or a value is not finite."""
    if name not in known:
        raise ValueError(f"unknown parameter {name!r}; the model has {list(known)}")
    column_values = values[:, column]
    bad = np.flatnonzero(~np.isfinite(column_values))
    if bad.size:
        raise ValueError(f"parameter {name!r} is not finite in set {bad[0]}")
    return column_values
