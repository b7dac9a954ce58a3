"""The step schedule of a test: hold phases and the ramps between them.

Step file ``ConfigN_PRT_amplitude_steps``: two columns, time (s) and level
(shaker voltage, V). The rows are the breakpoints of a piecewise-linear level
schedule; a *hold phase* is a run of consecutive rows with the same level,
spanning from the first to the last of them, and the segments between
different levels are ramps. A sampled level signal (one row per sample)
therefore works as well. Equal consecutive time stamps are allowed and write
an instantaneous jump.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from identification.measurements.series import check_increasing, frozen_array
from identification.measurements.text_table import format_table
from identification.measurements.trc_layout import read_trc_table

__all__ = ["Hold", "StepSchedule", "read_steps"]


@dataclass(frozen=True)
class Hold:
    """One hold phase: a constant excitation level from ``start_s`` to ``end_s``."""

    level: float
    start_s: float
    end_s: float

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


@dataclass(frozen=True, eq=False)
class StepSchedule:
    """Breakpoints ``(time_s, level)`` of a piecewise-linear excitation schedule."""

    time_s: np.ndarray
    level: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "step schedule"
        time = frozen_array(self.time_s)
        level = frozen_array(self.level)
        if time.ndim != 1 or time.shape != level.shape or time.size < 2:
            raise ValueError(f"{where}: needs at least two (time, level) rows of equal length")
        if not (np.isfinite(time).all() and np.isfinite(level).all()):
            raise ValueError(f"{where}: non-finite time or level")
        check_increasing(where, time, strict=False)
        object.__setattr__(self, "time_s", time)
        object.__setattr__(self, "level", level)

    def holds(self) -> list[Hold]:
        """Hold phases in time order: runs of equal level with a positive duration."""
        change = np.flatnonzero(np.diff(self.level) != 0) + 1
        starts = np.concatenate(([0], change))
        ends = np.concatenate((change, [self.level.size])) - 1
        return [
            Hold(float(self.level[a]), float(self.time_s[a]), float(self.time_s[b]))
            for a, b in zip(starts, ends, strict=True)
            if self.time_s[b] > self.time_s[a]
        ]

    def level_at(self, time_s: np.ndarray) -> np.ndarray:
        """Level at the given times (linear along ramps)."""
        return np.interp(time_s, self.time_s, self.level)

    def covers(self, start_s: float, end_s: float, tolerance_s: float = 0.0) -> bool:
        """True when the schedule spans ``[start_s, end_s]`` (within ``tolerance_s``)."""
        return self.time_s[0] <= start_s + tolerance_s and self.time_s[-1] >= end_s - tolerance_s

    def to_text(self, comma: bool = False, precision: int = 9) -> str:
        """The schedule as a step file's text (see :func:`format_table`)."""
        return format_table(np.column_stack([self.time_s, self.level]), comma, precision)


def read_steps(path: str | Path, decimal_comma: bool | None = None) -> StepSchedule:
    """Read a step file ``ConfigN_PRT_amplitude_steps`` (time s, level).

    ``decimal_comma``: numbers written ``0,5``; None detects it.
    """
    path = Path(path)
    table = read_trc_table(path, 2, "step (time, level)", decimal_comma=decimal_comma)
    return StepSchedule(table[:, 0], table[:, 1], source=str(path))
