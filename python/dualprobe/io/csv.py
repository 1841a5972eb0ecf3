"""CSV recordings: a fast columnar reader (``pyarrow.csv``) with the exact messages of a
line-by-line reader for anything it refuses.

Every problem with an input file is reported as an :class:`InputError` whose message is a single
line naming the file and, where it applies, the line of the file (1-based, header is line 1, as a
text editor shows it) and the column. The delimiter is a comma, or a semicolon / tab when the
header line has none; blank lines and whitespace around cells are ignored; a units row under
the header (``s,degC,degC``) is refused (put the unit in the header: ``Time (ms)``). With a
semicolon or tab delimiter the numbers may have a decimal comma (``512,37``: the European
export, told from the first data row). A time column of ISO 8601 date-times
(``2026-12-01T10:00:00.125``, a space for the ``T``, a comma for the point, a zone ``Z`` /
``+01:00`` on every stamp or on none) becomes seconds from its first stamp, as a Parquet
timestamp column does.

Fast path: the header is read here, the body by ``pyarrow.csv`` straight into float64 columns
(no NaN-by-default strings; an empty cell is NaN, a missing reading: see
:mod:`dualprobe.io.missing`); anything it refuses (text, a ragged row, a whitespace-only
line) sends the file through the line-by-line reader, which names the line and column. File
line numbers for later messages (time, non-finite values) are counted only when a message
needs them.
"""

from __future__ import annotations

import csv
import io as _io
import math
import os
import re
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe.io.errors import InputError
from dualprobe.io.table import Table, resolve_columns
from dualprobe.io.timebase import IRREGULAR_TIME_TOLERANCE, seconds_from_first, stamp_resolution

__all__ = [
    "IRREGULAR_TIME_TOLERANCE",
    "read_csv",
    "read_csv_table",
    "write_columns",
]

_BOM = b"\xef\xbb\xbf"
_NON_BLANK = re.compile(rb"\S")
_DECIMAL_COMMA = re.compile(r"[+-]?\d*,\d+([eE][+-]?\d+)?")
_STAMP = re.compile(r"\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(:\d{2}([.,]\d+)?)?"
                    r"(?P<zone>Z|[+-]\d{2}:?\d{2})?")
_STAMP_NOTE = "ISO 8601 date and time"


def _one_line(text: str, limit: int = 60) -> str:
    """Quote a cell for an error message: one line, bounded length."""
    text = text.replace("\r", "\\r").replace("\n", "\\n")
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return repr(text)


def _read_bytes(path: Path) -> bytes:
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a CSV file")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if _NON_BLANK.search(raw) is None:
        raise InputError(f"{path}: file is empty")
    offset = raw.find(b"\x00")
    if offset >= 0:
        raise InputError(f"{path}: binary data (NUL byte at offset {offset}), not a CSV text file")
    try:
        raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{path}: not UTF-8 text (undecodable byte at offset {exc.start}), not a CSV file"
        ) from None
    return raw


def _delimiter(header_line: str) -> str:
    """Comma, unless the header line has none but has semicolons or tabs (locale exports)."""
    if "," in header_line:
        return ","
    for candidate in (";", "\t"):
        if candidate in header_line:
            return candidate
    return ","


def _decimal_comma(delimiter: str, cells: list[str]) -> bool:
    """Whether the numbers have a decimal comma: a semicolon or tab delimiter and a cell of
    the first data row written like ``512,37``."""
    return delimiter != "," and any(_DECIMAL_COMMA.fullmatch(cell) for cell in cells)


def _stamp_type(cell: str) -> Any:
    """The Arrow type of a time column whose first cell is ``cell``: a timestamp (zoned: UTC)
    for an ISO 8601 date-time, else None (numbers)."""
    import pyarrow as pa

    found = _STAMP.fullmatch(cell)
    if found is None:
        return None
    return pa.timestamp("ns", tz="UTC" if found.group("zone") else None)


