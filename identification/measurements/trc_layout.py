"""The TRC file layout: file names, data columns, and reading its text tables.

The layout is the Tribomechadynamics Research Challenge (TRC) one, so measured
data and the virtual rig (:mod:`identification.rig`) go through the same path.

Files of one test configuration ``N`` (any extension, or none)::

    ConfigN_PRT_AssembA[_R]        data, one per assembly A (and run R)
    ConfigN_PRT_amplitude_steps    step schedule shared by the data files of config N
    ConfigN_linear_complex_modes   optional linear modes

Data file columns (blank, comma or semicolon separated, no header needed)::

    1       time (s), strictly increasing
    2-16    velocities (m/s) of the 15 panel points of the 5 × 3 grid
    17-18   velocities (m/s) of the 2 base points
    19      instantaneous frequency of the excitation (Hz)
    20      instantaneous phase of the excitation oscillator (deg)

Panel points are numbered row by row over 5 positions along the panel length
and 3 across its width, so point 8 is the centre (either way the grid is read).

Step file: two columns, time (s) and level (shaker voltage, V); see
:mod:`identification.measurements.steps`. Modes file: 16 rows, the mode shapes
at the panel points and the natural frequencies; see
:mod:`identification.measurements.modes`.

Every file is a text table (:mod:`identification.measurements.text_table`):
it may start with comment lines (``#`` or ``%``) and one header line of
non-numeric labels, both skipped; a decimal comma (``0,5;1,25``) is detected
or stated. A data file whose last line has no line break is taken for a file
cut short (its last number may be cut too): that line is left out, with a
warning. Anything else that is not a table of finite numbers (a missing or
extra column, a non-numeric, NaN or infinite cell, time stamps that repeat or
go back) is a ValueError naming the file, row and line.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from identification.measurements.text_table import read_numbers, sniff

__all__ = [
    "CENTRE_POINT",
    "DATA_COLUMNS",
    "N_BASE_POINTS",
    "N_PANEL_POINTS",
    "config_files",
    "name_part",
    "read_trc_table",
    "record_name",
]

N_PANEL_POINTS = 15
N_BASE_POINTS = 2
#: 1-based number of the panel centre point on the 5 × 3 grid.
CENTRE_POINT = 8
#: Column names of a data file, in file order.
DATA_COLUMNS: tuple[str, ...] = (
    "time_s",
    *(f"panel{p:02d}_m_s" for p in range(1, N_PANEL_POINTS + 1)),
    *(f"base{p}_m_s" for p in range(1, N_BASE_POINTS + 1)),
    "frequency_hz",
    "phase_deg",
)
#: Where the panel and base velocities are among the data columns.
PANEL = slice(1, 1 + N_PANEL_POINTS)
BASE = slice(PANEL.stop, PANEL.stop + N_BASE_POINTS)

_ID = r"[A-Za-z0-9-]+"
_EXT = r"(?:\.[^.]*)?"
DATA_RE = re.compile(
    rf"^Config(?P<config>{_ID})_PRT_Assemb(?P<assembly>{_ID})(?:_(?P<run>{_ID}))?{_EXT}$"
)
_SHARED_RE = {
    "steps": re.compile(rf"^Config(?P<config>{_ID})_PRT_amplitude_steps{_EXT}$"),
    "modes": re.compile(rf"^Config(?P<config>{_ID})_linear_complex_modes{_EXT}$"),
}


def record_name(config: str | int, assembly: str | int, run: str | int | None = None) -> str:
    """The TRC file stem ``Config{config}_PRT_Assemb{assembly}[_{run}]``."""
    name = f"Config{config}_PRT_Assemb{assembly}" + (f"_{run}" if run is not None else "")
    if not DATA_RE.match(name):
        raise ValueError(f"not a valid TRC record name: {name!r} (use letters, digits and -)")
    return name


def name_part(name: str, part: str) -> str | None:
    """``config``, ``assembly`` or ``run`` of a data file's name (None when it has none)."""
    match = DATA_RE.match(name)
    return match[part] if match else None


def config_files(folder: Path) -> dict[str, dict[str, Path]]:
    """Step and modes files (``steps``, ``modes``) of each configuration in ``folder``."""
    found: dict[str, dict[str, Path]] = {}
    for path in sorted(folder.iterdir()):
        for kind, pattern in _SHARED_RE.items():
            match = pattern.match(path.name)
            if match and path.is_file():
                entry = found.setdefault(match["config"], {})
                if kind in entry:
                    raise ValueError(
                        f"{folder}: two {kind} files for config {match['config']}: "
                        f"{entry[kind].name} and {path.name}"
                    )
                entry[kind] = path
    return found


def read_trc_table(
    path: Path,
    columns: int,
    what: str,
    decimal_comma: bool | None = None,
    progress: bool = False,
    complete_lines: bool = False,
) -> np.ndarray:
    """A TRC text table of ``columns`` numbers per row (see the module notes), read-only.

    ``what`` names the file's kind in errors; ``complete_lines`` leaves out a
    last line without a line break, with a warning.
    """
    if not path.is_file():
        raise ValueError(f"{path}: {what} file not found")
    layout = sniff(path, decimal_comma)
    if layout.columns != columns:
        raise ValueError(
            f"{path}: found {layout.columns} columns, expected {columns} ({what} layout)"
        )
    return read_numbers(path, layout, columns, progress=progress, complete_lines=complete_lines)
