"""TRC phase-resonance test records: read, write, and find them in a folder.

The TRC layout lives in modules of one concept each; this module gathers their
public names, so ``from identification.measurements.records import Record``
keeps working:

* :mod:`~identification.measurements.trc_layout`: file names, data columns and
  reading the layout's text tables (through the one text-table reader,
  :mod:`~identification.measurements.text_table`);
* :mod:`~identification.measurements.steps`: the step schedule and its hold phases;
* :mod:`~identification.measurements.modes`: the linear modes at the panel points;
* :mod:`~identification.measurements.record`: the :class:`Record` type, reading and
  writing one;
* :mod:`~identification.measurements.discovery`: the records of a folder
  (:class:`Campaign`).
"""

from identification.measurements.discovery import Campaign, RecordFiles, is_trc_source
from identification.measurements.modes import Modes, read_modes
from identification.measurements.record import Record, read_record, write_record
from identification.measurements.steps import Hold, StepSchedule, read_steps
from identification.measurements.trc_layout import (
    CENTRE_POINT,
    DATA_COLUMNS,
    N_BASE_POINTS,
    N_PANEL_POINTS,
    record_name,
)

__all__ = [
    "CENTRE_POINT",
    "DATA_COLUMNS",
    "N_BASE_POINTS",
    "N_PANEL_POINTS",
    "Campaign",
    "Hold",
    "Modes",
    "Record",
    "RecordFiles",
    "StepSchedule",
    "is_trc_source",
    "read_modes",
    "read_record",
    "read_steps",
    "record_name",
    "write_record",
]
