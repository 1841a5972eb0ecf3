"""CSV loading and validation for recordings.

Every problem with an input file is reported as an :class:`InputError` whose message is a single
line naming the file and, where it applies, the line of the file (1-based, header is line 1, as a
text editor shows it) and the column.
"""

from __future__ import annotations

import csv
import io as _io
import math
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dualprobe.io.errors import InputError

__all__ = [
    "load_columns",
    "read_csv_table",
    "write_columns",
]

# Relative deviation of any sample interval from the median interval above which the time base
# is called irregular: well above float64 rounding of typical time stamps (~1e-12 relative), far
# below any real sampling glitch.
IRREGULAR_TIME_TOLERANCE = 1e-6


def _one_line(text: str, limit: int = 60) -> str:
    """Quote a cell for an error message: one line, bounded length."""
    text = text.replace("\r", "\\r").replace("\n", "\\n")
    if len(text) > limit:
        text = text[: limit - 3] + "..."
    return repr(text)


def _read_text(path: Path) -> str:
    if not path.exists():
        raise InputError(f"{path}: no such file")
    if path.is_dir():
        raise InputError(f"{path}: is a directory, not a CSV file")
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror or exc})") from None
    if not raw.strip():
        raise InputError(f"{path}: file is empty")
    offset = raw.find(b"\x00")
    if offset >= 0:
        raise InputError(f"{path}: binary data (NUL byte at offset {offset}), not a CSV text file")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise InputError(
            f"{path}: not UTF-8 text (undecodable byte at offset {exc.start}), not a CSV file"
        ) from None
    return text


def _delimiter(text: str) -> str:
    """Comma, unless the header line has none but has semicolons or tabs (locale exports)."""
    header = next((line for line in text.splitlines() if line.strip()), "")
    if "," in header:
        return ","
    for candidate in (";", "\t"):
        if candidate in header:
            return candidate
    return ","


def read_csv_table(path: str | os.PathLike[str]) -> tuple[list[str], list[list[str]], list[int]]:
    """Read a CSV file with a header row.

    Returns (header, data rows of stripped cells, file line number of each data row). Blank
    lines are skipped; whitespace around cells is ignored; the delimiter is a comma, or a
    semicolon / tab when the header has no comma. Raises :class:`InputError`.
    """
    path = Path(path)
    text = _read_text(path)
    rows: list[list[str]] = []
    lines: list[int] = []
    reader = csv.reader(_io.StringIO(text, newline=""), delimiter=_delimiter(text))
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
    if any(not name for name in header):
        position = header.index("") + 1
        raise InputError(
            f"{path}: line {lines[0]}: header has an empty column name at position {position}"
        )
    seen: set[str] = set()
    for name in header:
        if name in seen:
            raise InputError(f"{path}: line {lines[0]}: header names column {name!r} twice")
        seen.add(name)
    if len(rows) == 1:
        raise InputError(f"{path}: header only, no data rows (header: {', '.join(header)})")
    return header, rows[1:], lines[1:]


def _check_widths(path: Path, data: list[list[str]], lines: list[int], width: int) -> None:
    for row, line in zip(data, lines, strict=True):
        if len(row) != width:
            raise InputError(f"{path}: line {line}: {len(row)} fields, header has {width}")


def column_cells(data: list[list[str]], index: int) -> list[str]:
    return [row[index] for row in data]


def _parse_column(
    path: Path, name: str, index: int, data: list[list[str]], lines: list[int]
) -> np.ndarray:
    cells = column_cells(data, index)
    try:
        values = np.array(cells, dtype=np.float64)
    except ValueError:
        # Slow path only to say exactly which cell is wrong.
        for cell, line in zip(cells, lines, strict=True):
            where = f"{path}: line {line}, column {name!r}"
            if cell == "":
                raise InputError(f"{where}: empty value") from None
            try:
                float(cell)
            except ValueError:
                raise InputError(f"{where}: not a number: {_one_line(cell)}") from None
        raise  # unreachable: numpy and float() accept the same strings
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        first = int(bad[0])
        raise InputError(
            f"{path}: line {lines[first]}, column {name!r}: non-finite value "
            f"{_one_line(cells[first])}"
        )
    return values