def _stamp_seconds(path: Path, name: str, column: Any, file_line: Any) -> np.ndarray:
    """A parsed timestamp column (Arrow, nulls for empty cells) as seconds from its first
    stamp; an empty cell is refused naming its line."""
    import pyarrow as pa

    ticks = column.cast(pa.int64())
    if ticks.null_count:
        valid = np.concatenate([chunk.is_valid().to_numpy(zero_copy_only=False)
                                for chunk in ticks.chunks])
        first = int(np.flatnonzero(~valid)[0])
        raise InputError(f"{path}: line {file_line(first)}, column {name!r}: missing time stamp")
    return seconds_from_first(np.concatenate([chunk.to_numpy() for chunk in ticks.chunks]),
                              "ns")


def _check_header(path: Path, header: list[str], line: int) -> None:
    if any(not name for name in header):
        position = header.index("") + 1
        raise InputError(
            f"{path}: line {line}: header has an empty column name at position {position}"
        )
    seen: set[str] = set()
    for name in header:
        if name in seen:
            raise InputError(f"{path}: line {line}: header names column {name!r} twice")
        seen.add(name)


def read_csv_table(path: str | os.PathLike[str]) -> tuple[list[str], list[list[str]], list[int]]:
    """Read a CSV file with a header row, line by line.

    Returns (header, data rows of stripped cells, file line number of each data row). Blank
    lines are skipped; whitespace around cells is ignored; the delimiter is a comma, or a
    semicolon / tab when the header has no comma. Raises :class:`InputError`.
    """
    header, rows, lines, _ = _read_table(Path(path))
    return header, rows, lines


def _read_table(path: Path) -> tuple[list[str], list[list[str]], list[int], str]:
    """:func:`read_csv_table` and the delimiter it read with."""
    text = _read_bytes(path).decode("utf-8-sig")
    header_line = next((line for line in text.splitlines() if line.strip()), "")
    delimiter = _delimiter(header_line)
    rows: list[list[str]] = []
    lines: list[int] = []
    reader = csv.reader(_io.StringIO(text, newline=""), delimiter=delimiter)
    try:
        for row in reader:
            cells = [cell.strip() for cell in row]
            if any(cells):
                rows.append(cells)
                lines.append(reader.line_num)
    except csv.Error as exc:
        raise InputError(f"{path}: line {reader.line_num}: malformed CSV ({exc})") from None
    if not rows:
        raise InputError(f"{path}: file is empty")
    header = rows[0]
    _check_header(path, header, lines[0])
    if len(rows) == 1:
        raise InputError(f"{path}: header only, no data rows (header: {', '.join(header)})")
    return header, rows[1:], lines[1:], delimiter


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _parse_stamps(path: Path, name: str, stamp: Any, cells: list[str], lines: list[int]
                  ) -> np.ndarray:
    """A time column of ISO 8601 date-times (``stamp`` its type) as seconds from the first."""
    import pyarrow as pa

    for cell, line in zip(cells, lines, strict=True):
        found = _STAMP.fullmatch(cell)
        where = f"{path}: line {line}, column {name!r}"
        if not cell:
            raise InputError(f"{where}: missing time stamp")
        if found is None:
            raise InputError(f"{where}: not an {_STAMP_NOTE}: {_one_line(cell)}")
        if bool(found.group("zone")) != (stamp.tz is not None):
            raise InputError(f"{where}: {_one_line(cell)} has {'no ' if stamp.tz else ''}zone "
                             "where the first stamp has " + ("one" if stamp.tz else "none")
                             + "; give every stamp a zone or none")
    # ISO 8601 allows a decimal comma in the seconds (Arrow's parser does not)
    text = pa.array([cell.replace(",", ".") for cell in cells])
    return _stamp_seconds(path, name, pa.chunked_array([text.cast(stamp)]),
                          lambda row: lines[row])


def _parse_column(
    path: Path, name: str, index: int, data: list[list[str]], lines: list[int],
    decimal_comma: bool = False,
) -> np.ndarray:
    cells = [row[index] or "nan" for row in data]  # an empty cell is a missing reading
    if decimal_comma:
        cells = [cell.replace(",", ".") for cell in cells]
    try:
        return np.array(cells, dtype=np.float64)
    except ValueError:
        pass
    # Slow path only to say exactly which cell is wrong.
    for position, (cell, line) in enumerate(zip(cells, lines, strict=True)):
        where = f"{path}: line {line}, column {name!r}"
        if not _is_number(cell):
            row = data[position]
            if position == 0 and not any(_is_number(c) for c in row):
                raise InputError(
                    f"{path}: line {line}: a units row under the header "
                    f"({', '.join(row)}); remove it and put units in the header, e.g. "
                    "'Time (ms)'"
                )
            raise InputError(f"{where}: not a number: {_one_line(cell)}") from None
    raise AssertionError("unreachable: numpy and float() accept the same strings")


