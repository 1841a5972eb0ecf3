"""The catalogue of effects the diagnosis can name: one module per family, each with its
simulation, its parameters and its size (:mod:`.dynamics`: ``extra_pole``, ``hysteresis``,
``dead_time``; :mod:`.conditions`: ``flow_dependence``, ``level_dependence``; :mod:`.static`:
``offset``, ``gain``, ``nonlinearity``, ``drift``; :mod:`.logger`: ``sample_and_hold``,
``quantisation``); here the names, the order of simplicity, the units of every parameter and
the dispatch of parameters and sizes.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from dualprobe.diagnose.catalogue import conditions, dynamics, logger, static
from dualprobe.diagnose.catalogue.static import STATIC_EFFECTS

__all__ = [
    "EFFECTS",
    "FITTED_EFFECTS",
    "MIN_EFFECT_SIZE",
    "SIMPLICITY",
    "STATIC_EFFECTS",
    "UNITS",
    "Scale",
    "effect_params",
    "effect_size",
    "with_units",
]

# The fitted effects, then the one that is only detected (it changes the noise floor).
FITTED_EFFECTS = (
    "extra_pole",
    "hysteresis",
    "dead_time",
    "gain",
    "offset",
    "nonlinearity",
    "flow_dependence",
    "level_dependence",
    "drift",
    "sample_and_hold",
)
EFFECTS = (*FITTED_EFFECTS, "quantisation")
# Simplest first: constant bias, a detected logger hold (no fitted parameter), linear static
# map, a straight line in time, curved static map, pure shift, new linear dynamics, a time
# constant following the level, or a measured flow, nonlinear (direction-dependent) dynamics.
SIMPLICITY = (
    "offset",
    "sample_and_hold",
    "gain",
    "drift",
    "nonlinearity",
    "dead_time",
    "extra_pole",
    "level_dependence",
    "flow_dependence",
    "hysteresis",
)

MIN_EFFECT_SIZE: dict[str, float] = {
    **dynamics.MIN_SIZE,
    **static.MIN_SIZE,
    **conditions.MIN_SIZE,
    "sample_and_hold": 2.0,  # samples per refresh
    "quantisation": logger.MIN_STEP,  # K
}

UNITS = {
    "tau": "s",
    "tau_heat": "s",
    "tau_cool": "s",
    "tau2": "s",
    "delay": "s",
    "gain": "1",
    "offset": "K",
    "curvature": "1/K",
    "drift_rate": "K/h",
    "flow_exponent": "1",
    "flow_reference": "flow unit",
    "flow_delay": "s",  # located, not fitted: the flow at the sensor follows the column by it
    "level_exponent": "1",
    "level_reference": "K",
    "hold_samples": "samples",
    "hold_phase": "row index",
    "quantisation_step": "K",
    "quantisation_floor": "K",
    "initial": "degC",
    "input_hold": "",  # 1: the reference is held over each sample interval (paper eq. 8)
}

_KEYS = {
    "extra_pole": ("tau", "tau_heat", "tau_cool", "tau2"),
    "hysteresis": ("tau_heat", "tau_cool"),
    "dead_time": ("delay",),
    "gain": ("gain",),
    "offset": ("offset",),
    "nonlinearity": ("curvature",),
    "drift": ("drift_rate",),
    "flow_dependence": ("tau", "tau_heat", "tau_cool", "flow_exponent", "flow_reference",
                        "flow_delay"),
    "level_dependence": ("tau", "tau_heat", "tau_cool", "level_exponent", "level_reference"),
    "sample_and_hold": ("hold_samples", "hold_phase"),
    "quantisation": ("quantisation_step", "quantisation_floor"),
}


@dataclass(frozen=True)
class Scale:
    """What the sizes of the effects are measured against."""

    ts: float
    duration: float  # s
    x_range: tuple[float, float]  # 1st and 99th percentile of the output (degC)
    conditions: conditions.Conditions


def effect_params(effect: str, params: Mapping[str, float]) -> dict[str, float]:
    """The parameters that describe `effect` in a fitted parameter set."""
    return {k: float(params[k]) for k in _KEYS[effect] if k in params}


def with_units(params: Mapping[str, float]) -> dict[str, str]:
    """The unit of each parameter."""
    return {k: UNITS.get(k, "") for k in params}


def effect_size(effect: str, params: Mapping[str, float], tau: float, scale: Scale) -> float:
    """Size of `effect` in units of its smallest reported size (>= 1 passes)."""
    if effect in dynamics.MIN_SIZE:
        return dynamics.size(effect, params, tau, scale.ts)
    if effect in STATIC_EFFECTS:
        return static.size(effect, params, scale.x_range, scale.duration)
    if effect in conditions.MIN_SIZE:
        return conditions.size(effect, params, scale.conditions)
    if effect == "sample_and_hold":
        return params["hold_samples"] / MIN_EFFECT_SIZE["sample_and_hold"]
    raise ValueError(f"effect_size: unknown effect {effect!r}")
