"""Pooling the characterisations of many recordings: per sensor one ``tau(flow)`` curve and one
flow exponent, weighted by the recordings' uncertainties (``DIR/pooled.json`` of
``dualprobe batch``).

Read from each recording's JSON document (``Characterisation.to_json_dict()``); a missing key
is NaN, never an error:

* ``sensors[i].time_constants[0]`` (dominant) and ``sensors[i].time_constants_std[0]``;
* ``flow_model``: ``kind`` (``"constant"`` or absent: no curve), ``exponent`` (one value or one
  per sensor) and ``exponent_std``, ``reference_flow``, ``delay`` (pooled by its median),
  optionally ``flow_range`` and
  ``curve = {"flow": [...], "time_constants": [[...] per sensor], "time_constants_std": ...}``.

Each recording's curve is taken in log space, ``ln tau(v)``: from its ``curve`` (log-log
interpolation within the curve's flows), else from the power law
``ln tau_ref - m ln(v / v_ref)`` with variance ``(s_tau / tau_ref)^2 + ln(v / v_ref)^2 s_m^2``
(the two estimates taken as uncorrelated). Support: the curve's flows, else ``flow_range``,
else ``v_ref / 4`` to ``4 v_ref``; nothing is extrapolated beyond a recording's support. On a
common geometric flow grid over all supports, the pooled ``ln tau`` is the inverse-variance
weighted mean of the recordings covering each point, its standard deviation
``1 / sqrt(sum w)``; with no usable variances the weights are equal and the standard deviation
is the scatter over the recordings / sqrt(n). The curve's exponent is the weighted least-squares
slope of the pooled ``ln tau`` over ``ln v``; the pooled exponent is the inverse-variance
weighted mean of the recordings' exponents.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

__all__ = ["GRID_POINTS", "pool_documents", "value"]

GRID_POINTS = 25


def value(mapping: Any, *keys: Any) -> float:
    """``mapping[k0][k1]...`` as a float; NaN when any key is missing or not a number."""
    current = mapping
    for key in keys:
        try:
            current = current[key]
        except (KeyError, IndexError, TypeError):
            return math.nan
    try:
        return float(current)
    except (TypeError, ValueError):
        return math.nan


def _sensor_value(model: Mapping[str, Any], key: str, sensor: int) -> float:
    item = model.get(key)
    if isinstance(item, (list, tuple)):
        return value(item, sensor)
    return value(model, key)


def _weighted(values: np.ndarray, variances: np.ndarray) -> tuple[float, float, str]:
    """(mean, std of the mean, weighting) over finite values."""
    keep = np.isfinite(values)
    values, variances = values[keep], variances[keep]
    if values.size == 0:
        return math.nan, math.nan, "none"
    usable = np.isfinite(variances) & (variances > 0)
    if np.any(usable):
        w = 1.0 / variances[usable]
        mean = float(w @ values[usable] / w.sum())
        return mean, float(1.0 / math.sqrt(w.sum())), "inverse-variance"
    spread = float(np.std(values, ddof=1)) / math.sqrt(values.size) if values.size > 1 else math.nan
    return float(np.mean(values)), spread, "equal (no uncertainties)"


def _flow_law(document: Mapping[str, Any]) -> Mapping[str, Any] | None:
    """The document's flow model when it is a law (not constant, not absent)."""
    model = document.get("flow_model")
    if not isinstance(model, Mapping) or model.get("kind") in (None, "constant"):
        return None
    return model