def _slow_columns(
    path: Path, requested: list[str], time: str | None
) -> tuple[dict[str, str], dict[str, np.ndarray], list[int], bool]:
    """(names, columns, file lines, whether the time column held date-times)."""
    header, data, lines, delimiter = _read_table(path)
    names = resolve_columns(str(path), header, requested, time=time)
    width = len(header)
    for row, line in zip(data, lines, strict=True):
        if len(row) != width:
            raise InputError(f"{path}: line {line}: {len(row)} fields, header has {width}")
    comma = _decimal_comma(delimiter, data[0])
    stamp = _stamp_type(data[0][header.index(names[time])]) if time else None
    parsed = {
        wanted: (_parse_stamps(path, actual, stamp, [row[header.index(actual)] for row in data],
                               lines)
                 if stamp is not None and wanted == time else
                 _parse_column(path, actual, header.index(actual), data, lines, comma))
        for wanted, actual in names.items()
    }
    return names, parsed, lines, stamp is not None


def _split_header(raw: bytes) -> tuple[str, int, int]:
    """(header line text, its file line number, byte offset of the body)."""
    position = len(_BOM) if raw.startswith(_BOM) else 0
    line = 1
    while True:
        end = raw.find(b"\n", position)
        stop = len(raw) if end < 0 else end
        text = raw[position:stop].decode("utf-8").rstrip("\r")
        if text.strip():
            return text, line, (len(raw) if end < 0 else end + 1)
        position = stop + 1
        line += 1


def _data_lines(raw: bytes, body: int, first_line: int) -> np.ndarray:
    """File line numbers of the non-blank lines of the body (the fast path's rows)."""
    lines = raw[body:].split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    blank = np.fromiter((not line.strip() for line in lines), dtype=bool, count=len(lines))
    return first_line + 1 + np.flatnonzero(~blank)


def _float64(column: Any) -> np.ndarray:
    """A float64 column as one NumPy array, nulls (empty cells) as NaN, read from its chunks'
    data buffers (pyarrow's ``to_numpy`` imports pandas on the way: ~50 MB and 0.3 s per run)."""
    parts = []
    for chunk in column.chunks:
        values = np.frombuffer(chunk.buffers()[1], dtype=np.float64, count=len(chunk),
                               offset=8 * chunk.offset)
        if chunk.null_count:
            valid = np.unpackbits(np.frombuffer(chunk.buffers()[0], dtype=np.uint8),
                                  bitorder="little")[chunk.offset : chunk.offset + len(chunk)]
            values = np.where(valid.astype(bool), values, np.nan)
        parts.append(values)
    return np.concatenate(parts) if parts else np.zeros(0)


def _first_cells(raw: bytes, body: int, delimiter: str) -> list[str]:
    """The stripped cells of the body's first non-blank line."""
    for line in raw[body:].split(b"\n", 64):
        text = line.decode("utf-8").strip()
        if text:
            return [cell.strip() for cell in next(csv.reader([text], delimiter=delimiter))]
    return []


