"""``reconstruct_pair``: the gas temperature from a sensor pair, by the smoother (offline), the
causal filter (as on the ECU) or the exact inverse; ``reconstruct`` also returns its standard
deviation (the smoother's posterior)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dualprobe.models.inverse import zoh_inverse_pair
from dualprobe.reconstruction.checks import (
    as_sigma,
    as_static,
    as_taus,
    check_signals,
    effective_sigma,
)
from dualprobe.reconstruction.resolution import Bandwidth, bandwidth
from dualprobe.reconstruction.smoother import SmootherFit, fit_smoother, rescheduled_gas
from dualprobe.reconstruction.statespace import causal_filter

__all__ = ["MODES", "Reconstruction", "reconstruct", "reconstruct_pair"]

MODES = ("smoother", "filter", "inverse")


@dataclass(frozen=True, eq=False)
class Reconstruction:
    """The gas temperature at the sample instants (NaN where it cannot be formed), its
    standard deviation given the model (the smoother's posterior, or the causal filter's own
    variance as the ECU computes it, with a schedule's stated error added; NaN for the exact
    inverse), the mode,
    the smoother's fit when one ran, and the smoother's bandwidth (what ``gas_std`` covers;
    :mod:`~dualprobe.reconstruction.resolution`)."""

    gas: np.ndarray
    gas_std: np.ndarray
    mode: str
    fit: SmootherFit | None
    bandwidth: Bandwidth | None = None


def reconstruct(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    taus1: float | Sequence[float],
    taus2: float | Sequence[float],
    *,
    mode: str = "smoother",
    noise_std: float | Sequence[float] | None = None,
    taus1_cool: float | Sequence[float] | None = None,
    taus2_cool: float | Sequence[float] | None = None,
    relative_static: tuple[float, float] | None = None,
    schedule: np.ndarray | None = None,
    schedule_log_std: float = 0.0,
    near: SmootherFit | None = None,
) -> Reconstruction:
    """Gas temperature at the sample instants (NaN where it cannot be formed).

    ``taus1``/``taus2``: each sensor's time constants (1 or 2; heating ones when hysteretic),
    ``taus*_cool``: cooling time constants (same count) for hysteretic sensors. ``noise_std``:
    one value, one per sensor, or None to estimate it. ``mode``: smoother (offline, default),
    filter (causal, as on the ECU), inverse (the exact inverse of each sampled sensor,
    weighted). ``relative_static``: ``(gain_ratio, offset)`` of sensor 2 relative to sensor 1
    as ``characterise_pair`` reports them (``details``, affine static model
    ``P1 T1 = g P2 T2 + o``): sensor 2's samples are first mapped to sensor 1's calibration,
    ``g T2 + o``, and the result is the gas temperature as sensor 1 reads it (its gain times
    Tg plus its offset; two sensors alone cannot tell their common calibration). Without it
    both sensors are taken as unit-gain, zero-offset (design.md). ``schedule`` (N,): the time
    constants in effect at sample k are the given ones times ``schedule[k]`` (they follow the
    gas flow); the smoother and the filter take it, the exact inverse does not.
    ``schedule_log_std``: the standard deviation of the schedule's logarithm at each row (the
    time constants' relative error, e.g. the part of a tracked schedule that follows the
    noise): ``gas_std`` then adds, in quadrature, half the change of the gas between the
    schedule moved by this factor up and down (all else held; the delta method, row by row).
    ``near``: the smoother's fit with nearby time constants, to search from
    (:func:`~dualprobe.reconstruction.smoother.fit_smoother`).
    """
    if mode not in MODES:
        raise ValueError(f"reconstruct_pair: mode must be one of {', '.join(MODES)}, got {mode!r}")
    if not (math.isfinite(schedule_log_std) and schedule_log_std >= 0.0):
        raise ValueError(f"reconstruct_pair: schedule_log_std must be finite and >= 0, got "
                         f"{schedule_log_std}")
    y = check_signals(t1, t2, ts)
    sigma = as_sigma(noise_std)
    if relative_static is not None:
        gain, offset = as_static(relative_static)
        y[:, 1] = gain * y[:, 1] + offset
        if sigma is not None:
            sigma = (sigma[0], gain * sigma[1])
    taus = (as_taus("taus1", taus1), as_taus("taus2", taus2))
    if taus[0] is None or taus[1] is None:
        raise ValueError("reconstruct_pair: taus1 and taus2 are required")
    cool = (as_taus("taus1_cool", taus1_cool), as_taus("taus2_cool", taus2_cool))
    for i in range(2):
        c = cool[i]
        if c is not None and len(c) != len(taus[i]):
            raise ValueError(
                f"reconstruct_pair: taus{i + 1}_cool needs {len(taus[i])} time constants"
            )
    cool_full = (cool[0] or taus[0], cool[1] or taus[1])
    nan = np.full(y.shape[0], np.nan)
    if mode == "inverse":
        if schedule is not None:
            raise ValueError("reconstruct_pair: the exact inverse needs constant time constants")
        gas = zoh_inverse_pair(
            y[:, 0], y[:, 1], float(ts), taus[0], taus[1], taus1_cool=cool_full[0],
            taus2_cool=cool_full[1], noise_std=effective_sigma(y, sigma), aligned=True)
        return Reconstruction(gas, nan, mode, None)
    fit = fit_smoother(
        y[:, 0],
        y[:, 1],
        float(ts),
        taus[0],
        taus[1],
        noise_std=sigma,
        taus1_cool=cool[0],
        taus2_cool=cool[1],
        schedule=schedule,
        near=near,
    )
    moved = None
    if schedule is not None and schedule_log_std > 0.0:
        factor = math.exp(schedule_log_std)
        row = np.asarray(schedule, dtype=float)
        moved = (row * factor, row / factor)
    if mode == "smoother":
        std = fit.gas_std
        if moved is not None:
            change = 0.5 * (rescheduled_gas(fit, y, moved[0]) - rescheduled_gas(fit, y, moved[1]))
            std = np.hypot(std, change)
        return Reconstruction(fit.gas, std, mode, fit,
                              bandwidth(fit.model, fit.background_q, fit.sigma,
                                        steps_sharp=fit.increments == "student_t"))
    gas, variance = causal_filter(y - fit.offset, fit.model, fit.background_q, fit.sigma,
                                  schedule=schedule)
    std = np.sqrt(np.maximum(variance, 0.0))
    if moved is not None:
        up, down = (causal_filter(y - fit.offset, fit.model, fit.background_q, fit.sigma,
                                  schedule=s)[0] for s in moved)
        std = np.hypot(std, 0.5 * (up - down))
    return Reconstruction(gas + fit.offset, std, mode, fit)


def reconstruct_pair(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    taus1: float | Sequence[float],
    taus2: float | Sequence[float],
    **options: object,
) -> np.ndarray:
    """The gas temperature of :func:`reconstruct` (same arguments) at the sample instants."""
    return reconstruct(t1, t2, ts, taus1, taus2, **options).gas  # type: ignore[arg-type]
