"""Format-independent loading of a recording: CSV, Parquet or MDF4 in, seconds and checked
float64 columns out (:func:`load_recording`), with the time base rules of
:mod:`dualprobe.io.timebase` (units, jitter resampled, dropped rows bridged, gaps split into
segments).

The format follows from the content (MDF4's ``MDF`` identification, Parquet's ``PAR1``
magic) and otherwise from the extension (``.mf4``/``.mdf``, ``.parquet``/``.pq``: a file
named so without the magic is refused); anything else is read as CSV text.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dualprobe.io.csv import read_csv
from dualprobe.io.errors import InputError
from dualprobe.io.mdf import MDF_MAGIC, read_mdf
from dualprobe.io.missing import MISSING, drop_missing
from dualprobe.io.parquet import PARQUET_MAGIC, read_parquet
from dualprobe.io.table import DEFAULT_TIME, Table
from dualprobe.io.timebase import (
    BRIDGE_ROWS,
    TIME_UNITS,
    Gap,
    TimeBase,
    analyse_time,
    resample_segments,
    split_unit,
    stamp_resolution,
    time_unit_factor,
    time_unit_of,
)

__all__ = ["FORMATS", "Recording", "detect_format", "load_columns", "load_recording"]

FORMATS = ("csv", "parquet", "mdf4")
_EXTENSIONS = {".mf4": "mdf4", ".mdf": "mdf4", ".parquet": "parquet", ".pq": "parquet"}
# An interval of this many seconds or more read from a column without a unit gets a note.
_LONG_INTERVAL = 5.0


@dataclass(frozen=True)
class Recording:
    """A loaded recording.

    ``t`` in seconds (uniform within each segment; across a gap it jumps), ``columns`` the
    requested columns (finite float64, same length), ``sample_interval`` in seconds,
    ``segments`` the contiguous uniform stretches as slices of the rows, ``gaps`` between
    them, ``notes`` one-line notes (unit read from the header, jitter resampled, gaps,
    dropped rows bridged, channels interpolated from another raster), ``source`` the file,
    ``format`` its format.
    """

    t: np.ndarray
    columns: dict[str, np.ndarray]
    sample_interval: float
    segments: tuple[slice, ...]
    gaps: tuple[Gap, ...]
    notes: tuple[str, ...]
    source: str
    format: str

    @property
    def contiguous(self) -> bool:
        return not self.gaps

    def require_contiguous(self, what: str) -> None:
        """Refuse (InputError, one line naming the gap) a record with a gap."""
        if not self.gaps:
            return
        longest = max(self.segments, key=lambda s: s.stop - s.start)
        more = f" and {len(self.gaps) - 1} more" if len(self.gaps) > 1 else ""
        # the segment by its times: its row numbers are not the file's once rows were dropped
        first, last = float(self.t[longest.start]), float(self.t[longest.stop - 1])
        raise InputError(
            f"{self.source}: {self.gaps[0]}{more}; {what} needs a record without gaps: give "
            f"--window {first:.10g}:{last:.10g} (the longest segment, {last - first:.6g} s) or "
            "cut the file at the gap"
        )

    def require_positive(self, column: str, what: str) -> None:
        """Refuse (InputError, one line) a column with values of 0 or below, naming how many,
        where, and the longest stretch above 0 as a ``--window`` (a flow column reads 0 while
        the engine is off)."""
        low = self.columns[column] <= 0.0
        if not low.any():
            return
        rows = np.flatnonzero(low)
        first, last = float(self.t[rows[0]]), float(self.t[rows[-1]])
        # the longest run of rows above 0: its bounds are the edges of the runs of low rows
        edges = np.flatnonzero(np.diff(np.concatenate(([1], low.view(np.int8), [1]))))
        starts, stops = edges[::2], edges[1::2]  # (low rows mark 1: runs of 0 between)
        hint = "cut those rows"
        if starts.size:
            k = int(np.argmax(stops - starts))
            if stops[k] - starts[k] >= 2:
                a, b = float(self.t[starts[k]]), float(self.t[stops[k] - 1])
                hint = (f"give --window {a:.10g}:{b:.10g} (the longest stretch above 0, "
                        f"{b - a:.6g} s) or cut those rows")
        where = f"t = {first:.6g} s" if rows.size == 1 else f"t = {first:.6g}-{last:.6g} s"
        raise InputError(
            f"{self.source}: column {column!r} is 0 or below on {rows.size} of {low.size} rows "
            f"({where}); {what}: {hint}"
        )


def detect_format(path: str | os.PathLike[str]) -> str:
    """'csv', 'parquet' or 'mdf4' from the file's first bytes, else its extension."""
    path = Path(path)
    head = b""
    if path.is_file():
        try:
            with path.open("rb") as handle:
                head = handle.read(8)
        except OSError as exc:
            raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    # "MDF     ", or "UnFinMF " for a file the logger did not finalise (asammdf reads both)
    if (head.startswith(MDF_MAGIC[:3]) and head[3:8].strip() == b"") or head.startswith(
        b"UnFinMF"
    ):
        return "mdf4"
    if head.startswith(PARQUET_MAGIC):
        return "parquet"
    expected = _EXTENSIONS.get(path.suffix.lower())
    if expected is not None and path.is_file():
        what = "an MDF4" if expected == "mdf4" else "a Parquet"
        raise InputError(f"{path}: not {what} file (its first bytes are {head[:8]!r})")
    return "csv"


