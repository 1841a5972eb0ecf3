"""The model family of the diagnosis, simulated exactly: first-order dynamics (or heating /
cooling time constants), an optional extra pole and dead time, and the static map (gain,
offset, Pt-100 curvature)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from scipy import signal

from dualprobe._core import simulate_hysteretic_first_order as _core_hysteretic

__all__ = [
    "NONLINEARITY_ZERO",
    "dynamics",
    "hysteretic_first_order",
    "simulate_effects",
    "simulate_hysteretic",
    "static_columns",
]


# Zero of the curvature term other than 0 degC: the linear-alpha conversion is exact at 0 and
# 100 degC (alpha is the mean slope over that interval).
NONLINEARITY_ZERO = 100.0


def hysteretic_first_order(
    gas: np.ndarray, ts: float, tau_heat: float, tau_cool: float, initial: float
) -> np.ndarray:
    """Pure-Python reference of the core loop (ZOH, direction by the sign of the drive):
    ``T(k) = T(k-1) + (1 - exp(-ts/tau_dir)) (Tg(k-1) - T(k-1))``, ``T(0) = initial``."""
    if not (ts > 0 and tau_heat > 0 and tau_cool > 0 and math.isfinite(initial)):
        raise ValueError("hysteretic_first_order: ts, tau_heat, tau_cool must be > 0")
    b_heat = -math.expm1(-ts / tau_heat)
    b_cool = -math.expm1(-ts / tau_cool)
    values = np.asarray(gas, dtype=float).tolist()
    out = [0.0] * len(values)
    if not values:
        return np.empty(0)
    state = float(initial)
    out[0] = state
    for k in range(1, len(values)):
        drive = values[k - 1] - state
        state += (b_heat if drive > 0.0 else b_cool) * drive
        out[k] = state
    return np.asarray(out)


def simulate_hysteretic(
    gas: np.ndarray, ts: float, tau_heat: float, tau_cool: float, initial: float
) -> np.ndarray:
    """:func:`hysteretic_first_order`, in C++ (``dualprobe._core``)."""
    gas = np.ascontiguousarray(gas, dtype=float)
    return np.asarray(_core_hysteretic(gas, float(ts), tau_heat, tau_cool, float(initial)))


def _first_order_foh(v: np.ndarray, ts: float, tau: float, initial: float) -> np.ndarray:
    """Exact response of 1/(1 + tau s) to the linearly interpolated input, state `initial` at
    the first sample: x(k) = a x(k-1) + b0 v(k) + b1 v(k-1)."""
    h = ts / tau
    a = math.exp(-h)
    one_minus_a = -math.expm1(-h)
    b0 = 1.0 - one_minus_a / h
    b1 = one_minus_a - b0
    out = np.empty_like(v)
    out[0] = initial
    if v.size > 1:
        zi = np.array([a * initial + b1 * v[0]])
        out[1:], _ = signal.lfilter([b0, b1], [1.0, -a], v[1:], zi=zi)
    return out


def _delayed(u: np.ndarray, delay_samples: float) -> np.ndarray:
    """u(t - delay), linearly interpolated, held at u[0] before the record."""
    if delay_samples <= 0.0:
        return u
    whole = math.floor(delay_samples)
    frac = delay_samples - whole
    index = np.arange(u.size) - whole
    now = u[np.clip(index, 0, None)]
    before = u[np.clip(index - 1, 0, None)]
    return (1.0 - frac) * now + frac * before


def _first_order_zoh(
    u: np.ndarray, ts: float, tau: float, initial: float, delay: float
) -> np.ndarray:
    """Exact response of exp(-delay s)/(1 + tau s) to the input held over each sample interval
    (paper eq. 8 when delay = 0): with delay = (n + f) ts the held value changes a fraction f
    into the interval, x(k) = a x(k-1) + c1 u(k-1-n) + c2 u(k-2-n)."""
    h = ts / tau
    a = math.exp(-h)
    whole = math.floor(delay / ts)
    frac = delay / ts - whole
    late = math.exp(-(1.0 - frac) * h)
    c1 = 1.0 - late
    c2 = late - a
    index = np.arange(u.size) - whole
    drive = c1 * u[np.clip(index, 0, None)]
    if c2 != 0.0:
        drive = drive + c2 * u[np.clip(index - 1, 0, None)]
    out, _ = signal.lfilter([0.0, 1.0], [1.0, -a], drive, zi=np.array([initial]))
    return out


def dynamics(u: np.ndarray, ts: float, p: Mapping[str, float]) -> np.ndarray:
    """Sensor temperature x (before the static map) for the parameter set `p`.

    The reference is interpolated linearly between samples, or held over each sample interval
    when ``p["input_hold"]`` is set (data that follow the paper's eq. 8 exactly)."""
    delay = p.get("delay", 0.0)
    initial = p["initial"]
    hold = bool(p.get("input_hold", 0.0))
    if "tau_heat" in p:
        v = _delayed(u, delay / ts)
        if not hold:
            # The core loop holds the gas over each interval; feeding it the interval mean of
            # the interpolated reference makes it the same (to O(ts/tau)^2) as the linear model.
            mid = np.empty_like(v)
            mid[:-1] = 0.5 * (v[:-1] + v[1:])
            mid[-1] = v[-1]
            v = mid
        x = simulate_hysteretic(v, ts, p["tau_heat"], p["tau_cool"], initial)
    elif hold:
        x = _first_order_zoh(u, ts, p["tau"], initial, delay)
    else:
        x = _first_order_foh(_delayed(u, delay / ts), ts, p["tau"], initial)
    if "tau2" in p:
        # the first stage's output is smooth: interpolating it is accurate in either case
        x = _first_order_foh(x, ts, p["tau2"], initial)
    return x


def static_columns(x: np.ndarray, effects: Sequence[str]) -> list[tuple[str, np.ndarray]]:
    columns = []
    if "offset" in effects:
        columns.append(("offset", np.ones_like(x)))
    if "gain" in effects:
        columns.append(("gain", x))
    if "nonlinearity" in effects:
        columns.append(("curvature", x * (x - NONLINEARITY_ZERO)))
    return columns


def simulate_effects(reference: np.ndarray, ts: float, params: Mapping[str, float]) -> np.ndarray:
    """Simulated sensor output for a parameter set as reported by :func:`diagnose`.

    Keys: ``initial`` and ``tau`` (or ``tau_heat`` and ``tau_cool``), optional ``tau2``,
    ``delay`` (s), ``gain``, ``offset`` (K), ``curvature`` (1/K), and ``input_hold`` = 1 when
    the reference is held over each sample interval (paper eq. 8) instead of interpolated."""
    u = np.asarray(reference, dtype=float)
    x = dynamics(u, ts, params)
    return (
        params.get("offset", 0.0)
        + params.get("gain", 1.0) * x
        + params.get("curvature", 0.0) * x * (x - NONLINEARITY_ZERO)
    )