def _fast_columns(
    path: Path, raw: bytes, requested: list[str], time: str | None
) -> tuple[dict[str, str], dict[str, np.ndarray], int, int, bool] | None:
    """The columns through pyarrow (and whether the time column held date-times), or None
    when the line-by-line reader must decide."""
    import pyarrow as pa
    import pyarrow.csv as pacsv

    header_text, header_line, body = _split_header(raw)
    delimiter = _delimiter(header_text)
    header = [cell.strip() for cell in next(csv.reader([header_text], delimiter=delimiter))]
    _check_header(path, header, header_line)
    if _NON_BLANK.search(raw, body) is None:
        raise InputError(f"{path}: header only, no data rows (header: {', '.join(header)})")
    names = resolve_columns(str(path), header, requested, time=time)
    actual = list(dict.fromkeys(names.values()))
    first = _first_cells(raw, body, delimiter)
    if len(first) != len(header):
        return None  # a ragged row: the line-by-line reader names it
    first_stamp = first[header.index(names[time])] if time else ""
    stamp = _stamp_type(first_stamp) if time else None
    if stamp is not None and "," in first_stamp:
        return None  # seconds with a decimal comma: the line-by-line reader parses them
    types = {name: pa.float64() for name in actual}
    if stamp is not None:
        types[names[time]] = stamp
    try:
        table = pacsv.read_csv(
            pa.py_buffer(memoryview(raw)[body:]),
            read_options=pacsv.ReadOptions(column_names=header),
            parse_options=pacsv.ParseOptions(delimiter=delimiter),
            convert_options=pacsv.ConvertOptions(
                column_types=types,
                decimal_point="," if _decimal_comma(delimiter, first) else ".",
                include_columns=actual,
                # an empty cell is a missing reading (NaN; io.missing decides what it costs)
                null_values=[""],
                strings_can_be_null=False,
                quoted_strings_can_be_null=False,
            ),
            # the system allocator hands the parse buffers back when the table goes; the
            # default (jemalloc/mimalloc) pool kept ~120 MB of a one-hour 100 Hz file
            memory_pool=pa.system_memory_pool(),
        )
    except (pa.ArrowInvalid, pa.ArrowTypeError, pa.ArrowNotImplementedError):
        return None
    if table.num_rows == 0:
        return None

    def file_line(row: int) -> int:
        return int(_data_lines(raw, body, header_line)[row])

    columns = {wanted: (_stamp_seconds(path, name, table.column(name), file_line)
                        if stamp is not None and wanted == time else _float64(table.column(name)))
               for wanted, name in names.items()}
    return names, columns, header_line, body, stamp is not None


def read_csv(
    path: str | os.PathLike[str], requested: list[str], *, time: str | None = None
) -> Table:
    """Read the requested columns (and the time column) of a CSV file with a header row."""
    path = Path(path)
    raw = _read_bytes(path)
    fast = _fast_columns(path, raw, requested, time)
    lines_cache: list[np.ndarray] = []
    if fast is not None:
        names, columns, header_line, body, stamped = fast

        def file_line(row: int) -> int:
            if not lines_cache:
                lines_cache.append(_data_lines(raw, body, header_line))
            return int(lines_cache[0][row])
    else:
        names, columns, lines, stamped = _slow_columns(path, requested, time)
        lines_cache.append(np.asarray(lines))

        def file_line(row: int) -> int:
            return int(lines_cache[0][row])

    def row_label(row: int) -> str:
        return f"line {file_line(row)}"

    stamps = columns[time] if time else None
    if time and time not in requested:
        del columns[time]
    return Table(
        source=str(path),
        columns=columns,
        names=names,
        time=stamps,
        time_name=names[time] if time else None,
        time_unit="s" if stamped else None,
        row_label=row_label,
        notes=([f"time column {names[time]!r} ({_STAMP_NOTE}): seconds from its first value"]
               if stamped and time else []),
        resolution=(lambda: stamp_resolution(stamps)) if stamps is not None else (lambda: 0.0),
        fixed_unit=stamped,
    )


def write_columns(path: str | os.PathLike[str], columns: dict[str, np.ndarray]) -> None:
    """Write equal-length arrays as a CSV with a header row; NaN is written as ``nan``."""
    path = Path(path)
    names = list(columns)
    arrays = [np.asarray(columns[name], dtype=np.float64) for name in names]
    lengths = {a.shape for a in arrays}
    if len(lengths) != 1 or any(a.ndim != 1 for a in arrays):
        raise ValueError("write_columns: all columns must be 1-D arrays of equal length")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, cannot write the CSV file there")
    if path.parent and not path.parent.exists():
        raise InputError(f"{path}: directory {path.parent} does not exist")
    table = np.column_stack(arrays)
    try:
        with path.open("w", newline="") as handle:
            handle.write(",".join(names) + "\n")
            for row in table.tolist():
                # repr is the shortest text that reads back to the same float (round trip).
                handle.write(",".join(repr(v) if math.isfinite(v) else "nan" for v in row) + "\n")
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None
