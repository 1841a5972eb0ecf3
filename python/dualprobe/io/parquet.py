"""Parquet recordings (``pyarrow.parquet``): one column per signal, one row per sample.

Numeric columns (integers, floats, decimals) are read as float64; a timestamp or duration time
column becomes seconds from its first value (its unit is the column type's). A null is a missing
reading, NaN (:mod:`dualprobe.io.missing`), except in a timestamp column, where it is refused
naming its row (1-based, as a table viewer numbers them); a column that is not numeric is
refused naming its type.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe.io.errors import InputError
from dualprobe.io.table import Table, resolve_columns
from dualprobe.io.timebase import seconds_from_first, stamp_resolution

__all__ = ["PARQUET_MAGIC", "read_parquet"]

PARQUET_MAGIC = b"PAR1"


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split())[:200] or type(exc).__name__


def _as_float(source: str, name: str, column: Any, *, time: bool) -> np.ndarray:
    import pyarrow as pa
    import pyarrow.compute as pc

    kind = column.type
    stamped = pa.types.is_timestamp(kind) or pa.types.is_duration(kind)
    if column.null_count and time and stamped:
        first = int(np.flatnonzero(column.is_null().to_numpy(zero_copy_only=False))[0])
        raise InputError(f"{source}: row {first + 1}, column {name!r}: missing time stamp (null)")
    if time and stamped:
        return seconds_from_first(column.cast(pa.int64()).to_numpy(), kind.unit)
    if pa.types.is_boolean(kind) or not (
        pa.types.is_integer(kind) or pa.types.is_floating(kind) or pa.types.is_decimal(kind)
    ):
        raise InputError(f"{source}: column {name!r} holds {kind}, not numbers")
    # a null is a missing reading: NaN (io.missing decides what it costs)
    values = pc.fill_null(pc.cast(column, pa.float64()), float("nan"))
    return np.asarray(values.to_numpy(), dtype=np.float64)


def read_parquet(
    path: str | os.PathLike[str], requested: list[str], *, time: str | None = None
) -> Table:
    """Read the requested columns (and the time column) of a Parquet file."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = Path(path)
    source = str(path)
    try:
        handle = pq.ParquetFile(path)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise InputError(f"{source}: not a readable Parquet file ({_one_line(exc)})") from None
    with handle:
        available = [
            name for name in handle.schema_arrow.names if not name.startswith("__index_level_")
        ]
        names = resolve_columns(source, available, requested, time=time)
        try:
            table = handle.read(columns=list(dict.fromkeys(names.values())))
        except (pa.ArrowException, OSError, ValueError) as exc:
            raise InputError(f"{source}: cannot read the Parquet data ({_one_line(exc)})") from None
    if table.num_rows == 0:
        raise InputError(f"{source}: no rows (columns: {', '.join(available)})")
    columns = {
        wanted: _as_float(source, actual, table.column(actual), time=wanted == time)
        for wanted, actual in names.items()
    }
    stamps = columns[time] if time else None
    if time and time not in requested:
        del columns[time]
    time_kind = table.column(names[time]).type if time else None
    timestamp = time_kind is not None and (
        pa.types.is_timestamp(time_kind) or pa.types.is_duration(time_kind)
    )
    notes = []
    if timestamp:
        notes.append(f"time column {names[time]!r} ({time_kind}): seconds from its first value")
    return Table(
        source=source,
        columns=columns,
        names=names,
        time=stamps,
        time_name=names[time] if time else None,
        time_unit="s" if timestamp else None,
        row_label=lambda row: f"row {row + 1}",
        notes=notes,
        resolution=(lambda: stamp_resolution(stamps)) if stamps is not None else (lambda: 0.0),
        fixed_unit=timestamp,
    )
