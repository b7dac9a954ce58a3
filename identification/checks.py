"""Input checks shared by the solvers, so that one mistake reads the same everywhere."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

__all__ = ["positive_vector"]


def positive_vector(values: ArrayLike, name: str) -> np.ndarray:
    """``values`` as a contiguous float 1-D array, non-empty, finite and > 0.

    Raises
    ------
    ValueError
        Naming ``name`` and the first offending entry.
    """
    try:
        array = np.ascontiguousarray(np.atleast_1d(np.asarray(values, dtype=float)))
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {values!r}") from None
    if array.ndim != 1 or array.size == 0:
        raise ValueError(f"{name} must be a non-empty 1-D array, got shape {array.shape}")
    bad = np.flatnonzero(~np.isfinite(array) | (array <= 0))
    if bad.size:
        raise ValueError(f"{name} must be finite and > 0; {name}[{bad[0]}] = {array[bad[0]]}")
    return array
