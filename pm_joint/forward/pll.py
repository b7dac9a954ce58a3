"""The PLL phase-resonance simulator as a forward model: :class:`PLLOp` (no gradient).

Points are the excitation levels (base-acceleration amplitudes of the holds, m/s²),
in test order.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from identification.analytical.pll import PLLConfig, pll_backbones
from identification.checks import positive_vector
from identification.model import JointModel
from pm_joint.forward.base import BackboneOp, checked_names

__all__ = ["PLLOp"]


class PLLOp(BackboneOp):
    """The PLL phase-resonance simulator as a black-box pytensor Op (no gradient).

    Points are the excitation levels, in test order. Holds that did not lock
    are NaN; parameter vectors the simulator cannot run (non-finite values,
    shape parameters ≤ 0, a model too stiff for the sub-step limit, a
    diverging run) give NaN rows counted in :attr:`n_failed`, never an error.

    Parameters
    ----------
    model
        Template model; the named parameters are overridden by θ.
    names
        Order of θ, names of :attr:`JointModel.parameter_names` (None: all).
    levels
        Base-acceleration amplitudes of the holds (m/s²).
    config
        Test settings (:class:`~identification.analytical.pll.PLLConfig`).
    executor
        ``concurrent.futures``-style executor for large batches (e.g. a
        ``dask.distributed`` Client); default: serially in the calling process,
        which suits one sampler chain per core and forked chains. An executor
        that cannot be pickled keeps the Op from multi-process sampling.
    """

    def __init__(
        self,
        model: JointModel,
        names: Sequence[str] | None,
        levels: ArrayLike,
        config: PLLConfig | None = None,
        executor: Any = None,
    ) -> None:
        super().__init__()
        self.model = model
        self.parameter_names = checked_names(model, names)
        #: Base-acceleration amplitudes of the holds (m/s²), the points.
        self.levels = positive_vector(levels, "levels")
        self.n_points = self.levels.size
        self.config = PLLConfig() if config is None else config
        self.executor = executor
        self._is_shape = np.array(["." in n for n in self.parameter_names])

    def _backbones(self, flat: np.ndarray) -> np.ndarray:
        out = np.full((flat.shape[0], self.n_points, 3), np.nan)
        usable = np.isfinite(flat).all(axis=1) & (flat[:, self._is_shape] > 0).all(axis=1)
        rows = np.flatnonzero(usable)
        if rows.size == 0:
            return out
        try:
            out[rows] = self._simulate(flat[rows])
        except ValueError:
            # One set the simulator refuses (e.g. too stiff) must not cost the others.
            for row in rows:
                with contextlib.suppress(ValueError):
                    out[row] = self._simulate(flat[row : row + 1])[0]
        return out

    def _simulate(self, parameters: np.ndarray) -> np.ndarray:
        executor = self.executor or _SerialExecutor()
        result = pll_backbones(
            self.model, self.levels, parameters, self.parameter_names, self.config,
            executor=executor, chunk_size=None if self.executor else len(parameters),
            progress=False,
        )  # fmt: skip
        backbone = np.stack([result.amplitude_m, result.frequency_hz, result.damping_ratio], -1)
        backbone[~result.locked] = np.nan
        return backbone

    def __repr__(self) -> str:
        return (
            f"PLLOp({self.model!r}, names={list(self.parameter_names)}, "
            f"levels={self.levels.tolist()})"
        )


class _SerialExecutor:
    """``submit`` that runs the task at once: serial batches through ``pll_backbones``.

    Without an executor ``pll_backbones`` runs numba threads, which are not
    fork-safe in the sampler's worker processes.
    """

    def submit(self, fn: Callable, *args: Any) -> Future:
        future: Future = Future()
        future.set_result(fn(*args))
        return future