def _read_table(
    path: Path, columns: list[str], time: str | None, raster: str | None
) -> tuple[Table, str]:
    kind = detect_format(path)
    if kind == "mdf4":
        return read_mdf(path, columns, time=time, raster=raster), kind
    if kind == "parquet":
        return read_parquet(path, columns, time=time), kind
    return read_csv(path, columns, time=time), kind


def _time_unit(table: Table, option: str | None) -> tuple[float, str | None]:
    """Factor to seconds and the note for a unit read from the file."""
    if option is not None:
        time_unit_factor(option)
    found = table.time_unit if table.fixed_unit else time_unit_of(table.time_name or "")
    if found is not None and option is not None and found != option:
        what = "the format's unit" if table.fixed_unit else "the unit in the header"
        raise InputError(
            f"{table.source}: --time-unit {option} conflicts with {what} ({found}) of time "
            f"column {table.time_name!r}"
        )
    unit = option or found or "s"
    note = None
    if option is None and found is not None and found != "s" and not table.fixed_unit:
        note = f"time column {table.time_name!r}: unit {found} read from the header"
    return TIME_UNITS[unit], note


def _check_finite(table: Table, columns: dict[str, np.ndarray]) -> None:
    """Refuse infinity (a wrong reading); NaN is a missing one (:mod:`dualprobe.io.missing`)."""
    for name, values in columns.items():
        bad = np.flatnonzero(np.isinf(values))
        if bad.size:
            first = int(bad[0])
            raise InputError(
                f"{table.source}: {table.row_label(first)}, column {table.names.get(name, name)!r}"
                f": non-finite value {float(values[first])!r}"
            )


def _window_rows(source: str, window: tuple[float | None, float | None], seconds: np.ndarray,
                 min_rows: int) -> np.ndarray:
    """The file rows from the first stamp at or after the window's start to the last at or
    before its end (a stamp that is NaN inside them stays: a missing reading)."""
    start, end = window
    # a bound written from a stamp (29.9) must take that stamp (29.900000000000002)
    low = -math.inf if start is None else start - 1e-9 * max(1.0, abs(start))
    high = math.inf if end is None else end + 1e-9 * max(1.0, abs(end))
    if start is not None and end is not None and not start < end:
        raise InputError(f"--window {start:g}:{end:g}: the start must come before the end")
    inside = np.flatnonzero((seconds >= low) & (seconds <= high))
    if inside.size < min_rows:
        finite = seconds[np.isfinite(seconds)]
        span = f"t = {finite[0]:.6g}-{finite[-1]:.6g} s" if finite.size else "no time stamps"
        raise InputError(
            f"{source}: --window {_bound(start)}:{_bound(end)} holds {inside.size} rows (need "
            f"at least {min_rows}); the record spans {span}"
        )
    return np.arange(int(inside[0]), int(inside[-1]) + 1)


def _bound(value: float | None) -> str:
    return "" if value is None else f"{value:g}"


