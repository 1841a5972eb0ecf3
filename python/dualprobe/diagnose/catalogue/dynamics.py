"""Dynamic effects of constant time constants: the first-order baseline and its extensions
``extra_pole`` (a second, faster stage), ``hysteresis`` (heating and cooling time constants)
and ``dead_time`` (a transport delay), each with its exact simulation, parameters and size.

Parameters (units in :data:`~dualprobe.diagnose.catalogue.UNITS`): ``tau`` or ``tau_heat`` /
``tau_cool`` (s), ``tau2`` (s), ``delay`` (s), ``initial`` (degC), ``input_hold`` (1 when the
reference is held over each sample interval, paper eq. 8, else interpolated linearly).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from scipy import signal

from dualprobe._core import simulate_hysteretic_first_order as _core_hysteretic

__all__ = [
    "DEAD_TIME_MIN_SAMPLES",
    "delayed",
    "first_order_foh",
    "first_order_zoh",
    "hysteretic_first_order",
    "interval_means",
    "main_tau",
    "null_extension",
    "simulate_hysteretic",
    "size",
]

# A dead time under half a sample cannot be told from where within the sample interval the gas
# changed (interpolation puts every change mid-interval).
DEAD_TIME_MIN_SAMPLES = 0.5

# Smallest size reported, about a quarter of the smallest realistic effect (issue 5: pole 8 % of
# tau, heating/cooling 25 %, dead time 10 % of tau).
MIN_SIZE = {
    "extra_pole": 0.02,  # tau2 / tau
    "hysteresis": 0.06,  # |tau_heat - tau_cool| / mean
    "dead_time": 0.04,  # delay / tau, and at least DEAD_TIME_MIN_SAMPLES samples
}


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


def first_order_foh(v: np.ndarray, ts: float, tau: float, initial: float) -> np.ndarray:
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


def delayed(u: np.ndarray, delay_samples: float) -> np.ndarray:
    """u(t - delay), linearly interpolated, held at u[0] before the record."""
    if delay_samples <= 0.0:
        return u
    whole = math.floor(delay_samples)
    frac = delay_samples - whole
    index = np.arange(u.size) - whole
    now = u[np.clip(index, 0, None)]
    before = u[np.clip(index - 1, 0, None)]
    return (1.0 - frac) * now + frac * before


def first_order_zoh(
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


def interval_means(v: np.ndarray) -> np.ndarray:
    """Mean of the linearly interpolated input over each sample interval (last value repeated):
    the direction-switched loops hold it, which makes them the linear model to O(ts/tau)^2."""
    mid = np.empty_like(v)
    mid[:-1] = 0.5 * (v[:-1] + v[1:])
    mid[-1] = v[-1]
    return mid


def main_tau(p: Mapping[str, float]) -> float:
    """Main time constant: tau, or the smaller of the heating and cooling ones."""
    return p["tau"] if "tau" in p else min(p["tau_heat"], p["tau_cool"])


def null_extension(p: Mapping[str, float], effect: str) -> dict[str, float]:
    """The extension at its null value: reproduces the current model (so a nested fit can only
    improve on it)."""
    q = dict(p)
    if effect == "extra_pole":
        q["tau2"] = 1e-3 * main_tau(q)
    elif effect == "dead_time":
        q["delay"] = 0.0
    elif effect == "hysteresis":
        tau = q.pop("tau")
        q["tau_heat"] = q["tau_cool"] = tau
    return q


def size(effect: str, p: Mapping[str, float], tau: float, ts: float) -> float:
    """Size of `effect` in units of its smallest reported size (dead time: of the larger of its
    two floors), so that >= 1 passes."""
    if effect == "extra_pole":
        return p["tau2"] / main_tau(p) / MIN_SIZE["extra_pole"]
    if effect == "hysteresis":
        diff = abs(p["tau_heat"] - p["tau_cool"]) / (0.5 * (p["tau_heat"] + p["tau_cool"]))
        return diff / MIN_SIZE["hysteresis"]
    floor = max(MIN_SIZE["dead_time"] * tau, DEAD_TIME_MIN_SAMPLES * ts)
    return p["delay"] / floor
