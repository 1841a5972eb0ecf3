"""Reading and writing recordings, and the errors of bad input (exit 2) and failed estimation
(exit 3). Readers of further formats go beside :mod:`dualprobe.io.csv`."""

from __future__ import annotations

from dualprobe.io.csv import load_columns, write_columns
from dualprobe.io.errors import EstimationError, InputError

__all__ = ["EstimationError", "InputError", "load_columns", "write_columns"]
