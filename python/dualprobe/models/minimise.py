"""One-dimensional minimisation on a coarse grid, then bounded Brent between the best grid
point's neighbours: the one search of the flow law's exponent and of a flow column's delay
(characterise and diagnose)."""

from __future__ import annotations

import functools
import math
from collections.abc import Callable

import numpy as np
import scipy.optimize

__all__ = ["grid_then_brent"]


def grid_then_brent(misfit: Callable[[float], float], grid: np.ndarray, tolerance: float,
                    ) -> tuple[float, np.ndarray]:
    """x minimising ``misfit(x)``: the grid, then bounded Brent between the best grid point's
    neighbours (kept only when it is no worse). Returns (x, the grid's misfits); NaN when no
    grid point fits (a non-finite misfit counts as no fit)."""

    @functools.cache
    def cached(x: float) -> float:
        value = misfit(x)
        return value if math.isfinite(value) else math.inf

    values = np.array([cached(float(x)) for x in grid])
    if not np.any(np.isfinite(values)):
        return math.nan, values
    best = int(np.argmin(values))
    lo = float(grid[max(best - 1, 0)])
    hi = float(grid[min(best + 1, grid.size - 1)])
    if hi > lo:
        result = scipy.optimize.minimize_scalar(
            lambda x: min(cached(float(x)), 1e300), bounds=(lo, hi), method="bounded",
            options={"xatol": tolerance})
        x = float(result.x)
        if cached(x) <= values[best]:
            return x, values
    return float(grid[best]), values