def _printed_resolution(cells: list[str]) -> float:
    """Resolution the time stamps were printed with: the finest last-digit unit among them.

    E.g. 1e-4 for stamps written with "%.4f". Writers that strip trailing zeros make some
    stamps look coarser ("0.5"), so the finest unit is the one that tells the resolution.
    """
    finest = math.inf
    for cell in cells:
        mantissa, _, exponent = cell.lower().partition("e")
        decimals = len(mantissa.partition(".")[2])
        try:
            shift = int(exponent) if exponent else 0
        except ValueError:
            continue
        finest = min(finest, 10.0 ** (shift - decimals))
    return finest if math.isfinite(finest) else 0.0


def _check_time(path: Path, name: str, t: np.ndarray, cells: list[str], lines: list[int]) -> float:
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0.0)
    if bad.size:
        later = int(bad[0]) + 1  # index of the later sample of the offending pair
        raise InputError(
            f"{path}: line {lines[later]}, column {name!r}: time not strictly increasing "
            f"({t[later - 1]:.10g} then {t[later]:.10g})"
        )
    interval = float(np.median(dt))
    # Allowed deviation: the relative tolerance, plus float64 resolution at the largest time
    # stamp (absolute clocks such as Unix time), plus the resolution the stamps were printed with.
    allowed = IRREGULAR_TIME_TOLERANCE * interval + 8.0 * np.spacing(np.max(np.abs(t)))
    irregular = np.flatnonzero(np.abs(dt - interval) > allowed)
    if irregular.size:
        # Two stamps rounded to the printed resolution make an interval off by up to one unit,
        # and the median interval is off by as much.
        allowed = allowed + 2.0 * _printed_resolution(cells)
        irregular = np.flatnonzero(np.abs(dt - interval) > allowed)
    if irregular.size:
        later = int(irregular[0]) + 1
        raise InputError(
            f"{path}: line {lines[later]}, column {name!r}: irregular time step "
            f"{dt[later - 1]:.10g} (median interval {interval:.10g}); "
            "resample to a uniform grid first"
        )
    # The mean over the whole record is the least-noisy estimate of the interval once it is
    # known to be regular.
    return float((t[-1] - t[0]) / (t.size - 1))


def load_columns(
    path: str | os.PathLike[str],
    columns: Sequence[str],
    *,
    time: str | None = "t",
    min_rows: int = 10,
) -> tuple[np.ndarray | None, dict[str, np.ndarray], float | None]:
    """Load numeric columns of a CSV file with a header row, validating everything.

    Parameters
    ----------
    path:
        CSV file with a header row.
    columns:
        Names of the data columns to return (finite float64 values required).
    time:
        Name of the time column (strictly increasing, uniform spacing within a relative
        1e-6 of the median interval plus the resolution the stamps are printed with), or
        ``None`` / ``""`` when the file has no time column.
    min_rows:
        Minimum number of data rows (at least 2 when there is a time column).

    Returns
    -------
    (time array or None, {column: array}, sample interval or None)

    Raises
    ------
    InputError
        With a one-line message naming the file and, where relevant, row and column.
    """
    path = Path(path)
    if not time:
        time = None
    header, data, lines = read_csv_table(path)
    wanted = ([time] if time is not None else []) + [c for c in columns if c != time]
    missing = [name for name in wanted if name not in header]
    if missing:
        which = "columns" if len(missing) > 1 else "column"
        raise InputError(
            f"{path}: missing {which} {', '.join(repr(m) for m in missing)}; "
            f"available: {', '.join(header)}"
        )
    if time is not None:
        min_rows = max(min_rows, 2)
    if len(data) < min_rows:
        raise InputError(f"{path}: too few data rows ({len(data)}; need at least {min_rows})")
    _check_widths(path, data, lines, len(header))
    parsed = {name: _parse_column(path, name, header.index(name), data, lines) for name in wanted}
    t: np.ndarray | None = None
    interval: float | None = None
    if time is not None:
        t = parsed[time]
        interval = _check_time(path, time, t, column_cells(data, header.index(time)), lines)
    return t, {name: parsed[name] for name in columns}, interval


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
