"""``characterise_pair``: what ``dualprobe characterise`` calls. Checks the signals, estimates
the noise levels unless given, and runs the SVF (:mod:`dualprobe.estimation.svf`, the default
``method="auto"``) or the paper's difference method (:mod:`dualprobe.estimation.difference`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dualprobe.estimation.difference import characterise_difference
from dualprobe.estimation.result import PairEstimate
from dualprobe.estimation.svf import characterise_svf
from dualprobe.estimation.svf_backend import STATIC_MODELS
from dualprobe.io import InputError
from dualprobe.models.noise import ORDER_ESTIMATION, estimate_noise_std

__all__ = ["METHODS", "characterise_pair"]


METHODS = ("auto", "svf", "ls", "tls", "gtls")
_MIN_SAMPLES = 20


def _check_inputs(
    t1: np.ndarray, t2: np.ndarray, ts: float, method: str, order: int, hysteresis: bool
) -> tuple[np.ndarray, np.ndarray, float]:
    a = np.asarray(t1, dtype=float)
    b = np.asarray(t2, dtype=float)
    if a.ndim != 1 or a.shape != b.shape:
        raise InputError(f"characterise_pair: t1 and t2 must be 1-D of equal length, got {a.shape} "
                         f"and {b.shape}")
    for name, x in (("t1", a), ("t2", b)):
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise InputError(f"characterise_pair: {name}[{int(bad[0])}] is not finite")
    try:
        ts = float(ts)
    except (TypeError, ValueError):
        raise InputError(
            f"characterise_pair: sample interval must be a number, got {ts!r}") from None
    if not (math.isfinite(ts) and ts > 0.0):
        raise InputError(f"characterise_pair: sample interval must be finite and > 0, got {ts!r}")
    if method not in METHODS:
        raise InputError(f"characterise_pair: method must be one of {', '.join(METHODS)}, "
                         f"got {method!r}")
    if order not in (1, 2):
        raise InputError(f"characterise_pair: order must be 1 or 2, got {order!r}")
    if method in ("ls", "tls", "gtls") and (order != 1 or hysteresis):
        raise InputError(f"characterise_pair: method {method!r} (difference equation) is first "
                         "order without hysteresis; use method 'auto' for order 2 or hysteresis")
    if hysteresis and order != 1:
        raise InputError("characterise_pair: the hysteresis-aware estimate is first order; "
                         "use order=1 with hysteresis=True")
    return a, b, ts


def _noise_levels(
    t1: np.ndarray, t2: np.ndarray, noise_std: float | Sequence[float] | None
) -> tuple[tuple[float, float], str]:
    if noise_std is None:
        levels = tuple(estimate_noise_std(x, ORDER_ESTIMATION) for x in (t1, t2))
        return (levels[0], levels[1]), "estimated"
    values = np.atleast_1d(np.asarray(noise_std, dtype=float)).ravel()
    if values.size == 1:
        values = np.repeat(values, 2)
    if values.size != 2 or not np.all(np.isfinite(values)) or np.any(values < 0.0):
        raise InputError(f"characterise_pair: noise_std must be one or two finite values >= 0, "
                         f"got {noise_std!r}")
    return (float(values[0]), float(values[1])), "given"


def characterise_pair(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    *,
    method: str = "auto",
    order: int = 1,
    hysteresis: bool = False,
    noise_std: float | Sequence[float] | None = None,
    filter_time_constant: float | None = None,
    static_model: str = "auto",
) -> PairEstimate:
    """Identify the two sensors' time constants from their signals alone.

    ``method``: auto | svf (state-variable filter, design.md 1.4; auto = svf with the filter
    time constant chosen from the data) or ls | tls | gtls (the paper's difference method,
    first order only). ``noise_std``: white-noise standard deviation, one value or one per
    sensor; estimated from the signals when None. ``filter_time_constant``: the SVF's tf in
    seconds (None: automatic). ``static_model`` (SVF): "unit" (both sensors of unit static
    gain, design.md 1.4), "affine" (a gain ratio and an offset between the sensors are
    estimated too; reported in ``details``) or "auto" (affine only when it fits significantly
    better). Raises ValueError (dualprobe.io.InputError) for bad arguments;
    estimation failures are reported in ``status`` with ``details["message"]``.
    """
    a, b, ts = _check_inputs(t1, t2, ts, method, order, hysteresis)
    if filter_time_constant is not None and not (
        math.isfinite(filter_time_constant) and filter_time_constant > 0.0
    ):
        raise InputError(f"characterise_pair: filter_time_constant must be finite and > 0, "
                         f"got {filter_time_constant!r}")
    sigma, source = _noise_levels(a, b, noise_std) if a.size >= ORDER_ESTIMATION + 2 else (
        (0.0, 0.0), "too few samples")
    if a.size < _MIN_SAMPLES:
        return PairEstimate(
            status="insufficient_excitation", method=method, order=order, sample_interval=ts,
            time_constants=((float("nan"),) * order,) * 2, beta=None, noise_std=sigma,
            details={"message": f"{a.size} samples: at least {_MIN_SAMPLES} are needed"},
        )
    if method in ("ls", "tls", "gtls"):
        return characterise_difference(a, b, ts, method, sigma, source)
    if static_model not in ("auto", *STATIC_MODELS):
        raise InputError(f"characterise_pair: static_model must be auto, unit or affine, "
                         f"got {static_model!r}")
    return characterise_svf(a, b, ts, order, hysteresis, sigma, source, filter_time_constant,
                         static_model)
