"""The time base of a recording: units, regularity, clock jitter and gaps.

Rules (the same for every file format):

* **Units.** Time is returned in seconds. The unit is ``--time-unit`` (s, ms, us, min) or the
  unit written after the column's name in parentheses or brackets (``Time (ms)``, ``t [us]``);
  nothing else in a name is read as a unit (``time_ms`` is not). A unit in the header and a
  different ``--time-unit`` is an error.
* **Regular.** Intervals within ``IRREGULAR_TIME_TOLERANCE`` (relative) of the median, plus the
  float64 resolution of the stamps and twice the resolution they were printed with, are a
  uniform clock: the interval is the mean over the record.
* **Jitter.** Intervals that scatter about the median (up to ``GAP_FACTOR`` times it) are clock
  jitter: every column is interpolated linearly onto the uniform grid of the mean interval
  (per segment, starting at the segment's first stamp), and a one-line note gives the jitter.
  The sensors are low-pass, so linear interpolation errs by at most ``h^2 max|T''| / 8`` for
  the longest interval h (e.g. 1e-4 K for a 10 K step seen through a 1 s time constant
  sampled at 15 ms). Loggers stamping CAN frames or event-driven readings scatter by tens of
  per cent; refusing them (as this loader did beyond 10 %) left a field record unreadable.
* **Dropped rows.** An interval of up to ``BRIDGE_ROWS`` (3) missing rows (a logger that lost
  a few frames) is bridged the same way, and a note says how many rows were interpolated:
  a straight line over 4 intervals errs by ``2 Ts^2 max|T''|`` (0.05 K for a 4 s sensor
  whose gas changes slope by 10 K/s, at 10 Hz), and one lost frame no longer cuts the record.
* **Gaps.** A longer interval splits the record into segments (contiguous, uniform
  stretches); each gap is reported (row, time, duration).
* Time that does not increase, or stamps that stray from a uniform grid by more than
  ``JITTER_LIMIT`` (a quarter interval: a clock that speeds up, not one that jitters) are
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
    "BRIDGE_ROWS",
    "GAP_FACTOR",
    "IRREGULAR_TIME_TOLERANCE",
    "JITTER_LIMIT",
    "TIME_UNITS",
    "Gap",
    "TimeBase",
    "analyse_time",
    "resample_segments",
    "seconds_from_first",
    "split_unit",
    "stamp_resolution",
    "time_unit_factor",
]

# Relative deviation of a sample interval from the median interval below which the clock is
# uniform: well above float64 rounding of typical time stamps (~1e-12 relative), far below any
# real sampling glitch.
IRREGULAR_TIME_TOLERANCE = 1e-6
# An interval longer than this many median intervals is not jitter: rows are missing.
GAP_FACTOR = 1.5
# Missing rows bridged by interpolation; a longer gap splits the record (module docstring).
BRIDGE_ROWS = 3
# Largest distance of a stamp from the uniform grid, in intervals, that is clock jitter: a
# stamp half-way between two grid instants belongs to neither (a corrupt stamp), and at
# +-30 % a drive cycle's interpolated noise and fluctuation already misfit 3.6x the noise.
JITTER_LIMIT = 0.25

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


def seconds_from_first(ticks: np.ndarray, unit: str) -> np.ndarray:
    """Integer time stamps (a date-time or duration in ``unit``: s, ms, us or ns) as seconds
    from the first one: differences first, so that float64 keeps the stamps' resolution."""
    scale = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}[unit]
    ticks = np.asarray(ticks, dtype=np.int64)
    return (ticks - ticks[0]).astype(np.float64) * scale


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
    cause: str = ""  # what made it, when known ("5 rows without a reading in every column")

    def __str__(self) -> str:
        cause = f": {self.cause}" if self.cause else ""
        return (
            f"{self.label} (t = {self.time:.6g} s): gap of {self.duration:.4g} s "
            f"({self.intervals:.3g} intervals{cause})"
        )


@dataclass(frozen=True)
class TimeBase:
    """What :func:`analyse_time` found: ``segments`` as (start, stop) row ranges."""

    interval: float
    segments: tuple[tuple[int, int], ...]
    gaps: tuple[Gap, ...]
    jitter: float  # largest |interval - mean interval| within segments, s (0 when regular)
    regular: bool  # within rounding of a uniform clock inside every segment
    bridged: tuple[Gap, ...] = ()  # dropped rows inside segments, interpolated over
    bridged_rows: int = 0  # the rows those intervals lost, which the bridging interpolates

    @property
    def uniform(self) -> bool:
        """The stamps are the grid: nothing to resample."""
        return self.regular and not self.bridged


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
    ordinary = dt <= GAP_FACTOR * median
    is_gap = dt >= (BRIDGE_ROWS + GAP_FACTOR) * median
    starts = [0, *(int(i) + 1 for i in np.flatnonzero(is_gap))]
    stops = [*starts[1:], t.size]
    segments = tuple(zip(starts, stops, strict=True))
    # the segments' spans over their steps, a bridged interval counted as the rows it lost
    # plus one (the mean interval of a jittering clock; leaving bridged intervals out would
    # bias it short, as they are the long tail of the jitter too)
    bridging = ~ordinary & ~is_gap
    rows = np.where(bridging, np.rint(dt / median), 1.0)  # grid steps of each interval
    steps = int(np.sum(rows[~is_gap]))
    interval = float(np.sum(dt[~is_gap])) / steps if steps else median
    _check_clock(t, dt, segments, rows, interval, median, where)
    regular = not bool(np.any(off & ordinary))
    jitter = 0.0 if regular else float(np.max(np.abs(dt[ordinary] - interval)))

    def gap(i: int) -> Gap:
        return Gap((label or where)(i + 1), float(t[i]), float(dt[i]), float(dt[i] / median))

    gaps = tuple(gap(int(i)) for i in np.flatnonzero(is_gap))
    bridged = tuple(gap(int(i)) for i in np.flatnonzero(bridging))
    return TimeBase(interval, segments, gaps, jitter, regular, bridged,
                    int(np.sum(rows[bridging])) - len(bridged))


def _check_clock(t: np.ndarray, dt: np.ndarray, segments: tuple[tuple[int, int], ...],
                 steps: np.ndarray, interval: float, median: float, where: Where) -> None:
    """Refuse stamps that are not a uniform clock with jitter: within a segment, each stamp
    must lie within ``JITTER_LIMIT`` intervals of a uniform grid (its rows counted with the
    bridged ones); beyond that its row cannot be placed on the grid (a clock that speeds up,
    or stamps of another rate)."""
    for start, stop in segments:
        if stop - start < 3:
            continue
        rows = np.concatenate(([0.0], np.cumsum(steps[start : stop - 1])))
        stray = t[start:stop] - t[start] - interval * rows
        stray -= 0.5 * (float(np.max(stray)) + float(np.min(stray)))
        worst = int(np.argmax(np.abs(stray)))
        if abs(stray[worst]) > JITTER_LIMIT * interval:
            row = start + max(worst, 1)
            raise InputError(
                f"{where(row)}: irregular time step {dt[row - 1]:.10g} s (median interval "
                f"{median:.10g} s): the stamps stray from a uniform clock by "
                f"{abs(stray[worst]):.4g} s here, over {JITTER_LIMIT:g} of an interval: not "
                "clock jitter; resample the record to a uniform grid first"
            )


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
