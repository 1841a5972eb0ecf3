"""Time constants that follow the conditions: ``flow_dependence`` and ``level_dependence``.

``flow_dependence`` (needs the flow column, e.g. the gas velocity): convective heat transfer
grows with the flow, ``tau(t) = tau (v(t)/v_ref)^-m`` (paper eq. 1; 0.3 <= m <= 0.7 for
cylinders in cross flow). ``level_dependence``: the gas properties change with the temperature
level, ``tau(t) = tau (T(t)/T_ref)^-n`` with ``T`` the *input* (gas) temperature in kelvin: the
film coefficient is set by the gas the sensor sits in, and the input is known without the
model. ``v_ref`` and ``T_ref`` are the record's medians (so ``tau`` is the time constant at
typical conditions); ``m`` and ``n`` are fitted. Both multiply every time constant of the first
stage (``tau``, or ``tau_heat`` and ``tau_cool``); a second stage keeps its own.

Simulation: the time constant is taken at the midpoint of each sample interval and held over
it, and the first stage is discretised exactly for that constant, with the same input
convention as the constant model (first-order hold, or the paper's eq. 8 hold with a
fractional delay), so that ``m = n = 0`` reproduces it to rounding. The recursion runs in the
C++ core (``simulate_switched_first_order``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from dualprobe._core import simulate_switched_first_order
from dualprobe.diagnose.catalogue.dynamics import delayed, interval_means

__all__ = [
    "KELVIN",
    "MIN_SIZE",
    "Conditions",
    "conditions_for",
    "size",
    "varies",
    "varying_first_stage",
]

KELVIN = 273.15
# Smallest reported variation of the time constant over the record's flow or level range
# (1st to 99th percentile), as for hysteresis: 6 % (a quarter of the smallest realistic one).
MIN_SIZE = {"flow_dependence": 0.06, "level_dependence": 0.06}
EXPONENT_LIMIT = 3.0


@dataclass(frozen=True)
class Conditions:
    """Logarithms of flow and level relative to their references, at the interval midpoints
    (n - 1 values), and the spans used for the effect sizes."""

    log_flow: np.ndarray | None
    log_level: np.ndarray
    flow_reference: float
    level_reference: float
    flow_span: float  # ln(v99 / v1)
    level_span: float  # ln(T99 / T1)


def _check_flow(flow: np.ndarray, size: int) -> np.ndarray:
    v = np.asarray(flow, dtype=float)
    if v.ndim != 1 or v.size != size:
        raise ValueError(f"diagnose: flow has {v.size} samples, the reference {size}")
    bad = np.flatnonzero(~np.isfinite(v) | (v <= 0.0))
    if bad.size:
        raise ValueError(
            f"diagnose: flow sample {int(bad[0])} is {v[bad[0]]!r}: the flow must be finite and "
            "> 0 (the time constant follows a power of it)"
        )
    return v


def conditions_for(
    reference: np.ndarray,
    flow: np.ndarray | None,
    *,
    flow_reference: float | None = None,
    level_reference: float | None = None,
) -> Conditions:
    """The conditions of a record (references: the medians unless given)."""
    u = np.asarray(reference, dtype=float)
    level = np.maximum(u + KELVIN, 1.0)  # kelvin; guards a nonsensical reading below 0 K
    t_ref = float(np.median(level)) if level_reference is None else float(level_reference)
    level_mid = 0.5 * (level[1:] + level[:-1])
    lo, hi = np.quantile(level, [0.01, 0.99])
    log_flow = None
    v_ref = float("nan")
    flow_span = 0.0
    if flow is not None:
        v = _check_flow(flow, u.size)
        v_ref = float(np.median(v)) if flow_reference is None else float(flow_reference)
        log_flow = np.log(0.5 * (v[1:] + v[:-1]) / v_ref)
        f_lo, f_hi = np.quantile(v, [0.01, 0.99])
        flow_span = math.log(f_hi / f_lo)
    return Conditions(
        log_flow=log_flow,
        log_level=np.log(level_mid / t_ref),
        flow_reference=v_ref,
        level_reference=t_ref,
        flow_span=flow_span,
        level_span=math.log(hi / lo),
    )


def varies(p: Mapping[str, float]) -> bool:
    return "flow_exponent" in p or "level_exponent" in p


def _log_factor(p: Mapping[str, float], conditions: Conditions) -> np.ndarray | float:
    """ln(tau_k / tau) per interval."""
    out: np.ndarray | float = 0.0
    if "flow_exponent" in p:
        if conditions.log_flow is None:
            raise ValueError("diagnose: flow_dependence needs the flow column")
        out = -p["flow_exponent"] * conditions.log_flow
    if "level_exponent" in p:
        out = out - p["level_exponent"] * conditions.log_level
    return out


def varying_first_stage(
    u: np.ndarray, ts: float, p: Mapping[str, float], conditions: Conditions
) -> np.ndarray:
    """First stage with a time constant per interval (see the module docstring)."""
    delay = p.get("delay", 0.0)
    hold = bool(p.get("input_hold", 0.0))
    initial = float(p["initial"])
    log_factor = _log_factor(p, conditions)
    if "tau_heat" in p:
        v = delayed(u, delay / ts)
        drive = v[:-1] if hold else interval_means(v)[:-1]
        coefficients = []
        for key in ("tau_heat", "tau_cool"):
            b = -np.expm1(-(ts / p[key]) * np.exp(-log_factor)) * np.ones(drive.size)
            coefficients += [1.0 - b, b * drive]
        return np.asarray(simulate_switched_first_order(drive, *coefficients, initial))
    h = (ts / p["tau"]) * np.exp(-log_factor) * np.ones(u.size - 1)
    a = np.exp(-h)
    if hold:
        whole = math.floor(delay / ts)
        frac = delay / ts - whole
        late = np.exp(-(1.0 - frac) * h)
        index = np.arange(u.size - 1) - whole
        f = (1.0 - late) * u[np.clip(index, 0, None)] + (late - a) * u[np.clip(index - 1, 0, None)]
        drive = u[:-1]
    else:
        v = delayed(u, delay / ts)
        one_minus_a = -np.expm1(-h)
        b0 = 1.0 - one_minus_a / h
        f = b0 * v[1:] + (one_minus_a - b0) * v[:-1]
        drive = v[:-1]
    return np.asarray(simulate_switched_first_order(drive, a, f, a, f, initial))


def size(effect: str, p: Mapping[str, float], conditions: Conditions) -> float:
    """Variation of the time constant over the record's flow or level range, in units of
    MIN_SIZE."""
    if effect == "flow_dependence":
        spread = math.expm1(abs(p["flow_exponent"]) * conditions.flow_span)
    else:
        spread = math.expm1(abs(p["level_exponent"]) * conditions.level_span)
    return spread / MIN_SIZE[effect]
