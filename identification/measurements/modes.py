"""Linear modes of a test configuration, at the panel points (or at any sensors).

Modes file ``ConfigN_linear_complex_modes``: 16 rows; rows 1-15 the mode
shapes at the panel points (one column per mode, column 1 the first bending
mode), row 16 the natural frequencies (Hz). A mode-shape file of a column
layout's sensors (``--mode-shapes``) is the same with one row per sensor, in
the order of the response columns, then the frequencies. Entries are real numbers or complex
numbers written ``a+bj`` or ``a+bi`` (the MATLAB form; no blanks inside a
number); with ``pairs=True`` each mode is instead a pair of columns, real part
then imaginary part. Comment lines, a header of labels, the delimiter and a
decimal comma are read as in every TRC file
(:mod:`identification.measurements.trc_layout`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from identification.measurements.series import frozen_array
from identification.measurements.text_table import sniff
from identification.measurements.trc_layout import N_PANEL_POINTS

__all__ = ["Modes", "read_modes"]


@dataclass(frozen=True, eq=False)
class Modes:
    """Linear modes at the measurement points: ``shapes`` (points, m) and ``frequencies_hz`` (m,).

    The TRC layout's are at its 15 panel points
    (:class:`~identification.measurements.record.Record` checks it).
    """

    shapes: np.ndarray
    frequencies_hz: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        where = self.source or "modes"
        shapes = frozen_array(self.shapes, dtype=complex)
        freqs = frozen_array(self.frequencies_hz)
        if shapes.ndim == 1:
            shapes = frozen_array(shapes[:, None], dtype=complex)
        if shapes.shape[0] < 1 or freqs.shape != (shapes.shape[1],):
            raise ValueError(
                f"{where}: expected shape rows and one frequency per mode, "
                f"got shapes {shapes.shape} and frequencies {freqs.shape}"
            )
        if not (np.isfinite(shapes).all() and np.isfinite(freqs).all()) or (freqs <= 0).any():
            raise ValueError(f"{where}: mode shapes must be finite and frequencies > 0")
        object.__setattr__(self, "shapes", shapes)
        object.__setattr__(self, "frequencies_hz", freqs)

    @property
    def first_bending(self) -> np.ndarray:
        """Shape of the first bending mode (column 1)."""
        return self.shapes[:, 0]

    def to_text(self, comma: bool = False, precision: int = 9) -> str:
        """The modes as a modes file's text (``a+bj`` entries, ``%.{precision}e``)."""
        sep = "," if comma else " "
        rows = [
            sep.join(f"{z.real:.{precision}e}{z.imag:+.{precision}e}j" for z in row)
            for row in self.shapes
        ]
        rows.append(sep.join(f"{f:.{precision}e}" for f in self.frequencies_hz))
        return "\n".join(rows) + "\n"


def read_modes(
    path: str | Path,
    pairs: bool = False,
    decimal_comma: bool | None = None,
    points: int | None = N_PANEL_POINTS,
) -> Modes:
    """Read a modes file ``ConfigN_linear_complex_modes`` (see the module notes).

    Parameters
    ----------
    path
        The file.
    pairs
        Columns are (real, imaginary) pairs instead of one complex number each.
    decimal_comma
        Numbers written ``0,5``; None detects it.
    points
        Shape rows expected (the TRC layout's 15 panel points); None takes every
        row but the last (a mode-shape file of a column layout's sensors).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: modes file not found")
    layout = sniff(path, decimal_comma)
    rows: list[list[complex]] = []
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        for number, line in enumerate(fh, start=1):
            if number <= layout.skip or not line.strip():
                continue
            fields = layout.split(line)
            if len(fields) != layout.columns:
                raise ValueError(
                    f"{path}: line {number} has {len(fields)} columns, expected {layout.columns}"
                )
            try:
                rows.append([layout.complex_number(f) for f in fields])
            except ValueError:
                raise ValueError(f"{path}: line {number}: non-numeric value in {fields}") from None
    expected = len(rows) if points is None else points + 1
    if len(rows) != expected or len(rows) < 2:
        raise ValueError(
            f"{path}: found {len(rows)} rows, expected {expected if points else 'at least 2'} "
            f"({points or 'one or more'} mode-shape rows and one frequency row)"
        )
    table = np.array(rows)
    if pairs:
        if table.shape[1] % 2 or np.any(table.imag):
            raise ValueError(f"{path}: pairs=True needs an even number of real columns")
        table = table.real[:, 0::2] + 1j * table.real[:, 1::2]
    freqs = table[-1]
    if np.any(freqs.imag):
        raise ValueError(f"{path}: frequency row (row {len(rows)}) must be real")
    return Modes(table[:-1], freqs.real, source=str(path))
