"""A signal moved in time by a fraction of a row: the one shift the flow's delay searches use
(``estimation.flow_timing`` for characterise, ``diagnose.flow_delay`` for diagnose)."""

from __future__ import annotations

import numpy as np

__all__ = ["DELAY_RANGE", "DELAY_STEP", "DELAY_TOLERANCE", "later"]

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
