"""Where the gas stands still, a tracked schedule is held (no flow signal).

Without a flow signal the schedule psi is determined only where the readings move: where both
stay within ``STILL_RANGE`` noise standard deviations over the slower sensor's time constant
either side, the tracking's columns are noise, and psi follows whatever that noise and the
logger's quantisation and holds suggest. A 600 s record at 25 Hz (0.1 K steps, sensor 2 held
3 rows) whose last 2 min idled had its tracked time constant rise 4-fold there and its adapted
one 7.8-fold (the truth: constant), and was refused for a time constant over a third of the
record. A still gas is read alike through any lag, so there the schedule is held instead:
linear in log psi between the rows where the readings move on either side, and at either end
of the record the value where they last moved.
"""

from __future__ import annotations

import numpy as np
import scipy.ndimage

__all__ = ["STILL_RANGE", "hold_still", "movement"]

# Readings whose range over a time constant either side stays within this many noise standard
# deviations: the gas stood still there (a 7 s idle start of a 60 s drive cycle: 0.28 K, 5.6
# standard deviations, where the tracked time constant rose 5-1700 times its median; the range
# of white noise over 500 rows is about 6.5; a drive cycle's swings are hundreds)
STILL_RANGE = 10.0


def movement(readings: tuple[np.ndarray, np.ndarray], reach: int) -> np.ndarray:
    """Per row, the larger range (K) of the two readings within ``reach`` rows either side."""
    size = 2 * max(1, int(reach)) + 1
    spans = [scipy.ndimage.maximum_filter1d(r, size, mode="nearest")
             - scipy.ndimage.minimum_filter1d(r, size, mode="nearest") for r in readings]
    return np.maximum(spans[0], spans[1])


def hold_still(psi: np.ndarray, readings: tuple[np.ndarray, np.ndarray], reach: int,
               noise: float) -> tuple[np.ndarray, float] | None:
    """``psi`` held where the gas stands still (module docstring), rescaled to ``psi``'s mean,
    and the share of rows held; None where nothing stands still, or everything does (nothing
    to hold it to)."""
    moving = movement(readings, reach) >= STILL_RANGE * noise
    if np.all(moving) or not np.any(moving):
        return None
    rows = np.arange(psi.size)
    # np.interp holds the end values beyond the first and last moving row
    log_psi = np.interp(rows, rows[moving], np.log(psi[moving]))
    held = np.exp(log_psi)
    return held * (float(np.mean(psi)) / float(np.mean(held))), float(np.mean(~moving))
