"""Sampled series: read-only arrays, and time axes checked for order and uniform sampling.

A measured time axis is uniform when its steps agree with their mean within
:data:`UNIFORM` (relative); such an axis is kept as written. Time stamps that
were rounded when written (a CSV of stamps with 7 significant digits at
5120 Hz steps 0.0001953 and 0.0001954 s below one second, 0.000195 and
0.000196 s above) jitter around their mean step without drifting from the
uniform grid: they are read on that grid, at the mean rate. A
missing sample, a jump of steps or a change of rate is no rounding and is
refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["UNIFORM", "RegularTime", "check_increasing", "frozen_array", "regular_time"]

#: Relative spread of the time steps up to which a time axis is uniform as written.
UNIFORM = 1e-3
#: Largest step deviation (fraction of the mean step) that rounded stamps may show:
#: a missing sample is a step of twice the mean.
_ROUNDING_STEP = 0.5
#: Largest distance (fraction of the mean step) of a rounded stamp from the uniform grid;
#: a missing sample puts the stamps on one side of it half a step or more away.
_ROUNDING_DRIFT = 0.25


def frozen_array(values, dtype=float) -> np.ndarray:
    """A read-only array; writable inputs are copied so the caller's array stays theirs."""
    if isinstance(values, np.ndarray) and values.dtype == dtype and not values.flags.writeable:
        return values
    array = np.array(values, dtype=dtype)
    array.setflags(write=False)
    return array


def check_increasing(where: str | Path, time: np.ndarray, strict: bool) -> None:
    """ValueError naming the row where ``time`` goes back (or repeats, when ``strict``)."""
    step = np.diff(time)
    bad = np.flatnonzero(step <= 0 if strict else step < 0)
    if bad.size:
        i = bad[0]
        kind = "not increasing" if step[i] < 0 else "duplicated"
        raise ValueError(
            f"{where}: time stamps {kind} at row {i + 2} "
            f"({time[i]:.10g} s then {time[i + 1]:.10g} s)"
        )


@dataclass(frozen=True)
class RegularTime:
    """A uniform time axis, and how far the stamps it replaces were from it.

    Attributes
    ----------
    time_s
        The stamps as written when they are uniform, else the uniform grid of
        their mean rate from the first stamp (read-only).
    jitter
        Largest step deviation of the written stamps from their mean step
        (fraction of it): 0 where they were kept as written.
    """

    time_s: np.ndarray
    jitter: float = 0.0


def regular_time(time_s: np.ndarray, where: str | Path) -> RegularTime:
    """The uniform time axis of strictly increasing stamps (see the module notes).

    Raises
    ------
    ValueError
        Stamps that are not uniform and not rounded ones either: a gap, a jump
        or a change of rate, naming the first row where it shows.
    """
    time = frozen_array(time_s)
    steps = np.diff(time)
    rate = (time.size - 1) / (time[-1] - time[0])
    deviation = np.abs(steps * rate - 1)
    if deviation.max() <= UNIFORM:
        return RegularTime(time)
    grid = time[0] + np.arange(time.size) / rate
    drift = np.abs(time - grid) * rate
    if deviation.max() <= _ROUNDING_STEP and drift.max() <= _ROUNDING_DRIFT:
        grid.setflags(write=False)
        return RegularTime(grid, float(deviation.max()))
    # The first step that is no rounding of one (a missing sample), else where the
    # stamps have drifted off the grid (a change of rate).
    jumps = np.flatnonzero(deviation > _ROUNDING_STEP)
    row = jumps[0] + 2 if jumps.size else np.flatnonzero(drift > _ROUNDING_DRIFT)[0] + 1
    raise ValueError(
        f"{where}: time is not uniformly sampled (steps {steps.min():.6g} to "
        f"{steps.max():.6g} s; a gap or a change of rate at row {row}, which rounded "
        "time stamps do not explain); resample first"
    )
