"""Batch: PLL backbones of many parameter sets of one model structure.

:func:`pll_backbones` runs the closed-loop test
(:mod:`identification.analytical.pll.closed_loop`) on every set of a parameter
array, in chunks, on numba threads here or on any executor (a dask ``Client``,
a ``concurrent.futures`` pool); the numbers are those of
:func:`~identification.analytical.pll.closed_loop.simulate_pll` on each set.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numba
import numpy as np
from numpy.typing import ArrayLike
from tqdm.auto import tqdm

from identification.analytical.harmonic import coefficient_table
from identification.analytical.pll.closed_loop import (
    PLLResult,
    _backbone,
    _control,
    backbone_result,
)
from identification.analytical.pll.config import PLLConfig
from identification.analytical.pll.loop import N_RESULTS, check_timing, settings_vector
from identification.checks import positive_vector
from identification.model import JointModel


@numba.njit(cache=True, parallel=True)
def _backbones_parallel(
    indices, coefficients, shapes, microslip, control, settings, excitation_m_s2, out
):
    for i in numba.prange(coefficients.shape[0]):
        _backbone(
            indices, coefficients[i], shapes[i], microslip[i], control[i], settings,
            excitation_m_s2, out[i],
        )  # fmt: skip


def _chunk_out(model, excitation_m_s2, parameters, names, config, parallel) -> np.ndarray:
    """Backbones of a chunk of parameter sets, ``(n_sets, n_levels, N_RESULTS)``."""
    table = coefficient_table(model, parameters, names)
    control = _control(table, config, model)
    settings = settings_vector(config)
    out = np.empty((table.n_sets, excitation_m_s2.size, N_RESULTS))
    arrays = (table.indices, table.coefficients, table.shapes, table.microslip)
    if parallel:
        _backbones_parallel(*arrays, control, settings, excitation_m_s2, out)
    else:  # the executor provides the parallelism; one set after another here
        for i in range(table.n_sets):
            _backbone(
                table.indices, table.coefficients[i], table.shapes[i], table.microslip[i],
                control[i], settings, excitation_m_s2, out[i],
            )  # fmt: skip
    return out


def _run_chunk(model, excitation_m_s2, parameters, names, config) -> np.ndarray:
    """Executor task: one chunk, serially (module-level so that it pickles)."""
    return _chunk_out(model, excitation_m_s2, parameters, names, config, parallel=False)


def pll_backbones(
    model: JointModel,
    levels: ArrayLike,
    parameters: ArrayLike,
    names: Sequence[str],
    config: PLLConfig | None = None,
    executor: Any = None,
    chunk_size: int | None = None,
    progress: bool | None = None,
) -> PLLResult:
    """PLL backbones of many parameter sets of one model structure.

    Parameters
    ----------
    model
        Template model; the named parameters are overridden per set.
    levels
        Base-acceleration amplitudes of the holds (m/s²), shared by all sets.
    parameters
        ``(n_sets, len(names))`` parameter values.
    names
        Parameter names as in :attr:`JointModel.parameter_names`.
    config
        Test settings (default gains are designed per set).
    executor
        Anything with ``submit(fn, *args)`` returning futures with ``.result()``
        (``concurrent.futures`` executors, a ``dask.distributed.Client``): the
        sets are split in chunks, submitted, and gathered in order. Without
        one, the chunks run here in numba threads (``prange`` over sets).
    chunk_size
        Sets per chunk; default about 8 chunks per worker thread (≥ 1 set).
    progress
        Show a tqdm bar; default when there is more than one chunk.

    Returns
    -------
    PLLResult
        Arrays of shape ``(n_sets, n_levels)``; the same numbers as
        :func:`simulate_pll` on each set.
    """
    config = PLLConfig() if config is None else config
    excitation_m_s2 = positive_vector(levels, "levels")
    names = list(names)
    values = np.asarray(parameters, dtype=float)
    # Validates names and values and the stability of every set before any work is sent out.
    table = coefficient_table(model, values, names)
    check_timing(config, _control(table, config, model))
    n_sets = table.n_sets
    if chunk_size is None:
        chunk_size = max(1, math.ceil(n_sets / (8 * numba.get_num_threads())))
    if not isinstance(chunk_size, int | np.integer) or chunk_size < 1:
        raise ValueError(f"chunk_size must be an integer ≥ 1, got {chunk_size!r}")
    starts = range(0, n_sets, chunk_size)
    chunks = [values[s : s + chunk_size] for s in starts]
    progress = len(chunks) > 1 if progress is None else progress
    bar = tqdm(total=n_sets, desc="PLL backbones", unit="set", disable=not progress)
    outs = []
    with bar:
        if executor is None:
            for chunk in chunks:
                outs.append(_chunk_out(model, excitation_m_s2, chunk, names, config, parallel=True))
                bar.update(len(chunk))
        else:
            futures = [
                executor.submit(_run_chunk, model, excitation_m_s2, chunk, names, config)
                for chunk in chunks
            ]
            for future, chunk in zip(futures, chunks, strict=True):
                outs.append(future.result())
                bar.update(len(chunk))
    return backbone_result(excitation_m_s2, np.concatenate(outs, axis=0))
