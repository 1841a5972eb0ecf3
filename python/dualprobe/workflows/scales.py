"""Columns in very different units: sensor 2 brought to sensor 1's scale for the estimation,
and its static map and noise level given back in its own.

Why: the estimators' Gram matrices mix both sensors' filtered signals, so their conditioning
goes as the square of the scale ratio. Measured on a 15 min drive cycle with the mass flow
(4 / 12 s sensors, 0.05 K noise): the second column x1e-4 or x4e-5 (a type K thermocouple's
voltage in V) characterised like the first (time constants within 1 %), x1e-5 (a type S's)
"model misfit" at 4.3 / 12.9 s with negative misfits printed, x1e-6 a misfit of 15 000 times
the noise without the flow; the same pair with both columns x1e-6, or the second x1e6, exact.
The model is linear in sensor 2's scale (``T1 = g T2 + b``): scaling it by a power of ten
changes ``g`` and sensor 2's noise level, nothing else.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from dualprobe.estimation import PairEstimate

__all__ = ["SCALE_RATIO", "column_scale", "in_own_scale", "scale_note"]

# Beyond this ratio of the columns' spreads sensor 2 is rescaled. Below it results stay as they
# were bit for bit (degF against K: 1.8; mK against K: 1000 is rescaled, exactly as well fit).
SCALE_RATIO = 100.0


def _spread(x: np.ndarray) -> float:
    """The 5-95 % range: a few spikes or a start-up transient do not set the scale."""
    low, high = np.percentile(x, [5.0, 95.0])
    return float(high - low)


def column_scale(t1: np.ndarray, t2: np.ndarray) -> float:
    """The power of ten that brings sensor 2's spread to sensor 1's, or 1 where they are
    within ``SCALE_RATIO`` (or either does not vary: refused later as no excitation)."""
    a, b = _spread(t1), _spread(t2)
    if not (a > 0.0 and b > 0.0 and math.isfinite(a / b)):
        return 1.0
    ratio = a / b
    if 1.0 / SCALE_RATIO <= ratio <= SCALE_RATIO:
        return 1.0
    return float(10.0 ** round(math.log10(ratio)))


def scale_note(scale: float, columns: tuple[str, str]) -> str:
    factor, than = (scale, "less") if scale > 1.0 else (1.0 / scale, "more")
    return (f"{columns[1]} varies about {factor:g} times {than} than {columns[0]} (columns in "
            f"different units?): estimated as {scale:g} x {columns[1]}, its static map and "
            "noise level given in its own units")


def _times(value: object, factor: float) -> object:
    return float(value) * factor if isinstance(value, (int, float)) else value


def in_own_scale(estimate: PairEstimate, scale: float) -> PairEstimate:
    """``estimate`` of (t1, ``scale`` x t2) as an estimate of (t1, t2): the gain ratio of
    ``T1 = g T2 + b`` (value and uncertainties) times ``scale``, sensor 2's noise levels
    divided by it; time constants, flow law, offset and misfits are unchanged by it."""
    if scale == 1.0:
        return estimate
    details = dict(estimate.details)
    conf = estimate.confidence
    if details.get("static_model") != "affine":
        # unit gains chosen by evidence on the scaled pair: T1 = scale x T2 exactly, in the
        # affine model's terms (its map is what the summary and the JSON give)
        details.update(static_model="affine", gain_ratio=1.0, offset=0.0)
        if conf is not None:
            conf = replace(conf, values={**conf.values, "gain_ratio": 1.0, "offset": 0.0},
                           std={**conf.std, "gain_ratio": 0.0, "offset": 0.0})
    details["gain_ratio"] = _times(details.get("gain_ratio"), scale)
    used = details.get("noise_std_used")
    if isinstance(used, (list, tuple)) and len(used) == 2:
        details["noise_std_used"] = (float(used[0]), float(used[1]) / scale)
    if conf is not None:
        conf = replace(conf, **{name: {**table, **({"gain_ratio": table["gain_ratio"] * scale}
                                                   if "gain_ratio" in table else {})}
                                for name, table in (("values", conf.values), ("std", conf.std),
                                                    ("jackknife_std", conf.jackknife_std),
                                                    ("settings_std", conf.settings_std))})
    noise = (estimate.noise_std[0], estimate.noise_std[1] / scale)
    return replace(estimate, details=details, confidence=conf, noise_std=noise)
