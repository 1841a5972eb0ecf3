"""What a perfect model would still leave: the noise of both signals (from the data, from the
logger's grid, or as given) and the sampling floor of a gas that changes between samples
(jumps at unknown instants, and the roughness of a continuously varying input that the
interpolation between samples cannot follow).

The noise of a channel is estimated from its second differences (``models.noise``, the one
estimator) on the rows at which the logger refreshed it (every ``k``-th row when the reading is
held), never below the rounding error of its grid, ``q / sqrt(12)``; when most differences are
exactly zero (a reading finer than its noise cannot be, noise-free data) only that floor is
left, and nothing is ever below :data:`RESOLUTION`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from dualprobe.diagnose.catalogue.logger import Grid, Hold, detect_grid, detect_hold
from dualprobe.models.noise import ORDER_DIAGNOSE, estimate_noise_std, quantisation_floor

__all__ = [
    "RESOLUTION",
    "ChannelNoise",
    "Floor",
    "channel_noise",
    "jump_neighbourhood",
    "refine_noise",
    "roughness_floor",
    "sampling_floor",
    "sensor_noise_gain",
]

# 0.1 mK: below the resolution of any thermometer; the noise level of noise-free data.
RESOLUTION = 1e-4


@dataclass(frozen=True)
class ChannelNoise:
    """The white-noise level of one channel and how it was found."""

    std: float  # K
    source: str  # "given", "differences", "grid" (q / sqrt(12)) or "resolution"
    hold: Hold | None
    grid: Grid | None


def channel_noise(x: np.ndarray, given: float | None = None) -> ChannelNoise:
    """Noise level of a channel (`given` wins when not None)."""
    hold = detect_hold(x)
    grid = detect_grid(x)
    if given is not None:
        return ChannelNoise(float(given), "given", hold, grid)
    series = x[hold.phase :: hold.samples] if hold is not None else x
    if series.size < ORDER_DIAGNOSE + 2:
        series = x
    d = np.diff(series, n=ORDER_DIAGNOSE)
    if float(np.median(np.abs(d - np.median(d)))) > 0.0:
        std, source = estimate_noise_std(series, ORDER_DIAGNOSE), "differences"
    else:
        # Most differences exactly zero: the noise is below the reading's resolution; the RMS
        # of the differences would measure the signal's changes, not noise.
        std, source = quantisation_floor(series), "grid"
    if grid is not None and grid.floor > std:
        std, source = grid.floor, "grid"
    if std < RESOLUTION:
        std, source = RESOLUTION, "resolution"
    return ChannelNoise(float(std), source, hold, grid)


@dataclass(frozen=True)
class Floor:
    """Mean squares (K^2) a perfect model leaves: white noise of both signals everywhere, the
    residue of gas jumps between samples in the few time constants after each jump
    (`near_jumps`), the roughness of a continuous input everywhere."""

    white: float
    jumps: float  # averaged over the record
    roughness: float
    near_jumps: np.ndarray  # rows within JUMP_SETTLING time constants after a jump

    @property
    def total(self) -> float:
        return self.white + self.jumps + self.roughness

    def regions(self) -> dict[str, tuple[np.ndarray, float]]:
        """Rows and floor of the parts of the record with their own floor: away from the jumps
        (white noise and roughness only) and after them (plus the jumps' residue there)."""
        near = self.near_jumps
        count = int(near.sum())
        away = self.white + self.roughness
        out = {"away_from_jumps": (~near, away)}
        if count:
            out["after_jumps"] = (near, away + self.jumps * near.size / count)
        return out


# A jump's residue decays as exp(-t/tau): 5 tau hold all but e^-10 of its energy.
JUMP_SETTLING = 5.0


def jump_neighbourhood(u: np.ndarray, ts: float, tau: float, sigma_u: float) -> np.ndarray:
    """Rows within JUMP_SETTLING time constants after a jump of the reference."""
    mark = np.zeros(u.size + 1)
    span = math.ceil(JUMP_SETTLING * tau / ts) + 2
    for start, _, _ in _jumps(u, sigma_u):
        mark[start] += 1.0
        mark[min(start + span, u.size)] -= 1.0
    return np.cumsum(mark[:-1]) > 0.0


def refine_noise(noise: ChannelNoise, residual: np.ndarray) -> ChannelNoise:
    """The output's noise from the residual of a fitted model when that is lower: the model
    removes the signal, whose curvature (a sensor moving most of the time, a gas fluctuating
    near the Nyquist frequency) inflates the differences of the output itself. Same estimator,
    same refresh rows, same floors."""
    rows = residual[noise.hold.phase :: noise.hold.samples] if noise.hold is not None else residual
    if rows.size < ORDER_DIAGNOSE + 2:
        return noise
    d = np.diff(rows, n=ORDER_DIAGNOSE)
    if not float(np.median(np.abs(d - np.median(d)))) > 0.0:
        return noise
    std = max(
        estimate_noise_std(rows, ORDER_DIAGNOSE),
        noise.grid.floor if noise.grid is not None else 0.0,
        RESOLUTION,
    )
    if std >= noise.std:
        return noise
    return ChannelNoise(float(std), "residual differences", noise.hold, noise.grid)


def sensor_noise_gain(ts: float, tau: float) -> float:
    """Output variance of the first-order sensor per unit variance of white input noise."""
    h = ts / tau
    return -math.expm1(-h) / (1.0 + math.exp(-h))


def _jumps(u: np.ndarray, sigma_u: float) -> list[tuple[int, int, float]]:
    """Jumps of the reference: runs of at most 3 differences above 10 noise standard deviations
    of a difference (a reference with a lag of a fraction of a sample spreads a jump over two or
    three), isolated: 3x larger than the differences around it. Longer runs are ramps, which
    interpolation follows."""
    du = np.diff(u)
    size = np.abs(du)
    big = size > max(10.0 * math.sqrt(2.0) * sigma_u, 1e-9)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], big.astype(np.int8), [0]))))
    out = []
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        if end - start > 3:
            continue
        jump = float(np.sum(du[start:end]))
        around = max(size[start - 1] if start > 0 else 0.0, size[end] if end < size.size else 0.0)
        if abs(jump) > 3.0 * around:
            out.append((int(start), int(end), jump))
    return out


