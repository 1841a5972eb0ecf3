"""The time base of a recording: units, regularity, clock jitter and gaps.

Rules (the same for every file format):

* **Units.** Time is returned in seconds. The unit is ``--time-unit`` (s, ms, us, min) or the
  unit written after the column's name in parentheses or brackets (``Time (ms)``, ``t [us]``);
  nothing else in a name is read as a unit (``time_ms`` is not). A unit in the header and a
  different ``--time-unit`` is an error.
* **Regular.** Intervals within ``IRREGULAR_TIME_TOLERANCE`` (relative) of the median, plus the
  float64 resolution of the stamps and twice the resolution they were printed with, are a
  uniform clock: the interval is the mean over the record.
* **Jitter.** Intervals scattering by up to ``JITTER_LIMIT`` (10 %) of the median are clock
  jitter: every column is interpolated linearly onto the uniform grid of the mean interval
  (per segment, starting at the segment's first stamp), and a one-line note gives the jitter.
  The sensors are low-pass, so linear interpolation errs by at most ``Ts^2 max|T''| / 8``
  (e.g. 1e-4 K for a 10 K step seen through a 1 s time constant sampled at 15 ms).
* **Gaps.** An interval over ``GAP_FACTOR`` (1.5) times the median splits the record into
  segments (contiguous, uniform stretches); each gap is reported (row, time, duration).
* Anything else (an interval off by more than 10 % but not a gap, time not increasing) is
  refused with one line naming the row.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from dualprobe.io.errors import InputError

__all__ = [
    "GAP_FACTOR",
    "IRREGULAR_TIME_TOLERANCE",
    "JITTER_LIMIT",
    "TIME_UNITS",
    "Gap",
    "TimeBase",
    "analyse_time",
    "resample_segments",
    "split_unit",
    "stamp_resolution",
    "time_unit_factor",
]

# Relative deviation of a sample interval from the median interval below which the clock is
# uniform: well above float64 rounding of typical time stamps (~1e-12 relative), far below any
# real sampling glitch.
IRREGULAR_TIME_TOLERANCE = 1e-6
# Largest scatter of the intervals, relative to the median, accepted as clock jitter.
JITTER_LIMIT = 0.10
# An interval longer than this many median intervals is a gap.
GAP_FACTOR = 1.5

TIME_UNITS: dict[str, float] = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "min": 60.0}
_UNIT_SPELLINGS = {
    "s": "s",
    "sec": "s",
    "ms": "ms",
    "msec": "ms",
    "us": "us",
    "µs": "us",
    "μs": "us",
    "usec": "us",
    "min": "min",
}
_SUFFIX = re.compile(r"^(?P<base>.*?\S)\s*(?:\((?P<paren>[^()]*)\)|\[(?P<bracket>[^\[\]]*)\])$")

Where = Callable[[int], str]


def split_unit(name: str) -> tuple[str, str | None]:
    """``"Time (ms)"`` -> ``("Time", "ms")``; the unit is the text in the trailing parentheses
    or brackets (any text, not only a time unit), None when there are none."""
    match = _SUFFIX.match(name.strip())
    if match is None:
        return name.strip(), None
    unit = match["paren"] if match["paren"] is not None else match["bracket"]
    return match["base"], unit.strip()


def time_unit_of(name: str) -> str | None:
    """The time unit written after a column name (canonical spelling), or None."""
    _, unit = split_unit(name)
    if unit is None:
        return None
    return _UNIT_SPELLINGS.get(unit, _UNIT_SPELLINGS.get(unit.lower()))


def time_unit_factor(unit: str) -> float:
    if unit not in TIME_UNITS:
        raise InputError(f"time unit must be one of {', '.join(TIME_UNITS)}, got {unit!r}")
    return TIME_UNITS[unit]


def stamp_resolution(raw: np.ndarray) -> float:
    """The decimal resolution the stamps were written with (1e-4 for "%.4f"), or 0.

    Stamps parsed from text are float64 approximations of decimals: they lie within float64
    rounding of a multiple of 10^-d for the smallest such d.
    """
    if raw.size == 0:
        return 0.0
    largest = float(np.max(np.abs(raw)))
    for digits in range(0, 10):
        scale = 10.0**digits
        if 16.0 * float(np.spacing(largest)) * scale > 1e-3:
            break
        scaled = raw * scale
        if float(np.max(np.abs(scaled - np.rint(scaled)))) <= 1e-3:
            return 1.0 / scale
    return 0.0


@dataclass(frozen=True)
class Gap:
    """A gap in the time column: ``label`` names the row after it (``line 1236``)."""

    label: str
    time: float  # time of the row before the gap, s
    duration: float  # the interval, s
    intervals: float  # the interval in median intervals

    def __str__(self) -> str:
        return (
            f"{self.label} (t = {self.time:.6g} s): gap of {self.duration:.4g} s "
            f"({self.intervals:.3g} intervals)"
        )


@dataclass(frozen=True)
class TimeBase:
    """What :func:`analyse_time` found: ``segments`` as (start, stop) row ranges."""

    interval: float
    segments: tuple[tuple[int, int], ...]
    gaps: tuple[Gap, ...]
    jitter: float  # largest |interval - mean interval| within segments, s (0 when regular)
    regular: bool  # within rounding of a uniform clock inside every segment


def _first(mask: np.ndarray) -> int | None:
    hits = np.flatnonzero(mask)
    return int(hits[0]) if hits.size else None


def analyse_time(
    t: np.ndarray,
    where: Where,
    *,
    label: Where | None = None,
    resolution: float | Callable[[], float] = 0.0,
    strict: bool = False,
) -> TimeBase:
    """Check a time column (seconds) and find its interval, jitter and gaps.

    ``where(i)`` is the location prefix of row i for messages (``"path: line 12, column 't'"``),
    ``label(i)`` the short name of row i for the gaps (``"line 12"``; default ``where``);
    ``resolution`` (or a function computing it, called only when needed) the printed
    resolution of the stamps in seconds. ``strict``: refuse any interval that is not uniform
    (no jitter, no gaps), as :func:`dualprobe.io.load_columns` does.
    """
    dt = np.diff(t)
    bad = _first(~(dt > 0.0))
    if bad is not None:
        later = bad + 1
        raise InputError(
            f"{where(later)}: time not strictly increasing ({t[later - 1]:.10g} then "
            f"{t[later]:.10g})"
        )
    if dt.size == 0:
        return TimeBase(math.nan, ((0, t.size),), (), 0.0, True)
    median = float(np.median(dt))
    allowed = IRREGULAR_TIME_TOLERANCE * median + 8.0 * float(np.spacing(np.max(np.abs(t))))
    deviation = np.abs(dt - median)
    if np.any(deviation > allowed):
        # Two stamps rounded to the printed resolution make an interval off by up to one unit,
        # and the median interval is off by as much.
        allowed += 2.0 * (resolution() if callable(resolution) else resolution)
    off = deviation > allowed
    if strict and np.any(off):
        later = int(np.flatnonzero(off)[0]) + 1
        raise InputError(
            f"{where(later)}: irregular time step {dt[later - 1]:.10g} (median interval "
            f"{median:.10g}); resample to a uniform grid first"
        )
    is_gap = dt > GAP_FACTOR * median
    irregular = _first(off & ~is_gap & (deviation > JITTER_LIMIT * median))
    if irregular is not None:
        later = irregular + 1
        raise InputError(
            f"{where(later)}: irregular time step {dt[irregular]:.10g} s (median interval "
            f"{median:.10g} s): more than the {JITTER_LIMIT * 100:.0f} % of clock jitter that "
            f"is resampled and less than a gap ({GAP_FACTOR:g} intervals)"
        )
    starts = [0, *(int(i) + 1 for i in np.flatnonzero(is_gap))]
    stops = [*starts[1:], t.size]
    segments = tuple(zip(starts, stops, strict=True))
    spans = sum(float(t[stop - 1] - t[start]) for start, stop in segments)
    steps = sum(stop - start - 1 for start, stop in segments)
    interval = spans / steps if steps > 0 else median
    inside = ~is_gap
    regular = not bool(np.any(off & inside))
    jitter = 0.0 if regular else float(np.max(np.abs(dt[inside] - interval)))
    gaps = tuple(
        Gap((label or where)(int(i) + 1), float(t[i]), float(dt[i]), float(dt[i] / median))
        for i in np.flatnonzero(is_gap)
    )
    return TimeBase(interval, segments, gaps, jitter, regular)


def resample_segments(
    t: np.ndarray, columns: Mapping[str, np.ndarray], base: TimeBase
) -> tuple[np.ndarray, dict[str, np.ndarray], tuple[slice, ...]]:
    """Every column linearly interpolated onto a uniform grid of ``base.interval`` per segment
    (from the segment's first stamp); returns (time, columns, segments as slices)."""
    grids: list[np.ndarray] = []
    for start, stop in base.segments:
        first, last = float(t[start]), float(t[stop - 1])
        count = math.floor((last - first) / base.interval + 1e-9) + 1
        grids.append(first + base.interval * np.arange(count))
    new_t = np.concatenate(grids)
    out: dict[str, np.ndarray] = {}
    for name, values in columns.items():
        parts = [
            np.interp(grid, t[start:stop], values[start:stop])
            for grid, (start, stop) in zip(grids, base.segments, strict=True)
        ]
        out[name] = np.concatenate(parts)
    slices: list[slice] = []
    position = 0
    for grid in grids:
        slices.append(slice(position, position + grid.size))
        position += grid.size
    return new_t, out, tuple(slices)
