"""Where a residual lives: the time windows of largest disagreement, its share by regime
(heating / cooling / settled, level bands and flow bands relative to the record's own range),
by frequency (bands relative to the sensor's corner, and the octave holding most of the excess
over the white floor), and physics signatures (direction of heat flow, level, onset after a
change)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal

from dualprobe.diagnose.fit import ModelFit
from dualprobe.diagnose.residuals import band_masks, direction_masks, disagreement_windows

__all__ = ["localise", "regime_table", "window_regime"]


def window_regime(masks: dict[str, np.ndarray], segment: slice) -> str:
    """The direction regime of a window: heating or cooling if it holds 30 % of it."""
    heat = float(np.mean(masks["heating"][segment]))
    cool = float(np.mean(masks["cooling"][segment]))
    return "heating" if heat > max(cool, 0.3) else ("cooling" if cool > 0.3 else "steady")


def _stats(r: np.ndarray, mask: np.ndarray, total: float) -> dict[str, float]:
    count = int(mask.sum())
    return {
        "fraction_of_time": count / r.size,
        "rms": float(np.sqrt(np.mean(r[mask] ** 2))) if count else 0.0,
        "mean": float(np.mean(r[mask])) if count else 0.0,
        "share_of_squared_error": float(np.sum(r[mask] ** 2) / total),
    }


def regime_table(
    r: np.ndarray,
    prediction: np.ndarray,
    reference: np.ndarray,
    ts: float,
    sigma: float,
    flow: np.ndarray | None = None,
) -> dict[str, dict[str, dict[str, Any]]]:
    """Residual statistics per regime, in groups whose regimes partition the record:
    ``direction`` (heating, cooling, steady), ``level`` (thirds of the reference's range, degC)
    and, with a flow, ``flow`` (thirds of its range)."""
    total = float(np.sum(r**2)) or 1e-300
    out: dict[str, dict[str, dict[str, Any]]] = {
        "direction": {
            name: _stats(r, mask, total)
            for name, mask in direction_masks(prediction, reference, ts, sigma).items()
        }
    }
    groups = [("level", reference)] + ([("flow", flow)] if flow is not None else [])
    for group, x in groups:
        out[group] = {
            name: {"range": list(edges), **_stats(r, mask, total)}
            for name, (edges, mask) in band_masks(x, ts).items()
        }
    return out


def _frequency(r: np.ndarray, ts: float, tau: float, sigma: float) -> dict[str, Any]:
    """Excess power over the white floor by band relative to the sensor corner 1/(2 pi tau),
    and the octave band that holds most of it."""
    nperseg = int(min(r.size, max(256, 2 ** math.ceil(math.log2(20 * tau / ts + 1)))))
    freq, psd = signal.welch(r, fs=1.0 / ts, nperseg=nperseg)
    corner = 1.0 / (2.0 * math.pi * tau)
    white = 2.0 * sigma**2 * ts
    df = freq[1] - freq[0] if freq.size > 1 else 1.0
    excess = np.clip(psd - white, 0.0, None) * df
    excess_total = float(excess.sum())
    scale = excess_total or 1e-300
    bands = {
        "static_below_corner/10": freq < corner / 10,
        "around_corner": (freq >= corner / 10) & (freq < 10 * corner),
        "fast_above_10x_corner": freq >= 10 * corner,
    }
    out: dict[str, Any] = {name: float(excess[m].sum() / scale) for name, m in bands.items()}
    nyquist = 0.5 / ts
    lowest = max(df, 1e-12)
    best = (0.0, 0.0, 0.0)
    high = nyquist * (1.0 + 1e-9)
    while high > lowest:
        low = high / 2.0
        share = float(excess[(freq >= low) & (freq < high)].sum() / scale)
        if share > best[0]:
            best = (share, low, min(high, nyquist))
        high = low
    out["dominant_band"] = {
        "low_hz": best[1],
        "high_hz": best[2],
        "share": best[0],
        "excess_rms": math.sqrt(excess_total),
    }
    return out


def localise(
    fit: ModelFit,
    reference: np.ndarray,
    t: np.ndarray,
    ts: float,
    sigma: float,
    flow: np.ndarray | None = None,
) -> dict[str, Any]:
    """Where the residual of `fit` lives: time windows, regimes, frequency bands and physics
    signatures (direction of heat flow, level, onset after a change)."""
    r = fit.residual
    total = float(np.sum(r**2)) or 1e-300
    tau = fit.tau
    masks = direction_masks(fit.prediction, reference, ts, sigma)
    windows = []
    for start, end in disagreement_windows(r, t, ts, tau, sigma):
        segment = slice(start, end)
        windows.append(
            {
                "start": float(t[start]),
                "end": float(t[end - 1]),
                "rms": float(np.sqrt(np.mean(r[segment] ** 2))),
                "mean": float(np.mean(r[segment])),
                "share": float(np.sum(r[segment] ** 2) / total),
                "regime": window_regime(masks, segment),
            }
        )
    signatures: dict[str, float] = {"mean_residual": float(np.mean(r))}
    # Residual signed by the direction of heat flow (> 0: the sensor is ahead of the model).
    # A wrong time constant gives the same sign in both directions, a direction-dependent one
    # (hysteresis) opposite signs.
    heat, cool = masks["heating"], masks["cooling"]
    lead_heat = float(np.mean(r[heat])) if np.any(heat) else 0.0
    lead_cool = float(-np.mean(r[cool])) if np.any(cool) else 0.0
    signatures["lead_heating"] = lead_heat
    signatures["lead_cooling"] = lead_cool
    signatures["direction_asymmetry"] = (lead_heat - lead_cool) / max(
        abs(lead_heat) + abs(lead_cool), 1e-300
    )
    steady = masks["steady"]
    signatures["corr_level_steady"] = 0.0
    signatures["corr_curvature_steady"] = 0.0
    if np.sum(steady) > 10 and np.ptp(reference[steady]) > 0 and np.ptp(r[steady]) > 0:
        level = reference[steady]
        signatures["corr_level_steady"] = float(np.corrcoef(r[steady], level)[0, 1])
        centred = (level - level.mean()) / (np.ptp(level) or 1.0)
        quad = centred**2 - np.mean(centred**2)
        quad = quad - centred * (quad @ centred) / max(centred @ centred, 1e-300)
        if np.ptp(quad) > 0:
            signatures["corr_curvature_steady"] = float(np.corrcoef(r[steady], quad)[0, 1])
    signatures.update(_onset_signature(r, reference, ts, tau, sigma))
    return {
        "windows": windows,
        "regimes": regime_table(r, fit.prediction, reference, ts, sigma, flow),
        "frequency": _frequency(r, ts, tau, sigma),
        "signatures": signatures,
    }


def _onset_signature(
    r: np.ndarray, reference: np.ndarray, ts: float, tau: float, sigma: float
) -> dict[str, float]:
    """Mean residual after the input's fast changes, signed by the change: its peak time (in
    units of tau; early and sharp for a dead time, later and smooth for an extra pole)."""
    step = np.diff(reference)
    threshold = max(10.0 * sigma, 1.0)
    onsets = np.flatnonzero(np.abs(step) > threshold)
    if onsets.size:
        keep = np.concatenate(([True], np.diff(onsets) > max(2, round(tau / ts))))
        onsets = onsets[keep]
    span = max(3, round(2.0 * tau / ts))
    profiles = [
        np.sign(step[k]) * r[k + 1 : k + 1 + span] for k in onsets if k + 1 + span <= r.size
    ]
    if not profiles:
        return {
            "onset_count": 0.0,
            "onset_peak_time_over_tau": float("nan"),
            "onset_mean_residual": 0.0,
        }
    mean_profile = np.mean(profiles, axis=0)
    peak = int(np.argmax(np.abs(mean_profile)))
    return {
        "onset_count": float(len(profiles)),
        "onset_peak_time_over_tau": float((peak + 1) * ts / tau),
        "onset_mean_residual": float(mean_profile[peak]),
    }
