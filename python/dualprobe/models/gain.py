"""The static gain of a sensor against a reference of the same temperature: what is plausible,
and a quick estimate of it before any model is fitted (:func:`static_gain`)."""

from __future__ import annotations

import math

import numpy as np
from scipy import linalg, signal

__all__ = ["GAIN_RANGE", "static_gain"]

# Static gains a temperature sensor against a temperature reference can have: a thermocouple or
# RTD reads its own temperature within a few per cent; far outside this the two columns are not
# the same quantity (degC against V, K against degC through a scaled channel, ...).
GAIN_RANGE = (0.5, 2.0)


def static_gain(u: np.ndarray, y: np.ndarray, ts: float, *, scan: int = 24) -> float:
    """The gain of ``y`` against ``u`` through a first-order lag, with an offset and the decay
    of the sensor's initial state free: least squares at each of ``scan`` time constants from
    0.3 samples to a fifth of the record, the gain of the best. Linear at each time constant,
    so it cannot wander off as a nonlinear fit from a unity-gain start did on a thermocouple
    logged in mV (gain -117 and a 3000 s pole)."""
    n = u.size
    rows = np.arange(n)
    best_sse, gain = math.inf, math.nan
    for tau in np.geomspace(0.3 * ts, 0.2 * n * ts, scan):
        a = math.exp(-ts / tau)
        lagged = signal.lfilter([1.0 - a], [1.0, -a], u, zi=[a * u[0]])[0]
        design = np.column_stack([lagged, np.ones(n), a**rows])
        coef, *_ = linalg.lstsq(design, y, check_finite=False)
        residual = y - design @ coef
        sse = float(residual @ residual)
        if sse < best_sse:
            best_sse, gain = sse, float(coef[0])
    return gain
