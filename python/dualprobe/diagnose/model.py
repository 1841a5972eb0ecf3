"""The model family of the diagnosis, composed from the catalogue and simulated exactly::

    v(t)  = u(t - delay)                                    dead_time
    x1    = 1/(1 + tau s) v   tau: constant, or tau_heat / tau_cool     hysteresis
                              times (v/v_ref)^-m (T/T_ref)^-n           flow_ / level_dependence
    x     = 1/(1 + tau2 s) x1                               extra_pole
    x_h   = x at the logger's latest refresh                sample_and_hold
    y_hat = offset + gain x_h + curvature x_h (x_h - 100) + drift_rate t_h     static effects

The reference is interpolated linearly between samples (first-order hold), or held over each
sample interval when ``input_hold`` is set (data that follow the paper's eq. 8); the dynamics
are discretised exactly for either.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from dualprobe.diagnose.catalogue import conditions as cond
from dualprobe.diagnose.catalogue import dynamics as dyn
from dualprobe.diagnose.catalogue import static
from dualprobe.diagnose.catalogue.logger import hold_index
from dualprobe.models.shift import later

__all__ = [
    "Context",
    "context_for",
    "held",
    "sensor_state",
    "simulate_effects",
]


@dataclass(frozen=True)
class Context:
    """What a simulation needs besides the reference and the parameters."""

    conditions: cond.Conditions
    hours: np.ndarray  # time since the first row (h)


def context_for(
    reference: np.ndarray,
    ts: float,
    flow: np.ndarray | None = None,
    *,
    flow_reference: float | None = None,
    level_reference: float | None = None,
) -> Context:
    u = np.asarray(reference, dtype=float)
    return Context(
        conditions=cond.conditions_for(
            u, flow, flow_reference=flow_reference, level_reference=level_reference
        ),
        hours=np.arange(u.size) * (ts / static.SECONDS_PER_HOUR),
    )


def sensor_state(u: np.ndarray, ts: float, p: Mapping[str, float], context: Context) -> np.ndarray:
    """Sensor temperature x (before the logger and the static map) for the parameters `p`."""
    delay = p.get("delay", 0.0)
    initial = p["initial"]
    hold = bool(p.get("input_hold", 0.0))
    if cond.varies(p):
        x = cond.varying_first_stage(u, ts, p, context.conditions)
    elif "tau_heat" in p:
        v = dyn.delayed(u, delay / ts)
        if not hold:
            # The core loop holds the gas over each interval; feeding it the interval mean of
            # the interpolated reference makes it the same (to O(ts/tau)^2) as the linear model.
            v = dyn.interval_means(v)
        x = dyn.simulate_hysteretic(v, ts, p["tau_heat"], p["tau_cool"], initial)
    elif hold:
        x = dyn.first_order_zoh(u, ts, p["tau"], initial, delay)
    else:
        x = dyn.first_order_foh(dyn.delayed(u, delay / ts), ts, p["tau"], initial)
    if "tau2" in p:
        # the first stage's output is smooth: interpolating it is accurate in either case
        x = dyn.first_order_foh(x, ts, p["tau2"], initial)
    return x


def held(x: np.ndarray, hours: np.ndarray, p: Mapping[str, float]) -> tuple[np.ndarray, np.ndarray]:
    """State and time as the logger reads them (at its latest refresh, with sample_and_hold)."""
    if "hold_samples" not in p:
        return x, hours
    index = hold_index(x.size, int(p["hold_samples"]), int(p["hold_phase"]))
    return x[index], hours[index]


def simulate_effects(
    reference: np.ndarray,
    ts: float,
    params: Mapping[str, float],
    *,
    flow: np.ndarray | None = None,
) -> np.ndarray:
    """Simulated sensor output for a parameter set as reported by :func:`diagnose`.

    Keys (units in ``catalogue.UNITS``): ``initial`` and ``tau`` (or ``tau_heat`` and
    ``tau_cool``), optional ``tau2``, ``delay``, ``gain``, ``offset``, ``curvature``,
    ``drift_rate``, ``flow_exponent`` with ``flow_reference`` (needs `flow`) and the flow's
    ``flow_delay`` (the flow at the sensor is `flow` that many seconds later),
    ``level_exponent`` with ``level_reference``, ``hold_samples`` with ``hold_phase``, and
    ``input_hold`` = 1 when the reference is held over each sample interval (paper eq. 8)."""
    u = np.asarray(reference, dtype=float)
    moved = None
    if flow is not None and "flow_exponent" in params:
        moved = later(flow, params.get("flow_delay", 0.0), ts)
    context = context_for(
        u,
        ts,
        moved,
        flow_reference=params.get("flow_reference"),
        level_reference=params.get("level_reference"),
    )
    x, hours = held(sensor_state(u, ts, params, context), context.hours, params)
    return static.apply(x, hours, params)
