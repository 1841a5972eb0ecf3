"""The diagnosis of a CSV recording and its JSON document."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable

from dualprobe.diagnose.result import Diagnosis
from dualprobe.diagnose.search import MIN_SAMPLES, diagnose
from dualprobe.io import InputError, load_recording
from dualprobe.models.stuck import refuse_stuck
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
    time_unit: str | None = None,
    flow_column: str | None = None,
    noise_std: float | tuple[float, float] | None = None,
    progress: Callable[[str], None] | None = None,
    window: tuple[float | None, float | None] | None = None,
    missing: str = "refuse",
) -> Diagnosis:
    """Load a recording (CSV, Parquet, MDF4: ``dualprobe.io.load_recording``; ``time_unit`` s,
    ms, us or min overrides the header's) and diagnose it; `flow_column`
    (values > 0) makes ``flow_dependence`` a candidate, `noise_std` (K) replaces the estimated
    noise of both signals (or gives (reference, measured))."""
    if input_column == output_column:
        raise InputError(f"--input and --output are the same column {input_column!r}")
    if flow_column is not None and flow_column in (input_column, output_column):
        raise InputError(f"the flow column {flow_column!r} is also --input or --output")
    names = [input_column, output_column] + ([flow_column] if flow_column else [])
    # the loader of characterise: clock jitter resampled, a few dropped rows bridged (each
    # said in a note), a gap refused naming it
    recording = load_recording(path, names, time=time or None, time_unit=time_unit,
                               sample_interval=sample_interval, min_rows=MIN_SAMPLES,
                               required=[flow_column] if flow_column else [], window=window,
                               missing=missing)
    recording.require_contiguous("diagnose")
    if flow_column:
        recording.require_positive(flow_column, f"--flow {flow_column!r} must be > 0")
    columns = recording.columns
    # the sensor only: a reference may be a setpoint, flat on its plateaus and stepping
    # between them, which the sensor follows (models/stuck.py's rules are for a lagging sensor)
    refuse_stuck([(output_column, columns[output_column], input_column,
                   columns[input_column])], recording.sample_interval, recording.t)
    try:
        result = diagnose(
            columns[input_column],
            columns[output_column],
            recording.sample_interval,
            time=recording.t,
            flow=columns[flow_column] if flow_column else None,
            noise_std=noise_std,
            progress=progress,
        )
        return dataclasses.replace(result, notes=recording.notes)
    except ValueError as exc:
        raise InputError(f"{path}: {exc}") from None


def write_json(diagnosis: Diagnosis, path: str | os.PathLike[str]) -> None:
    """Write the issue's JSON document (strict JSON: non-finite numbers become null)."""
    write_json_document(diagnosis.to_json_dict(), path)
