"""Tests of a residual: MATLAB-resid-style whiteness and cross-correlation with the input, the
effective sample size, and the regimes (heating, cooling, settled; level and flow bands)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import fft as sp_fft
from scipy import stats

__all__ = [
    "CONFIDENCE",
    "REGIME_THRESHOLD_NOISE",
    "WHITENESS_LAGS",
    "band_masks",
    "direction_masks",
    "disagreement_windows",
    "effective_size",
    "moving_mean",
    "residual_tests",
]


# Heating / cooling regime: the sensor is "after a change" while the gas differs from the
# simulated sensor by more than this many output noise standard deviations (and 0.2 K).
REGIME_THRESHOLD_NOISE = 5.0


WHITENESS_LAGS = 25  # as MATLAB resid
CONFIDENCE = 0.99  # resid's band


def _autocorrelation(r: np.ndarray, max_lag: int) -> np.ndarray:
    """Biased sample autocorrelation, lags 0..max_lag (FFT)."""
    r = r - r.mean()
    n = r.size
    # zero padding to n + max_lag makes the circular correlation exact up to max_lag
    size = sp_fft.next_fast_len(n + max_lag + 1, real=True)
    spectrum = sp_fft.rfft(r, size)
    acov = sp_fft.irfft(spectrum * np.conj(spectrum), size)[: max_lag + 1] / n
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
    # a short record (a plunge's refresh rows) has fewer lags than the test's 25
    tested = min(WHITENESS_LAGS, lags)
    q = n * (n + 2) * float(np.sum(acf[1 : tested + 1] ** 2 / (n - np.arange(1, tested + 1))))
    p_white = float(stats.chi2.sf(q, tested))
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
    """Centred moving mean over `width` samples; near the ends, over the samples there are
    (not pulled towards 0 by zero padding)."""
    width = max(int(width), 1)
    kernel = np.ones(width)
    total = np.convolve(x, kernel, mode="same")
    count = np.convolve(np.ones(x.size), kernel, mode="same")
    return total / count


def direction_masks(
    prediction: np.ndarray, reference: np.ndarray, ts: float, sigma: float
) -> dict[str, np.ndarray]:
    """Heating / cooling (gas clearly hotter / colder than the simulated sensor, i.e. the
    seconds after a change) and steady: each sample in exactly one."""
    smooth_ref = moving_mean(reference, max(3, round(0.5 / ts)))
    drive = smooth_ref - prediction
    threshold = max(REGIME_THRESHOLD_NOISE * sigma, 0.2)
    heating = drive > threshold
    cooling = drive < -threshold
    return {"heating": heating, "cooling": cooling, "steady": ~(heating | cooling)}


def band_masks(x: np.ndarray, ts: float) -> dict[str, tuple[tuple[float, float], np.ndarray]]:
    """Thirds of the record's own range of `x` (0.5th to 99.5th percentile of its 1-s moving
    mean): low, mid, high, each with its range; every sample in exactly one band. A record
    whose range is nil is one band, "all"."""
    smooth = moving_mean(x, max(1, round(1.0 / ts)))
    lo, hi = (float(v) for v in np.quantile(smooth, [0.005, 0.995]))
    if not hi > lo:
        return {"all": ((float(np.min(x)), float(np.max(x))), np.ones(x.size, dtype=bool))}
    first, second = lo + (hi - lo) / 3.0, lo + 2.0 * (hi - lo) / 3.0
    return {
        "low": ((lo, first), smooth < first),
        "mid": ((first, second), (smooth >= first) & (smooth < second)),
        "high": ((second, hi), smooth >= second),
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
