"""Reading and writing recordings, and the errors of bad input (exit 2) and failed estimation
(exit 3).

:func:`load_recording` reads CSV, Parquet and MDF4 (:mod:`~dualprobe.io.recording`; readers in
:mod:`~dualprobe.io.csv`, :mod:`~dualprobe.io.parquet`, :mod:`~dualprobe.io.mdf`) with the time
base rules of :mod:`~dualprobe.io.timebase`; :func:`load_columns` is its strict form (uniform
time only).
"""

from __future__ import annotations

from dualprobe.io.csv import write_columns
from dualprobe.io.errors import EstimationError, InputError
from dualprobe.io.missing import MISSING
from dualprobe.io.recording import FORMATS, Recording, detect_format, load_columns, load_recording
from dualprobe.io.timebase import TIME_UNITS, Gap

__all__ = [
    "FORMATS",
    "MISSING",
    "TIME_UNITS",
    "EstimationError",
    "Gap",
    "InputError",
    "Recording",
    "detect_format",
    "load_columns",
    "load_recording",
    "write_columns",
]
