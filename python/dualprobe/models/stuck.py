"""A channel stuck on one value: an open circuit read as 0 or full scale, a logger repeating
the last frame of a channel it lost, a frozen conversion.

A lagging sensor moves towards the gas on every row; its reading can repeat exactly only where
the gas is still (within an ADC step), or for a logger's refresh (:mod:`dualprobe.models.held`).
A longer stretch of one repeated value is a fault, and no model fits it: a 60 s stretch at
0 K in a 10 min drive cycle was refused as "fitted dynamics oscillate ... give --flow, or try
--order 1", a 30 s frozen channel as "no positive real time constants fit these signals ...",
which send a test engineer after the model instead of the channel.

A run of ``MIN_ROWS`` or more exactly equal readings (shorter ones are spikes,
:mod:`dualprobe.models.spikes`) is such a fault (:func:`find_stuck`) when

* it is a **dropout**: the steps into it and out of it both exceed the spike threshold
  (12 local robust scales, at least 12 ADC steps) in opposite directions: the reading left the
  record's course and came back (not on a held sensor, whose refresh steps are no such
  evidence); or
* it is **frozen while the gas moves**: longer than a logger's refresh (``SENSOR_REFRESH``), and
  no first-order sensor of up to a third of the record's duration (the slowest the
  characterisation accepts) can have stayed there. A sensor that reads c over the run has
  ``tau (x(t) - c) = int_0^t (gas - x) ds ~ int_0^t (gas - c) ds``, so it stays within a band
  only if that integral does. The other sensor stands for the gas up to its own gain, lag and
  offset: the offset is free (the smallest over constants b of the largest
  ``|int_0^t (other - b) ds|``), and the gain and lag only shrink the integral's swing. The
  run is frozen when that bound over the slowest time constant exceeds ``FROZEN_STEPS`` ADC
  steps (at least ``FROZEN_FLOOR``), where a sensor at rest reads within half a step.
  (From rest at the other sensor's reading instead, 19 of 360 legitimate drive cycles were
  flagged: a slow sensor at its turning point reads one 0.5 K step for 8-80 s.)
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import optimize

from dualprobe.io.errors import InputError
from dualprobe.models.held import SENSOR_REFRESH, is_held
from dualprobe.models.spikes import MAX_RUN, thresholds

__all__ = ["FROZEN_FLOOR", "FROZEN_STEPS", "MIN_ROWS", "Stuck", "find_stuck", "refuse_stuck"]

MIN_ROWS = MAX_RUN + 1  # shorter runs are the spike rule's
# ADC steps a frozen run must have missed: a sensor at rest flickers by one step at most, and
# three keep a slow sensor's last step before the run (the proxy is only the other sensor's
# reading, with its own lag and gain) well inside
FROZEN_STEPS = 3.0
FROZEN_FLOOR = 0.1  # K: unquantised readings; far above any RTD's noise in a mean of rows
_SLOWEST = 1.0 / 3.0  # of the record's duration: the longest time constant accepted


@dataclass(frozen=True)
class Stuck:
    """A stuck run: rows ``start`` .. ``start + rows - 1`` read ``value``; ``kind``
    "dropout" or "frozen"; ``movement`` (K) what the other sensor drove the slowest accepted
    sensor by within it (frozen), or the smaller of the steps into and out of it (dropout)."""

    start: int
    rows: int
    value: float
    kind: str
    movement: float


def _runs(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(starts, lengths) of the runs of exactly equal consecutive readings of MIN_ROWS+, but
    not one over every row: a constant channel is no stretch to leave out (the callers name
    it: no excitation, or a sensor that does not follow its input)."""
    change = np.flatnonzero(np.diff(x) != 0.0) + 1
    starts = np.concatenate(([0], change))
    lengths = np.diff(np.concatenate((starts, [x.size])))
    keep = (lengths >= MIN_ROWS) & (lengths < x.size)
    return starts[keep], lengths[keep]


def _swing(u: np.ndarray, ts: float) -> float:
    """min over b of max over t of |int_0^t (u - b) ds| (K s; trapezoids; convex in b)."""
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (u[1:] + u[:-1])) * ts))
    elapsed = np.arange(u.size) * ts
    lo, hi = float(np.min(u)), float(np.max(u))
    if hi <= lo:
        return 0.0
    best = optimize.minimize_scalar(lambda b: float(np.max(np.abs(integral - b * elapsed))),
                                    bounds=(lo, hi), method="bounded",
                                    options={"xatol": 1e-9 * (hi - lo)})
    return float(best.fun)


