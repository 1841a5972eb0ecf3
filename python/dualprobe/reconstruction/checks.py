"""Argument checks of the reconstruction and the noise levels it works with."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dualprobe.models.inverse import as_time_constants
from dualprobe.models.noise import ORDER_RECONSTRUCTION, estimate_noise_std

__all__ = [
    "MIN_SAMPLES",
    "as_sigma",
    "as_static",
    "as_taus",
    "check_signals",
    "effective_sigma",
]

MIN_SAMPLES = 8  # fewer: no noise level, no intensity can be estimated
_SIGMA_FLOOR_REL = 1e-9  # smallest noise level, relative to the signal scale (exact data)


def as_taus(name: str, taus: float | Sequence[float] | None) -> tuple[float, ...] | None:
    """:func:`~dualprobe.models.inverse.as_time_constants` for reconstruct_pair's arguments."""
    return as_time_constants("reconstruct_pair", name, taus)


def as_sigma(noise_std: float | Sequence[float] | None) -> tuple[float, float] | None:
    if noise_std is None:
        return None
    values = np.broadcast_to(np.asarray(noise_std, dtype=float), (2,))
    if not np.all(np.isfinite(values)) or np.any(values < 0.0):
        raise ValueError(f"reconstruct_pair: noise_std must be finite and >= 0, got {noise_std}")
    return float(values[0]), float(values[1])


def as_static(static: Sequence[float]) -> tuple[float, float]:
    values = np.asarray(static, dtype=float)
    if values.shape != (2,) or not np.all(np.isfinite(values)) or not values[0] > 0.0:
        raise ValueError(
            f"reconstruct_pair: relative_static must be (gain_ratio > 0, offset), finite, "
            f"got {static!r}"
        )
    return float(values[0]), float(values[1])


def check_signals(t1: np.ndarray, t2: np.ndarray, ts: float) -> np.ndarray:
    a = np.asarray(t1, dtype=float)
    b = np.asarray(t2, dtype=float)
    if a.ndim != 1 or b.ndim != 1 or a.shape != b.shape:
        raise ValueError(
            f"reconstruct_pair: t1 and t2 must be 1-D of equal length, got {a.shape}, {b.shape}"
        )
    if a.size < MIN_SAMPLES:
        raise ValueError(f"reconstruct_pair: need >= {MIN_SAMPLES} samples, got {a.size}")
    for name, x in (("t1", a), ("t2", b)):
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise ValueError(f"reconstruct_pair: {name} is not finite at sample {bad[0]}")
    if not (isinstance(ts, (int, float, np.floating)) and math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"reconstruct_pair: ts must be finite and > 0, got {ts}")
    return np.column_stack([a, b])


def effective_sigma(y: np.ndarray, sigma: tuple[float, float] | None) -> np.ndarray:
    """Given or estimated noise levels, floored (exact data still needs R > 0)."""
    est = (
        np.array([estimate_noise_std(y[:, i], ORDER_RECONSTRUCTION) for i in range(2)])
        if sigma is None
        else np.array(sigma)
    )
    scale = float(np.max(np.abs(y))) + 1.0
    return np.maximum(est, _SIGMA_FLOOR_REL * scale)
