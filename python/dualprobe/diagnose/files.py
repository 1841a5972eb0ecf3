"""The diagnosis of a CSV recording and its JSON document."""

from __future__ import annotations

import math
import os
from collections.abc import Callable

from dualprobe.diagnose.result import Diagnosis
from dualprobe.diagnose.search import MIN_SAMPLES, diagnose
from dualprobe.io import InputError, load_columns
from dualprobe.report.json import write_json as write_json_document

__all__ = [
    "diagnose_file",
    "write_json",
]


def diagnose_file(
    path: str | os.PathLike[str],
    *,
    input_column: str = "T_ref",
    output_column: str = "T_m",
    time: str | None = "t",
    sample_interval: float | None = None,
    progress: Callable[[str], None] | None = None,
) -> Diagnosis:
    """Load a CSV recording (``dualprobe.io.load_columns``) and diagnose it."""
    if input_column == output_column:
        raise InputError(f"--input and --output are the same column {input_column!r}")
    t, columns, interval = load_columns(
        path, [input_column, output_column], time=time or None, min_rows=MIN_SAMPLES
    )
    if interval is None:
        if sample_interval is None:
            raise InputError(f"{path}: no time column; give the sample interval")
        interval = sample_interval
    elif sample_interval is not None and not math.isclose(interval, sample_interval, rel_tol=1e-6):
        raise InputError(
            f"{path}: time column gives sample interval {interval:g} s, "
            f"--sample-interval says {sample_interval:g} s"
        )
    try:
        return diagnose(
            columns[input_column], columns[output_column], interval, time=t, progress=progress
        )
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None


def write_json(diagnosis: Diagnosis, path: str | os.PathLike[str]) -> None:
    """Write the issue's JSON document (strict JSON: non-finite numbers become null)."""
    write_json_document(diagnosis.to_json_dict(), path)