def find_stuck(x: np.ndarray, other: np.ndarray, ts: float) -> list[Stuck]:
    """The stuck runs of ``x`` (module docstring), longest first; ``other`` the pair's other
    sensor on the same rows. No dropout test on a held sensor (:func:`is_held`)."""
    x = np.asarray(x, dtype=float)
    other = np.asarray(other, dtype=float)
    starts, lengths = _runs(x)
    if not starts.size:
        return []
    steps = np.abs(np.diff(x))
    moving = steps[steps > 0.0]
    adc = float(np.min(moving)) if moving.size else 0.0
    limit = max(FROZEN_STEPS * adc, FROZEN_FLOOR)
    tau = _SLOWEST * x.size * ts
    # the spike threshold (a running median over the record) and the held test only for a run
    # that leaves and comes back: most records have none, and despike computes it again
    limits: np.ndarray | None = None
    found: list[Stuck] = []
    for start, length in zip(starts.tolist(), lengths.tolist(), strict=True):
        end = start + length  # first row after the run
        into = x[start] - x[start - 1] if start > 0 else 0.0
        out = x[end] - x[end - 1] if end < x.size else 0.0
        if into * out < 0.0:
            if limits is None:
                limits = (np.full(x.size, np.inf)
                          if is_held(x, ts, SENSOR_REFRESH) or x.size <= MAX_RUN + 4
                          else thresholds(x))
            if min(abs(into), abs(out)) > limits[start - 1]:
                found.append(Stuck(start, length, float(x[start]), "dropout",
                                   float(min(abs(into), abs(out)))))
                continue
        if length * ts <= SENSOR_REFRESH:
            continue
        movement = _swing(other[start:end], ts) / tau
        if movement > limit:
            found.append(Stuck(start, length, float(x[start]), "frozen", movement))
    return sorted(found, key=lambda s: -s.rows)


def refuse_stuck(channels: Sequence[tuple[str, np.ndarray, str, np.ndarray]], ts: float,
                 time: np.ndarray) -> None:
    """An :class:`InputError` (one line) naming the longest stuck run of the ``channels``,
    each ``(column, readings, other column, other readings)`` (the other a sensor or reference
    on the same rows), and the longest stretch free of every one, as a ``--window`` of
    ``time``; nothing if none."""
    runs = [(column, run) for column, x, _, other in channels
            for run in find_stuck(x, other, ts)]
    if not runs:
        return
    others = {column: other for column, _, other, _ in channels}
    column, run = max(runs, key=lambda item: item[1].rows)
    first, last = float(time[run.start]), float(time[run.start + run.rows - 1])
    if run.kind == "dropout":
        why = (f"jumping {run.movement:.3g} K or more into it and out of it, which no lagging "
               "sensor can do (an open circuit, a lost channel)")
    else:
        why = (f"while {others[column]} moves so that even a sensor with a time constant of "
               f"a third of the record would have moved {run.movement:.3g} K (a frozen "
               "channel or logger)")
    bounds = sorted({0, time.size} | {r.start for _, r in runs}
                    | {r.start + r.rows for _, r in runs})
    covered = [(r.start, r.start + r.rows) for _, r in runs]
    free = [(a, b) for a, b in itertools.pairwise(bounds)
            if not any(s <= a and b <= e for s, e in covered)]
    more = f" ({len(runs) - 1} more such stretch{'es' if len(runs) > 2 else ''})" \
        if len(runs) > 1 else ""
    hint = "leave it out"
    if free:
        a, b = max(free, key=lambda span: span[1] - span[0])
        hint = (f"leave it out with --window {float(time[a]):.10g}:{float(time[b - 1]):.10g} "
                f"(the longest stretch without it, {float(time[b - 1] - time[a]):.6g} s)")
    raise InputError(
        f"{column} reads exactly {run.value:.6g} on {run.rows} rows from t = {first:.6g} to "
        f"{last:.6g} s{more}, {why}: {hint}, or mend the channel")
