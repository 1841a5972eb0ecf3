"""Where and how a model disagrees with the measurement: the sampling floor of off-grid gas
jumps, MATLAB-resid-style whiteness and cross-correlation tests, and the localisation of the
residual in time, regime, frequency and physics signatures."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import signal, stats

from dualprobe.diagnose.fit import ModelFit

__all__ = [
    "CONFIDENCE",
    "REGIME_THRESHOLD_NOISE",
    "WHITENESS_LAGS",
    "disagreement_windows",
    "effective_size",
    "localise",
    "moving_mean",
    "regime_masks",
    "residual_tests",
    "sampling_floor",
]


# Heating / cooling regime: the sensor is "after a change" while the gas differs from the
# simulated sensor by more than this many output noise standard deviations (and 0.2 K).
REGIME_THRESHOLD_NOISE = 5.0


WHITENESS_LAGS = 25  # as MATLAB resid
CONFIDENCE = 0.99  # resid's band


def sampling_floor(u: np.ndarray, ts: float, tau: float, sigma_u: float) -> float:
    """Mean square residual even a perfect model leaves because gas jumps fall between samples.

    A jump dT of the reference (changes of 14 noise standard deviations of a difference) happened
    at an unknown instant within a sample interval; interpolation puts it
    mid-interval, off by delta ~ U(-ts/2, ts/2). The first-order response to that shift is
    dT delta/tau exp(-t/tau), of energy dT^2 delta^2 / (2 tau), mean delta^2 = ts^2 / 12."""
    du = np.diff(u)
    size = np.abs(du)
    big = size > max(10.0 * math.sqrt(2.0) * sigma_u, 1e-9)
    # A jump is a run of at most 3 large differences (a reference with a lag of a fraction of a
    # sample spreads it over two or three), isolated: 3x larger than the differences around it.
    # Longer runs are ramps, which interpolation follows.
    edges = np.flatnonzero(np.diff(np.concatenate(([0], big.astype(np.int8), [0]))))
    total = 0.0
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        if end - start > 3:
            continue
        jump = float(np.sum(du[start:end]))
        around = max(size[start - 1] if start > 0 else 0.0, size[end] if end < size.size else 0.0)
        if abs(jump) > 3.0 * around:
            total += jump**2
    energy = ts**2 / 12.0 * total / (2.0 * tau)
    return energy / (u.size * ts)


def _autocorrelation(r: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased sample autocorrelation, lags 0..max_lag (FFT)."""
    r = r - r.mean()
    n = r.size
    size = 1 << (2 * n - 1).bit_length()
    spectrum = np.fft.rfft(r, size)
    acov = np.fft.irfft(spectrum * np.conj(spectrum), size)[: max_lag + 1] / n
    if acov[0] <= 0:
        return np.zeros(max_lag + 1)
    return acov / acov[0]


