"""A signal moved in time by a fraction of a row, and the search for a flow column's delay: one
implementation for ``estimation.flow_timing`` (characterise) and ``diagnose.flow_delay``."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np

from dualprobe.models.minimise import grid_then_brent

__all__ = ["DELAY_RANGE", "DELAY_STEP", "DELAY_TOLERANCE", "delay_profile", "later"]

# A flow column's delay against the flow at the sensors, as both searches take it:
DELAY_RANGE = 2.0  # s: |d| searched (intake-to-exhaust transport and ECU filters: 0.05-1 s)
DELAY_STEP = 0.25  # s: coarse grid before Brent (the profile is smooth on this scale)
DELAY_TOLERANCE = 0.01  # s


def later(values: np.ndarray, delay: float, ts: float) -> np.ndarray:
    """``values`` ``delay`` seconds later, ``v(t - delay)`` (either sign): linear between rows,
    the end values held beyond the record."""
    v = np.asarray(values, dtype=float)
    if delay == 0.0:
        return v
    rows = np.arange(v.size, dtype=float)
    return np.asarray(np.interp(rows - delay / ts, rows, v))


def delay_profile(misfit: Callable[[float], float], ts: float) -> tuple[float, float]:
    """(d, misfit(d)) minimising ``misfit`` over |d| <= DELAY_RANGE: a grid of delays (every
    ``DELAY_STEP``, at least a row), then bounded Brent. NaN when nothing fits."""
    cached = functools.cache(misfit)
    step = max(DELAY_STEP, ts)
    grid = np.arange(-DELAY_RANGE, DELAY_RANGE + step / 2, step)
    d, _ = grid_then_brent(cached, grid, DELAY_TOLERANCE)
    return (d, cached(d)) if math.isfinite(d) else (math.nan, math.inf)
