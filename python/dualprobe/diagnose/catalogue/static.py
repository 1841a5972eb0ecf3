"""Static effects, linear in their parameters: ``offset``, ``gain``, ``nonlinearity`` and
``drift``. The output map is::

    y = offset + gain x + curvature x (x - 100) + drift_rate (t - t0) / 3600

with ``x`` the sensor temperature (degC) and ``t - t0`` the time since the first sample (s).
``curvature x (x - 100)`` is the shape of a Pt-100 read through the linear alpha conversion
(Callendar-Van Dusen gives ``T_read - T = (B/alpha) T (T - 100)``). ``drift_rate`` (K/h) is a
slow linear change of the reading that starts with the record (a sensor or amplifier that
drifts after its calibration); together with ``offset`` it is any straight line in time. All
are solved exactly for every trial of the dynamics (variable projection).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

__all__ = [
    "MIN_SIZE",
    "NONLINEARITY_ZERO",
    "STATIC_EFFECTS",
    "columns",
    "size",
]

STATIC_EFFECTS = ("offset", "gain", "nonlinearity", "drift")
# Zero of the curvature term other than 0 degC: the linear-alpha conversion is exact at 0 and
# 100 degC (alpha is the mean slope over that interval).
NONLINEARITY_ZERO = 100.0
SECONDS_PER_HOUR = 3600.0
# Smallest reported size, about a quarter of the smallest realistic effect (gain 2 %, offset
# 0.5 K, a drift of 0.5 K over the record).
MIN_SIZE = {
    "gain": 0.005,  # |gain - 1|
    "offset": 0.1,  # K
    "nonlinearity": 0.2,  # K: deviation of the curvature term from a straight line over the data
    "drift": 0.1,  # K over the record
}


def columns(
    x: np.ndarray, hours: np.ndarray, effects: Sequence[str]
) -> list[tuple[str, np.ndarray]]:
    """The regressors of the static effects present (name of the parameter, column)."""
    out = []
    if "offset" in effects:
        out.append(("offset", np.ones_like(x)))
    if "gain" in effects:
        out.append(("gain", x))
    if "nonlinearity" in effects:
        out.append(("curvature", x * (x - NONLINEARITY_ZERO)))
    if "drift" in effects:
        out.append(("drift_rate", hours))
    return out


def apply(x: np.ndarray, hours: np.ndarray, p: Mapping[str, float]) -> np.ndarray:
    """The output map for a parameter set (absent parameters at their null values)."""
    return (
        p.get("offset", 0.0)
        + p.get("gain", 1.0) * x
        + p.get("curvature", 0.0) * x * (x - NONLINEARITY_ZERO)
        + p.get("drift_rate", 0.0) * hours
    )


def size(
    effect: str, p: Mapping[str, float], x_range: tuple[float, float], duration: float
) -> float:
    """Size of a static effect in units of MIN_SIZE."""
    if effect == "gain":
        return abs(p["gain"] - 1.0) / MIN_SIZE["gain"]
    if effect == "offset":
        return abs(p["offset"]) / MIN_SIZE["offset"]
    if effect == "drift":
        return abs(p["drift_rate"]) * duration / SECONDS_PER_HOUR / MIN_SIZE["drift"]
    # Curvature term c x (x - 100) against its best straight line over the data range: the
    # deviation of a parabola from its chord is c (span/2)^2, from the best line half that.
    lo, hi = x_range
    return abs(p["curvature"]) * (hi - lo) ** 2 / 8.0 / MIN_SIZE["nonlinearity"]