def sampling_floor(u: np.ndarray, ts: float, tau: float, sigma_u: float) -> float:
    """Mean square residual even a perfect model leaves because gas jumps fall between samples.

    A jump dT of the reference happened at an unknown instant within a sample interval;
    interpolation puts it mid-interval, off by delta ~ U(-ts/2, ts/2). The first-order response
    to that shift is dT delta/tau exp(-t/tau), of energy dT^2 delta^2 / (2 tau), mean
    delta^2 = ts^2 / 12."""
    total = sum(jump**2 for _, _, jump in _jumps(u, sigma_u))
    energy = ts**2 / 12.0 * total / (2.0 * tau)
    return energy / (u.size * ts)


def roughness_floor(u: np.ndarray, ts: float, tau: float, sigma_u: float) -> float:
    """Mean square residual a perfect model leaves because a continuously varying input is
    curved between its samples and the model interpolates it linearly.

    Over an interval the linear interpolation misses the mean of a curved input by
    ``-u'' ts^2 / 12`` = ``-(second difference) / 12``; the sensor filters that error. Its
    mean square through the fitted first-order sensor, less what the reference noise alone
    gives (the second difference of white noise through the same filter), away from the jumps
    (their residue is :func:`sampling_floor`)."""
    if u.size < 3:
        return 0.0
    d2 = np.zeros(u.size)
    d2[1:-1] = u[2:] - 2.0 * u[1:-1] + u[:-2]
    for start, end, _ in _jumps(u, sigma_u):
        d2[max(start - 1, 0) : end + 2] = 0.0
    a = math.exp(-ts / tau)
    filtered = signal.lfilter([1.0 - a], [1.0, -a], d2 / 12.0)
    length = int(min(u.size, 20.0 * tau / ts + 10))
    impulse = np.zeros(length)
    impulse[:3] = (1.0, -2.0, 1.0)
    response = signal.lfilter([1.0 - a], [1.0, -a], impulse)
    noise_part = sigma_u**2 / 144.0 * float(np.sum(response**2))
    return max(float(np.mean(filtered**2)) - noise_part, 0.0)