def _recording_curve(
    document: Mapping[str, Any], sensor: int
) -> tuple[float, float, Any] | None:
    """(support low, high, f(v) -> (ln tau, var ln tau)) of one recording, None without one."""
    model = _flow_law(document)
    if model is None:
        return None
    curve = model.get("curve")
    if isinstance(curve, Mapping):
        flow = np.asarray([value(curve, "flow", k) for k in range(len(curve.get("flow") or []))])
        taus_all = (curve.get("time_constants") or [[]] * (sensor + 1))
        taus = np.asarray([
            value(item, 0) if isinstance(item, (list, tuple)) else value([item], 0)
            for item in (taus_all[sensor] if sensor < len(taus_all) else [])
        ])
        stds_all = curve.get("time_constants_std")
        stds = np.full(taus.size, math.nan)
        if isinstance(stds_all, (list, tuple)) and sensor < len(stds_all):
            stds = np.asarray([
                value(item, 0) if isinstance(item, (list, tuple)) else value([item], 0)
                for item in stds_all[sensor]
            ])
        ok = np.isfinite(flow) & np.isfinite(taus) & (flow > 0) & (taus > 0)
        if flow.size == taus.size and np.count_nonzero(ok) >= 2:
            flow, taus, stds = flow[ok], taus[ok], stds[ok]
            order = np.argsort(flow)
            log_v, log_tau = np.log(flow[order]), np.log(taus[order])
            var = (stds[order] / taus[order]) ** 2

            def from_curve(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
                x = np.log(v)
                return np.interp(x, log_v, log_tau), np.interp(x, log_v, var)

            return float(flow.min()), float(flow.max()), from_curve
    v_ref = value(model, "reference_flow")
    tau_ref = value(document, "sensors", sensor, "time_constants", 0)
    tau_std = value(document, "sensors", sensor, "time_constants_std", 0)
    m = _sensor_value(model, "exponent", sensor)
    m_std = _sensor_value(model, "exponent_std", sensor)
    if not (v_ref > 0 and tau_ref > 0 and math.isfinite(m)):
        return None
    low, high = value(model, "flow_range", 0), value(model, "flow_range", 1)
    if not (0 < low < high):
        low, high = v_ref / 4.0, v_ref * 4.0

    def from_power_law(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        ratio = np.log(v / v_ref)
        return math.log(tau_ref) - m * ratio, (tau_std / tau_ref) ** 2 + ratio**2 * m_std**2

    return low, high, from_power_law


def _pooled_curve(
    grid: np.ndarray, log_tau: np.ndarray, var: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """(pooled ln tau, its std, the curve's exponent) on the grid from the recordings' rows."""
    pooled = [_weighted(log_tau[:, k], var[:, k]) for k in range(grid.size)]
    mean = np.array([p[0] for p in pooled])
    spread = np.array([p[1] for p in pooled])
    fit = np.isfinite(mean)
    if np.count_nonzero(fit) < 3:
        return mean, spread, math.nan
    weights = np.where(np.isfinite(spread) & (spread > 0), spread, np.nan) ** -2.0
    weights = np.where(np.isfinite(weights), weights, 1.0)[fit]
    x, y = np.log(grid[fit]), mean[fit]
    design = np.column_stack([np.ones_like(x), x])
    coef = np.linalg.solve(design.T @ (design * weights[:, None]), design.T @ (weights * y))
    return mean, spread, float(-coef[1])


def _pool_sensor(documents: Sequence[Mapping[str, Any]], sensor: int) -> dict[str, Any]:
    taus = np.array([value(d, "sensors", sensor, "time_constants", 0) for d in documents])
    stds = np.array([value(d, "sensors", sensor, "time_constants_std", 0) for d in documents])
    tau, tau_std, weighting = _weighted(taus, stds**2)
    models = [d.get("flow_model") if isinstance(d.get("flow_model"), Mapping) else {}
              for d in documents]
    exponents = np.array([_sensor_value(m, "exponent", sensor) for m in models])
    exponent_stds = np.array([_sensor_value(m, "exponent_std", sensor) for m in models])
    flow_models = [m.get("kind") not in (None, "constant") for m in models]
    exponent, exponent_std, _ = _weighted(
        np.where(flow_models, exponents, math.nan), exponent_stds**2
    )
    column = next((d["sensors"][sensor].get("column") for d in documents
                   if isinstance(d.get("sensors"), list) and len(d["sensors"]) > sensor), None)
    result: dict[str, Any] = {
        "sensor": sensor + 1,
        "column": column,
        "time_constant": tau,
        "time_constant_std": tau_std,
        "n_recordings": int(np.count_nonzero(np.isfinite(taus))),
        "weighting": weighting,
        "exponent": exponent,
        "exponent_std": exponent_std,
        "curve": None,
    }
    curves = [c for c in (_recording_curve(d, sensor) for d in documents) if c is not None]
    if not curves:
        return result
    low = min(c[0] for c in curves)
    high = max(c[1] for c in curves)
    grid = np.geomspace(low, high, GRID_POINTS)
    log_tau = np.full((len(curves), grid.size), math.nan)
    var = np.full_like(log_tau, math.nan)
    for row, (lo, hi, evaluate) in enumerate(curves):
        inside = (grid >= lo * (1 - 1e-9)) & (grid <= hi * (1 + 1e-9))
        if np.any(inside):
            log_tau[row, inside], var[row, inside] = evaluate(grid[inside])
    mean, spread, slope = _pooled_curve(grid, log_tau, var)
    counts = np.count_nonzero(np.isfinite(log_tau), axis=0)
    # The grid points share recordings, so their errors are correlated: the slope's std is the
    # jackknife over recordings (leave one out), not the least-squares formula.
    slope_std = math.nan
    if len(curves) >= 3 and math.isfinite(slope):
        rows = np.arange(len(curves))
        leave_one_out = np.array(
            [_pooled_curve(grid, log_tau[rows != k], var[rows != k])[2] for k in rows]
        )
        n = leave_one_out.size
        deviations = leave_one_out - leave_one_out.mean()
        slope_std = float(math.sqrt((n - 1) / n * float(deviations @ deviations)))
    result["curve"] = {
        "flow": grid.tolist(),
        "time_constants": np.exp(mean).tolist(),
        "time_constants_std": (np.exp(mean) * spread).tolist(),
        "n_recordings": counts.tolist(),
        "exponent": slope,
        "exponent_std": slope_std,
        "n_curves": len(curves),
    }
    return result


def pool_documents(documents: Sequence[Mapping[str, Any]], sensors: int = 2) -> dict[str, Any]:
    """The pooled document: per sensor the weighted time constant, exponent and curve."""
    with_flow = sum(1 for d in documents if _flow_law(d) is not None)
    return {
        "n_recordings": len(documents),
        "n_with_flow_model": with_flow,
        "sensors": [_pool_sensor(documents, index) for index in range(sensors)],
        "flow_delay": _pool_delay(documents),
    }


def _pool_delay(documents: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    """The flow delay over the recordings with a flow law (``flow_model.delay``, s): median
    (one recording whose law absorbed something else does not move it), range and count; NaN
    when none has one."""
    delays = np.array([value(d, "flow_model", "delay") for d in documents
                       if _flow_law(d) is not None])
    delays = delays[np.isfinite(delays)]
    if delays.size == 0:
        return {"median": math.nan, "min": math.nan, "max": math.nan, "n": 0}
    return {"median": float(np.median(delays)), "min": float(delays.min()),
            "max": float(delays.max()), "n": int(delays.size)}