def _name_missing(base: TimeBase, rows: np.ndarray, label: Callable[[int], str]) -> TimeBase:
    """Say which gaps are rows of the file without a reading in every column (their stamps
    are there: it is the readings that are missing)."""
    after = {label(int(k)): int(rows[k] - rows[k - 1] - 1) for k in range(1, rows.size)
             if rows[k] - rows[k - 1] > 1}
    gaps = tuple(
        dataclasses.replace(gap, cause=f"{after[gap.label]} rows without a reading in every "
                            "column") if gap.label in after else gap
        for gap in base.gaps
    )
    return dataclasses.replace(base, gaps=gaps)


def load_recording(
    path: str | os.PathLike[str],
    columns: Sequence[str],
    *,
    time: str | None = "t",
    time_unit: str | None = None,
    sample_interval: float | None = None,
    min_rows: int = 10,
    raster: str | None = None,
    strict: bool = False,
    required: Sequence[str] = (),
    window: tuple[float | None, float | None] | None = None,
    missing: str = "refuse",
) -> Recording:
    """Load columns of a recording in any supported format (CSV, Parquet, MDF4).

    Parameters
    ----------
    columns:
        The data columns (channels) to return; a column whose name is this followed by a unit
        in parentheses or brackets is found too.
    time:
        The time column (CSV, Parquet), or None / "" without one; then ``sample_interval`` is
        needed. MDF4 uses the master channel of the raster's group.
    time_unit:
        s, ms, us or min; default: the unit after the time column's name, else seconds.
    sample_interval:
        Seconds between rows when there is no time column; with one, a check.
    raster:
        MDF4: the channel whose group's time base is used (default: ``columns[0]``).
    strict:
        Refuse jitter, gaps and missing readings instead of resampling / splitting / dropping.
    required:
        Columns in which a missing reading (empty cell, NaN, null) is refused rather than
        dropped with its row (:mod:`dualprobe.io.missing`).
    window:
        (start, end) in seconds of the time column (None: the record's own): only the rows
        inside are read; a gap, a missing reading or jitter outside it does not matter.
    missing:
        "refuse" (default): a missing reading (empty cell, NaN, null, an MDF4 sample marked
        invalid) is an input error naming it; "bridge": its row is dropped and bridged like a
        row the logger lost (:mod:`dualprobe.io.missing`).

    Raises
    ------
    InputError
        With a one-line message naming the file and, where relevant, row and column.
    """
    path = Path(path)
    time = time or None
    if missing not in MISSING:
        raise InputError(f"missing must be one of {', '.join(MISSING)}, got {missing!r}")
    wanted = list(dict.fromkeys(columns))
    if not wanted:
        raise InputError("no columns requested")
    if sample_interval is not None and not (math.isfinite(sample_interval) and sample_interval > 0):
        raise InputError(f"sample interval must be finite and > 0, got {sample_interval!r}")
    table, kind = _read_table(path, wanted, time, raster)
    notes = list(table.notes)
    named = table.time_name if kind != "mdf4" else None  # MDF4: the masters are the time
    if time == DEFAULT_TIME and named and split_unit(named)[0] != time:
        notes.append(f"time column {named!r} (the file has no column {time!r}; "
                     "--time COL names another)")
    data = {name: table.columns[name] for name in wanted}
    size = next(iter(data.values())).size
    if table.time is not None:
        min_rows = max(min_rows, 2)
    if size < min_rows:
        raise InputError(f"{path}: too few data rows ({size}; need at least {min_rows})")
    stamps = table.time
    checked = data if stamps is None else {**data, time or "time": stamps}
    _check_finite(table, checked)
    if stamps is None and sample_interval is None:
        raise InputError(f"{path}: no time column; give the sample interval")
    ts_given = float(sample_interval or 1.0)
    factor, unit_note = (1.0, None) if table.time is None else _time_unit(table, time_unit)
    if unit_note:
        notes.append(unit_note)
    rows: np.ndarray | None = None  # the file's rows kept, when not all of them

    def label(row: int) -> str:
        return table.row_label(row if rows is None else int(rows[row]))

    if window is not None:
        seconds = np.arange(size) * ts_given if stamps is None else stamps * factor
        rows = _window_rows(str(path), window, seconds, min_rows)
        notes.append(
            f"window t = {seconds[rows[0]]:.6g}-{seconds[rows[-1]]:.6g} s: {label(0)} to "
            f"{label(rows.size - 1)}, {rows.size} of {size} rows"
        )
        data = {name: values[rows] for name, values in data.items()}
        stamps = None if stamps is None else stamps[rows]
        checked = data if stamps is None else {**data, time or "time": stamps}
    names = {**table.names, **({time or "time": table.time_name} if table.time_name else {})}
    dropped = drop_missing(str(path), checked, names, label, strict=strict,
                           bridge=missing == "bridge", required=required)
    if dropped is not None:
        kept = dropped.rows
        if kept.size < min_rows:
            raise InputError(
                f"{path}: too few rows with a reading in every column ({kept.size}; need at "
                f"least {min_rows})"
            )
        notes.append(dropped.note)
        data = {name: values[kept] for name, values in data.items()}
        stamps = None if stamps is None else stamps[kept]
        rows = kept if rows is None else rows[kept]
    if stamps is None:
        if rows is None:
            t = np.arange(size, dtype=np.float64) * ts_given
            return Recording(t, data, ts_given, (slice(0, size),), (), tuple(notes), str(path),
                             kind)
        # rows lost or cut without a time column: the row numbers are the clock
        stamps = rows.astype(np.float64) * ts_given
    resolution = table.resolution
    if rows is not None and not table.fixed_unit:  # the printed resolution of the rows kept
        kept_stamps = stamps
        resolution = lambda: stamp_resolution(kept_stamps)  # noqa: E731
    t = stamps * factor if factor != 1.0 else np.asarray(stamps, dtype=np.float64)
    time_name = table.time_name

    def where(row: int) -> str:
        return f"{path}: {label(row)}, column {time_name!r}"

    base = analyse_time(
        t,
        where,
        label=label,
        resolution=lambda: resolution() * factor,
        strict=strict,
    )
    if rows is not None and base.gaps:
        base = _name_missing(base, rows, label)
    segments = tuple(slice(start, stop) for start, stop in base.segments)
    stamped = size
    if not base.uniform:
        t, data, segments = resample_segments(t, data, base)
    if not base.regular:
        scatter = base.jitter
        notes.append(
            f"clock jitter: intervals scatter by up to {scatter * 1e3:.3g} ms "
            f"({scatter / base.interval * 100:.1f} % of {base.interval * 1e3:.6g} ms); resampled "
            "linearly onto a uniform grid"
        )
    if base.bridged:
        longest = max(base.bridged, key=lambda gap: gap.duration)
        count = len(base.bridged)
        notes.append(
            f"dropped rows: {count} interval{'s' if count > 1 else ''} of up to "
            f"{BRIDGE_ROWS} missing rows (longest: {longest}) bridged by linear "
            f"interpolation: {base.bridged_rows} of {t.size} rows interpolated "
            f"({100.0 * base.bridged_rows / t.size:.2g} %; {stamped} rows in the file)"
        )
    notes.extend(f"{gap}: the record is split there" for gap in base.gaps)
    if base.interval >= _LONG_INTERVAL and time_name and time_unit is None and unit_note is None:
        if not table.fixed_unit and time_unit_of(time_name or "") is None:
            notes.append(
                f"time column {time_name!r} read in seconds (interval {base.interval:.6g} s); "
                "give --time-unit if it is in ms, us or min"
            )
    if sample_interval is not None:
        tolerance = (1e-6 if base.regular else 1e-3) * base.interval
        if abs(sample_interval - base.interval) > tolerance:
            raise InputError(
                f"{path}: --sample-interval {sample_interval:g} disagrees with the time column "
                f"({base.interval:.10g})"
            )
    return Recording(
        t, data, base.interval, segments, base.gaps, tuple(notes), str(path), kind
    )


def load_columns(
    path: str | os.PathLike[str],
    columns: Sequence[str],
    *,
    time: str | None = "t",
    min_rows: int = 10,
    time_unit: str | None = None,
) -> tuple[np.ndarray | None, dict[str, np.ndarray], float | None]:
    """The strict loader: (time in s or None, {column: array}, sample interval or None).

    Any format; the time column must be uniform (no jitter, no gaps: see
    :func:`load_recording` for a loader that resamples jitter and splits at gaps).
    """
    time = time or None
    recording = load_recording(
        path,
        columns,
        time=time,
        time_unit=time_unit,
        sample_interval=None if time else 1.0,
        min_rows=min_rows,
        strict=True,
    )
    data = {name: recording.columns[name] for name in columns}
    if time is None:
        return None, data, None
    return recording.t, data, recording.sample_interval
