"""The calibration out: identified time constants as a DCM file (``KONSERVIERUNG_FORMAT 2.0``),
the text format INCA and CANape import.

Written from the characterisation's JSON document (``Characterisation.to_json_dict()``):

* with a flow model (``flow_model.kind`` present and not ``"constant"``): per sensor a
  ``KENNLINIE <name> <n>`` of the dominant time constant (``WERT``, s) over the flow (``ST/X``):
  the model's ``curve`` (``{"flow": [...], "time_constants": [[...], [...]]}``) when given, else
  the power law ``tau_ref (v / v_ref)^-m`` (``sensors[i].time_constants[0]`` at
  ``flow_model.reference_flow``, ``flow_model.exponent`` one value or one per sensor) on a
  geometric grid over ``flow_model.flow_range`` (default v_ref/4 to 4 v_ref);
* otherwise a ``FESTWERT <name>`` per sensor with its dominant time constant;
* a second stage (order 2) as ``FESTWERT <name>_2``; heating / cooling time constants
  (hysteresis) as ``FESTWERT <name>_HEAT`` / ``<name>_COOL``;
* a gas-level term of the flow law (``flow_model.level_reference`` given): ``FESTWERT
  <name>_LEVEL`` (b, per unit of the temperature columns), ``<name>_LEVEL2`` (c, per unit
  squared; 0 when the document has none) and ``<name>_LEVEL_REF`` (the level the curve holds
  at): tau(flow, T) = curve(flow) exp(b dT + c dT^2), dT = T - T_ref;
* a flow delay (``flow_model.delay`` not 0): ``FESTWERT <name>_FLOW_DELAY`` (s): the curve
  holds for the flow channel that many seconds earlier (transport from where the flow is
  measured to the sensors).

Every entry has ``LANGNAME`` (what it is, which column), ``EINHEIT_W "s"`` and for curves
``EINHEIT_X`` (the flow unit, ``"-"`` when unknown). Names are configurable (one per sensor).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe.io.errors import EstimationError, InputError

__all__ = ["DEFAULT_NAMES", "dcm_text", "write_dcm"]

DEFAULT_NAMES = ("DP_TAU_S1", "DP_TAU_S2")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\[\]]*$")
_PER_LINE = 6
_GRID_POINTS = 9


def _number(value: float) -> str:
    return f"{value:.6f}"


def _rows(keyword: str, values: Sequence[float]) -> list[str]:
    return [
        f"   {keyword:<9} " + "   ".join(_number(v) for v in values[i : i + _PER_LINE])
        for i in range(0, len(values), _PER_LINE)
    ]


def _text(value: object) -> str:
    return " ".join(str(value).split()).replace('"', "'")


def _finite(values: Sequence[Any], what: str) -> list[float]:
    out = []
    for value in values:
        number = float("nan") if value is None else float(value)
        if not math.isfinite(number):
            raise EstimationError(f"DCM: {what} is not finite: nothing to calibrate")
        out.append(number)
    return out


def _festwert(name: str, langname: str, value: float, unit: str = "s") -> list[str]:
    return [
        f"FESTWERT {name}",
        f'   LANGNAME "{_text(langname)}"',
        f'   EINHEIT_W "{_text(unit)}"',
        *_rows("WERT", [value]),
        "END",
    ]


def _kennlinie(
    name: str, langname: str, flow: Sequence[float], taus: Sequence[float], unit: str
) -> list[str]:
    return [
        f"KENNLINIE {name} {len(flow)}",
        f'   LANGNAME "{_text(langname)}"',
        f'   EINHEIT_X "{_text(unit)}"',
        '   EINHEIT_W "s"',
        *_rows("ST/X", flow),
        *_rows("WERT", taus),
        "END",
    ]


def _per_sensor(value: Any, count: int) -> list[Any]:
    if isinstance(value, (list, tuple)):
        if len(value) != count:
            raise EstimationError(f"DCM: expected {count} values per sensor, got {len(value)}")
        return list(value)
    return [value] * count


def _curves(document: Mapping[str, Any], sensors: list[Mapping[str, Any]]) -> tuple[
    list[float], list[list[float]]
] | None:
    """(flow grid, dominant tau per sensor on it) from the flow model, None without one."""
    model = document.get("flow_model")
    if not isinstance(model, Mapping) or model.get("kind") in (None, "constant"):
        return None
    curve = model.get("curve")
    if isinstance(curve, Mapping) and curve.get("flow") and curve.get("time_constants"):
        flow = _finite(curve["flow"], "a flow of the curve")
        taus = []
        for index, values in enumerate(curve["time_constants"][: len(sensors)]):
            dominant = [v[0] if isinstance(v, (list, tuple)) else v for v in values]
            taus.append(_finite(dominant, f"a time constant of sensor {index + 1}'s curve"))
        if any(len(t) != len(flow) for t in taus) or len(taus) != len(sensors):
            raise EstimationError("DCM: the flow model's curve has inconsistent lengths")
        return flow, taus
    (reference,) = _finite([model.get("reference_flow")], "the reference flow")
    exponents = _finite(_per_sensor(model.get("exponent"), len(sensors)), "the flow exponent")
    low, high = model.get("flow_range") or (reference / 4.0, reference * 4.0)
    low, high = _finite([low, high], "the flow range")
    if not 0 < low < high:
        raise EstimationError(f"DCM: flow range {low:g}-{high:g} is not increasing and > 0")
    grid = np.geomspace(low, high, _GRID_POINTS)
    taus = []
    for index, (sensor, exponent) in enumerate(zip(sensors, exponents, strict=True)):
        (tau_ref,) = _finite(sensor["time_constants"][:1], f"sensor {index + 1}'s time constant")
        taus.append([float(v) for v in tau_ref * (grid / reference) ** -exponent])
    return [float(v) for v in grid], taus


def dcm_text(
    document: Mapping[str, Any],
    *,
    names: Sequence[str] = DEFAULT_NAMES,
    flow_unit: str | None = None,
    source: str | None = None,
) -> str:
    """The DCM file for a characterisation's JSON document (see the module docstring)."""
    sensors = list(document.get("sensors") or [])
    if not sensors:
        raise EstimationError("DCM: the characterisation has no sensors")
    if len(names) != len(sensors):
        raise InputError(f"DCM names: need {len(sensors)} (one per sensor), got {len(names)}")
    for name in names:
        if not _NAME.match(name):
            raise InputError(f"DCM name {name!r}: letters, digits, '_', '.', '[]' only")
    if len(set(names)) != len(names):
        raise InputError(f"DCM names must differ, got {', '.join(names)}")
    curves = _curves(document, sensors)
    model = document.get("flow_model") if curves else None
    unit = flow_unit or (model.get("unit") if isinstance(model, Mapping) else None) or "-"
    lines = [
        "* dualprobe: identified sensor time constants",
        f"* source {_text(source or document.get('source') or '-')}; method "
        f"{_text(document.get('method', '-'))}, order {_text(document.get('order', '-'))}",
        "",
        "KONSERVIERUNG_FORMAT 2.0",
        "",
    ]
    for index, (name, sensor) in enumerate(zip(names, sensors, strict=True)):
        column = sensor.get("column", f"sensor {index + 1}")
        taus = _finite(sensor.get("time_constants") or [None], f"sensor {index + 1}'s tau")
        what = f"sensor {index + 1} ({column})"
        if curves is not None:
            kind = _text(model.get("kind")) if isinstance(model, Mapping) else "flow"
            lines += _kennlinie(
                name, f"Time constant of {what} over flow ({kind})", curves[0],
                curves[1][index], unit,
            )
        else:
            lines += _festwert(name, f"Time constant of {what}", taus[0])
        lines.append("")
        if len(taus) > 1:
            lines += _festwert(f"{name}_2", f"Second time constant of {what}", taus[1])
            lines.append("")
        if isinstance(model, Mapping) and model.get("level_reference") is not None:
            # tau(flow, T) = curve(flow) * exp(LEVEL dT + LEVEL2 dT^2), dT = T - LEVEL_REF
            level, reference, curvature = _finite(
                [model.get("level_sensitivity"), model.get("level_reference"),
                 model.get("level_curvature", 0.0)], "the level term")
            lines += _festwert(f"{name}_LEVEL", f"Log change of {what}'s time constants per "
                               "unit of gas temperature", level, "1/T")
            lines.append("")
            lines += _festwert(f"{name}_LEVEL2", f"Curvature of the log of {what}'s time "
                               "constants in the gas temperature", curvature, "1/T^2")
            lines.append("")
            lines += _festwert(f"{name}_LEVEL_REF", f"Gas temperature of {what}'s curve",
                               reference, "T")
            lines.append("")
        if isinstance(model, Mapping) and model.get("delay"):
            (delay,) = _finite([model.get("delay")], "the flow delay")
            lines += _festwert(f"{name}_FLOW_DELAY", f"Delay from the flow channel to {what}'s "
                               "time constants", delay)
            lines.append("")
        for key, label in (("time_constants_heat", "HEAT"), ("time_constants_cool", "COOL")):
            if sensor.get(key):
                (value,) = _finite(sensor[key][:1], f"{what}'s {label.lower()} tau")
                lines += _festwert(f"{name}_{label}", f"Time constant of {what}, "
                                   f"{'heating' if label == 'HEAT' else 'cooling'}", value)
                lines.append("")
    return "\n".join(lines)


def write_dcm(
    document: Mapping[str, Any],
    path: str | os.PathLike[str],
    *,
    names: Sequence[str] = DEFAULT_NAMES,
    flow_unit: str | None = None,
    source: str | None = None,
) -> None:
    """Write :func:`dcm_text` to ``path`` (unwritable path: InputError)."""
    text = dcm_text(document, names=names, flow_unit=flow_unit, source=source)
    path = Path(path)
    try:
        path.write_text(text, encoding="utf-8")
    except OSError as exc:
        raise InputError(f"{path}: cannot write ({exc.strerror or exc})") from None