def effective_size(residual: np.ndarray, horizon: int) -> float:
    """N / (1 + 2 sum_k w_k rho_k) with a Bartlett taper over `horizon` lags (long-run variance
    of the residual): the number of independent samples the likelihood is worth."""
    n = residual.size
    horizon = int(min(max(horizon, 10), n // 5))
    rho = _autocorrelation(residual, horizon)[1:]
    weights = 1.0 - np.arange(1, horizon + 1) / (horizon + 1.0)
    inflation = max(1.0 + 2.0 * float(weights @ rho), 1.0)
    return n / inflation


def _cross_correlation(a: np.ndarray, b: np.ndarray, max_lag: int) -> np.ndarray:
    """corr(a(k), b(k - m)) for m = -max_lag..max_lag."""
    a = a - a.mean()
    b = b - b.mean()
    n = a.size
    size = 1 << (2 * n - 1).bit_length()
    cc = np.fft.irfft(np.fft.rfft(a, size) * np.conj(np.fft.rfft(b, size)), size)
    scale = n * a.std() * b.std()
    if scale <= 0:
        return np.zeros(2 * max_lag + 1)
    values = np.concatenate((cc[-max_lag:], cc[: max_lag + 1])) / scale
    return values


def residual_tests(
    residual: np.ndarray, reference: np.ndarray, ts: float, tau: float
) -> dict[str, Any]:
    """MATLAB-resid-like tests: residual autocorrelation and cross-correlation with the input
    increments (the prewhitened step input), with their 99 % bands; Ljung-Box whiteness."""
    n = residual.size
    band = stats.norm.ppf(0.5 + CONFIDENCE / 2) / math.sqrt(n)
    lags = int(min(max(WHITENESS_LAGS, round(2.0 * tau / ts)), n // 4))
    acf = _autocorrelation(residual, lags)
    q = (
        n
        * (n + 2)
        * float(np.sum(acf[1 : WHITENESS_LAGS + 1] ** 2 / (n - np.arange(1, WHITENESS_LAGS + 1))))
    )
    p_white = float(stats.chi2.sf(q, WHITENESS_LAGS))
    du = np.diff(reference, prepend=reference[0])
    xcf = _cross_correlation(residual, du, lags)
    outside_acf = float(np.mean(np.abs(acf[1:]) > band))
    outside_xcf = float(np.mean(np.abs(xcf) > band))
    return {
        "lags": lags,
        "band": band,
        "autocorrelation": acf,
        "cross_correlation": xcf,
        "ljung_box_q": q,
        "ljung_box_p": p_white,
        "white": bool(p_white > 1.0 - CONFIDENCE),
        "autocorrelation_outside_band": outside_acf,
        "cross_correlation_outside_band": outside_xcf,
        "input_independent": bool(outside_xcf <= 1.0 - CONFIDENCE + 0.02),
    }


def moving_mean(x: np.ndarray, width: int) -> np.ndarray:
    width = max(int(width), 1)
    kernel = np.ones(width) / width
    return np.convolve(x, kernel, mode="same")


def regime_masks(
    fit: ModelFit, reference: np.ndarray, ts: float, sigma: float
) -> dict[str, np.ndarray]:
    """Masks: heating / cooling (gas clearly hotter / colder than the simulated sensor, i.e. the
    seconds after a change) and steady; temperature level thirds."""
    smooth_ref = moving_mean(reference, max(3, round(0.5 / ts)))
    drive = smooth_ref - fit.prediction
    threshold = max(REGIME_THRESHOLD_NOISE * sigma, 0.2)
    heating = drive > threshold
    cooling = drive < -threshold
    low, high = np.quantile(reference, [1 / 3, 2 / 3])
    return {
        "heating": heating,
        "cooling": cooling,
        "steady": ~(heating | cooling),
        "level_low": reference <= low,
        "level_mid": (reference > low) & (reference <= high),
        "level_high": reference > high,
    }


def disagreement_windows(
    residual: np.ndarray, t: np.ndarray, ts: float, tau: float, sigma: float, limit: int = 5
) -> list[tuple[int, int]]:
    """Index ranges of the largest disagreement: runs where the moving RMS of the residual
    exceeds twice the noise (model error > 1.7 sigma) and 40 % of its peak (so that a model
    that is off everywhere still shows where it is worst), largest squared error first."""
    width = max(5, round(min(max(tau, 1.0), 0.05 * (t[-1] - t[0] + ts)) / ts))
    rms = np.sqrt(moving_mean(residual**2, width))
    threshold = max(2.0 * sigma, 0.4 * float(rms.max()), 1e-12)
    above = rms > threshold
    if not np.any(above):
        return []
    edges = np.flatnonzero(np.diff(np.concatenate(([0], above.astype(np.int8), [0]))))
    runs = [(int(s), int(e)) for s, e in zip(edges[::2], edges[1::2], strict=True)]
    merged: list[tuple[int, int]] = []
    for start, end in runs:
        if merged and start - merged[-1][1] < width // 2:
            merged[-1] = (merged[-1][0], end)
        else:
            merged.append((start, end))
    energy = [float(np.sum(residual[s:e] ** 2)) for s, e in merged]
    order = np.argsort(energy)[::-1][:limit]
    return [merged[i] for i in sorted(order, key=lambda i: -energy[i])]


def localise(
    fit: ModelFit, reference: np.ndarray, t: np.ndarray, ts: float, sigma: float
) -> dict[str, Any]:
    """Where the residual of `fit` lives: time windows, regimes, frequency bands and physics
    signatures (direction of heat flow, level, onset after a change)."""
    r = fit.residual
    total = float(np.sum(r**2)) or 1e-300
    tau = fit.tau
    windows = []
    masks = regime_masks(fit, reference, ts, sigma)
    for start, end in disagreement_windows(r, t, ts, tau, sigma):
        segment = slice(start, end)
        share_heat = float(np.mean(masks["heating"][segment]))
        share_cool = float(np.mean(masks["cooling"][segment]))
        regime = (
            "heating"
            if share_heat > max(share_cool, 0.3)
            else ("cooling" if share_cool > 0.3 else "steady")
        )
        windows.append(
            {
                "start": float(t[start]),
                "end": float(t[end - 1]),
                "rms": float(np.sqrt(np.mean(r[segment] ** 2))),
                "mean": float(np.mean(r[segment])),
                "share": float(np.sum(r[segment] ** 2) / total),
                "regime": regime,
            }
        )
    regimes = {}
    for name, mask in masks.items():
        count = int(mask.sum())
        regimes[name] = {
            "fraction_of_time": count / r.size,
            "rms": float(np.sqrt(np.mean(r[mask] ** 2))) if count else 0.0,
            "mean": float(np.mean(r[mask])) if count else 0.0,
            "share": float(np.sum(r[mask] ** 2) / total),
        }
    # Frequency: residual power by band relative to the sensor corner 1/(2 pi tau).
    nperseg = int(min(r.size, max(256, 2 ** math.ceil(math.log2(20 * tau / ts + 1)))))
    freq, psd = signal.welch(r, fs=1.0 / ts, nperseg=nperseg)
    corner = 1.0 / (2.0 * math.pi * tau)
    white = 2.0 * sigma**2 * ts
    df = freq[1] - freq[0] if freq.size > 1 else 1.0
    excess = np.clip(psd - white, 0.0, None) * df
    bands = {
        "static_below_corner/10": freq < corner / 10,
        "around_corner": (freq >= corner / 10) & (freq < 10 * corner),
        "fast_above_10x_corner": freq >= 10 * corner,
    }
    excess_total = float(excess.sum()) or 1e-300
    frequency = {name: float(excess[m].sum() / excess_total) for name, m in bands.items()}
    # Physics signatures.
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
    if np.sum(steady) > 10 and np.ptp(reference[steady]) > 0:
        level = reference[steady]
        signatures["corr_level_steady"] = float(np.corrcoef(r[steady], level)[0, 1])
        centred = (level - level.mean()) / (np.ptp(level) or 1.0)
        quad = centred**2 - np.mean(centred**2)
        quad = quad - centred * (quad @ centred) / max(centred @ centred, 1e-300)
        signatures["corr_curvature_steady"] = (
            float(np.corrcoef(r[steady], quad)[0, 1]) if np.ptp(quad) > 0 else 0.0
        )
    else:
        signatures["corr_level_steady"] = 0.0
        signatures["corr_curvature_steady"] = 0.0
    signatures.update(_onset_signature(r, reference, ts, tau, sigma))
    return {
        "windows": windows,
        "regimes": regimes,
        "frequency": frequency,
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
