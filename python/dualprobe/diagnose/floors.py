"""What a perfect model would still leave: the noise of both signals (from the data, from the
logger's grid, or as given) and the sampling floor of a gas that changes between samples
(jumps at unknown instants, and the roughness of a continuously varying input that the
interpolation between samples cannot follow).

The noise of a channel is estimated from its second differences (``models.noise``, the one
estimator, with its quantisation floor) on the rows at which the logger refreshed it (every
``k``-th row when the reading is held), never below the rounding error of its grid,
``q / sqrt(12)``; when most second differences are exactly zero (noise below the reading's
resolution, noise-free data) only that floor is left, and nothing is ever below
:data:`RESOLUTION`. The output's level is refined on the residual of the baseline fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from dualprobe.diagnose.catalogue.logger import Grid, Hold, detect_grid, detect_hold
from dualprobe.models.noise import ORDER_DIAGNOSE, estimate_noise_std

__all__ = [
    "RESOLUTION",
    "ChannelNoise",
    "Floor",
    "channel_noise",
    "jump_density",
    "perfect_model_floor",
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
        # Most differences exactly zero: the noise is below the reading's resolution (the grid
        # below, or the resolution floor); the RMS of the differences, or the smallest step,
        # would measure the signal's changes (a noise-free step), not noise.
        std, source = 0.0, "resolution"
    if grid is not None and grid.floor > std:
        std, source = grid.floor, "grid"
    if std < RESOLUTION:
        std, source = RESOLUTION, "resolution"
    return ChannelNoise(float(std), source, hold, grid)


@dataclass(frozen=True)
class Floor:
    """Mean squares (K^2) a perfect model leaves: white noise of both signals and the roughness
    of a continuous input everywhere, and the residue of each gas jump between samples where it
    lives, decaying as exp(-2 t / tau) after the jump (`jump_density`, K^2 per row; its mean is
    `jumps`)."""

    white: float
    jumps: float  # averaged over the record
    roughness: float
    jump_density: np.ndarray

    @property
    def total(self) -> float:
        return self.white + self.jumps + self.roughness

    def regions(self) -> dict[str, tuple[np.ndarray, float]]:
        """Rows and floor of the parts of the record with their own floor: where the jumps'
        residue exceeds the white noise (the first time constants after large jumps) and the
        rest."""
        near = self.jump_density > self.white
        out = {}
        for name, rows in (("away_from_jumps", ~near), ("after_jumps", near)):
            if np.any(rows):
                level = self.white + self.roughness + float(np.mean(self.jump_density[rows]))
                out[name] = (rows, level)
        return out


def perfect_model_floor(u: np.ndarray, ts: float, tau: float, sigma_u: float, sigma_y: float,
                        *, interpolated: bool = True) -> Floor:
    """The floor of a model of dominant time constant ``tau`` driven by the reference ``u``:
    the output's white noise and the reference's through the sensor, and, when the model
    interpolates the reference between samples (not when it holds it, as the paper's eq. 8
    does), the residue of its jumps and of its roughness."""
    white = sigma_y**2 + sensor_noise_gain(ts, tau) * sigma_u**2
    if not interpolated:
        return Floor(white, 0.0, 0.0, np.zeros(u.size))
    return Floor(white, sampling_floor(u, ts, tau, sigma_u), roughness_floor(u, ts, tau, sigma_u),
                 jump_density(u, ts, tau, sigma_u))


def jump_density(u: np.ndarray, ts: float, tau: float, sigma_u: float) -> np.ndarray:
    """The jumps' residue per row: each jump's energy (see :func:`sampling_floor`) spread over
    the rows after it as the square of a first-order transient, (2/tau) exp(-2 t/tau)."""
    out = np.zeros(u.size)
    span = min(math.ceil(10.0 * tau / ts) + 1, u.size)
    decay = np.exp(-2.0 * np.arange(span) * ts / tau)
    shape = decay / (ts * float(np.sum(decay)))  # sum(shape) ts = 1: the energy is kept
    for start, _, jump in _jumps(u, sigma_u):
        energy = ts**2 / 12.0 * jump**2 / (2.0 * tau)  # K^2 s
        seg = min(span, u.size - start)
        out[start : start + seg] += energy * shape[:seg]
    return out


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
    """Jumps of the reference, as (first difference, end, size).

    Within each run of differences above 10 noise standard deviations of a difference, a jump
    is the largest difference with its neighbours down to 2 % of it (a reference that lags by a
    fraction of a sample spreads a jump over two or three), at most 3 differences, that is 3x
    larger than the differences around it; a run may hold several (a jump into a fluctuation or
    a ramp), a ramp none (its differences are alike, and interpolation follows it)."""
    du = np.diff(u)
    size = np.abs(du)
    big = size > max(10.0 * math.sqrt(2.0) * sigma_u, 1e-9)
    edges = np.flatnonzero(np.diff(np.concatenate(([0], big.astype(np.int8), [0]))))
    out = []
    for start, end in zip(edges[::2], edges[1::2], strict=True):
        free = np.ones(end - start, dtype=bool)
        while np.any(free):
            k = start + int(np.argmax(np.where(free, size[start:end], -1.0)))
            lo, hi = k, k + 1
            while (
                hi - lo < 3
                and lo > start
                and free[lo - 1 - start]
                and size[lo - 1] > 0.02 * size[k]
            ):
                lo -= 1
            while hi - lo < 3 and hi < end and free[hi - start] and size[hi] > 0.02 * size[k]:
                hi += 1
            free[lo - start : hi - start] = False
            around = max(size[lo - 1] if lo > 0 else 0.0, size[hi] if hi < size.size else 0.0)
            jump = float(np.sum(du[lo:hi]))
            if abs(jump) <= 3.0 * around:
                break  # the largest left is not a jump: neither is anything smaller
            out.append((int(lo), int(hi), jump))
    return sorted(out)


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
