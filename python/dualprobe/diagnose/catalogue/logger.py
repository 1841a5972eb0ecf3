"""Logger effects: ``sample_and_hold`` and ``quantisation``, found in the readings themselves.

``sample_and_hold``: the logger refreshes the reading every ``k`` rows and repeats it in
between, so the reading changes only at rows ``phase + j k``. Detected from the rows at which
consecutive readings differ (exactly equal values repeat): all of at least MIN_CHANGES changes
(99 %, for a glitch) fall on one residue modulo ``k``, the largest such ``k`` <= MAX_HOLD.
Modelled by reading the simulated output at the latest refresh; ``k`` and ``phase`` are
detected, not fitted, and count as one parameter of the model.

``quantisation``: the readings lie on a grid of step ``q`` (the ADC's resolution): every
non-zero difference of consecutive readings is a whole multiple of ``q`` (to the rounding of
the stored numbers), ``q`` the smallest non-zero difference or a fraction 1/2 .. 1/10 of it.
It adds ``q^2 / 12`` to the noise variance (the rounding error is uniform over one step), a
floor that the noise estimate of held or slowly varying data would otherwise miss. Named when
that floor is a visible part of the output's noise (:data:`MIN_FLOOR_SHARE`) and the step at
least :data:`MIN_STEP`; it changes the floor, not the prediction.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MAX_HOLD",
    "MIN_CHANGES",
    "MIN_FLOOR_SHARE",
    "MIN_STEP",
    "Grid",
    "Hold",
    "detect_grid",
    "detect_hold",
    "hold_index",
]

MAX_HOLD = 64
MIN_CHANGES = 20
ALIGNED = 0.99
# The quantisation floor q^2/12 must be at least a fifth of the output's noise variance (the
# step at least ~1.7 times the noise it rides on) to be named ...
MIN_FLOOR_SHARE = 0.2
# ... and the step at least 5 mK (a quarter of a 16-bit converter's step over a 1000 K range):
# finer grids are the number format of the file, not a logger effect.
MIN_STEP = 0.005
MAX_DIVISOR = 10


@dataclass(frozen=True)
class Hold:
    """The reading is refreshed at rows phase + j k."""

    samples: int  # k
    phase: int
    changes: int  # rows at which the reading changed
    aligned: float  # share of them on the refresh rows


@dataclass(frozen=True)
class Grid:
    """Readings on origin + j step."""

    step: float  # K
    origin: float  # K, in [0, step)
    differences: int  # non-zero differences checked (all whole multiples of the step)
    tolerance: float  # K, the rounding allowed

    @property
    def floor(self) -> float:
        """Standard deviation of the rounding error, q / sqrt(12) (K)."""
        return self.step / math.sqrt(12.0)

    @property
    def chance_log10(self) -> float:
        """log10 of the probability that continuous readings would all fall on the grid."""
        share = min(2.0 * self.tolerance / self.step, 1.0)
        return self.differences * math.log10(max(share, 1e-300))


def detect_hold(y: np.ndarray) -> Hold | None:
    """The logger's refresh period, or None when the readings change at any row."""
    changes = np.flatnonzero(np.diff(np.asarray(y, dtype=float)) != 0.0) + 1
    if changes.size < MIN_CHANGES or changes.size > 0.9 * (y.size - 1):
        return None
    for k in range(min(MAX_HOLD, y.size // MIN_CHANGES), 1, -1):
        counts = np.bincount(changes % k, minlength=k)
        phase = int(np.argmax(counts))
        if counts[phase] >= ALIGNED * changes.size:
            return Hold(k, phase, int(changes.size), float(counts[phase] / changes.size))
    return None


def hold_index(n: int, samples: int, phase: int) -> np.ndarray:
    """Row of the latest refresh for each of n rows (rows before the first refresh read the
    first row)."""
    index = np.arange(n)
    latest = phase + np.floor_divide(index - phase, samples) * samples
    return np.clip(latest, 0, None)


def detect_grid(y: np.ndarray) -> Grid | None:
    """The grid the readings lie on, or None."""
    x = np.asarray(y, dtype=float)
    steps = np.abs(np.diff(x))
    moving = steps[steps > 0.0]
    if moving.size < MIN_CHANGES:
        return None
    # differences of stored decimal numbers carry the rounding of the values themselves
    rounding = 64.0 * np.finfo(float).eps * max(float(np.max(np.abs(x))), 1.0)
    smallest = float(np.min(moving))
    if smallest <= 100.0 * rounding:
        return None
    for divisor in range(1, MAX_DIVISOR + 1):
        step = smallest / divisor
        tolerance = rounding + 1e-6 * step
        ratio = moving / step
        if np.all(np.abs(ratio - np.round(ratio)) * step <= tolerance):
            residue = x - step * np.round(x / step)
            origin = float(np.median(residue)) % step
            return Grid(step, origin, int(moving.size), tolerance)
    return None
