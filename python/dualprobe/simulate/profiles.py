"""Gas temperature profiles: piecewise polynomials (degree <= 3, with jumps), exact to rounding.

Steps and ramps between samples are represented exactly, so the sensors driven by a profile
(:mod:`dualprobe.simulate.sensors`) can be integrated in closed form over every piece.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.interpolate

__all__ = [
    "GasProfile",
    "RngLike",
    "constant_profile",
    "fluctuating_profile",
    "multistep_profile",
    "step_profile",
]


_DEGREE = 3  # profiles are piecewise cubic at most
_NCOEF = _DEGREE + 1

RngLike = np.random.Generator | int | None


def _rng(rng: RngLike) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


@dataclass(frozen=True, eq=False)
class GasProfile:
    """Piecewise-cubic gas temperature ``Tg(t)``, right-continuous, with jumps allowed.

    ``breaks`` (P,) strictly increasing; ``coeffs`` (P+1, 4) ascending powers. Piece 0 covers
    ``t < breaks[0]`` and must be constant; piece p (1 <= p <= P) covers
    ``breaks[p-1] <= t < breaks[p]`` (the last one to +inf, constant again) and is a polynomial
    in ``t - breaks[p-1]``. ``jumps`` lists the breaks where the value is discontinuous.
    """

    breaks: np.ndarray
    coeffs: np.ndarray
    jumps: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        breaks = np.atleast_1d(np.asarray(self.breaks, dtype=float)).copy()
        coeffs = np.atleast_2d(np.asarray(self.coeffs, dtype=float)).copy()
        if breaks.ndim != 1 or coeffs.ndim != 2 or coeffs.shape[1] > _NCOEF:
            raise ValueError("GasProfile: breaks must be 1-D and coeffs (P+1, <=4)")
        coeffs = np.pad(coeffs, ((0, 0), (0, _NCOEF - coeffs.shape[1])))
        if coeffs.shape[0] != breaks.size + 1:
            raise ValueError(
                f"GasProfile: need len(coeffs) == len(breaks) + 1, "
                f"got {coeffs.shape[0]} and {breaks.size}"
            )
        if not (np.all(np.isfinite(breaks)) and np.all(np.isfinite(coeffs))):
            raise ValueError("GasProfile: breaks and coefficients must be finite")
        if np.any(np.diff(breaks) <= 0.0):
            raise ValueError("GasProfile: breaks must be strictly increasing")
        if np.any(coeffs[0, 1:] != 0.0) or (breaks.size and np.any(coeffs[-1, 1:] != 0.0)):
            raise ValueError("GasProfile: the two unbounded end pieces must be constant")
        breaks.setflags(write=False)
        coeffs.setflags(write=False)
        object.__setattr__(self, "breaks", breaks)
        object.__setattr__(self, "coeffs", coeffs)
        if breaks.size:
            origins = np.concatenate(([breaks[0]], breaks[:-1]))
            left = _horner(coeffs[:-1], breaks - origins)
            right = coeffs[1:, 0]
            scale = 1.0 + np.maximum(np.abs(left), np.abs(right))
            jumps = breaks[np.abs(right - left) > 1e-9 * scale]  # spline roundoff is ~1e-13
        else:
            jumps = np.empty(0)
        jumps.setflags(write=False)
        object.__setattr__(self, "jumps", jumps)

    # -- evaluation ------------------------------------------------------------------------
    def _locate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Piece index and local coordinate (t - piece origin) of each time (right-continuous)."""
        idx = np.searchsorted(self.breaks, t, side="right")
        if self.breaks.size == 0:
            return idx, np.zeros_like(t)
        origins = np.concatenate(([self.breaks[0]], self.breaks))
        return idx, t - origins[idx]

    def __call__(self, t: np.ndarray | float) -> np.ndarray:
        t_arr = np.asarray(t, dtype=float)
        idx, local = self._locate(t_arr)
        return _horner(self.coeffs[idx], local)

    def local_coefficients(self, start: np.ndarray, mid: np.ndarray) -> np.ndarray:
        """Coefficients (N, 4) of the piece containing ``mid``, re-expanded around ``start``."""
        idx, local_mid = self._locate(np.asarray(mid, dtype=float))
        shift = local_mid - (mid - start)  # = start - origin of the piece
        return _taylor_shift(self.coeffs[idx], shift)

    # -- construction helpers --------------------------------------------------------------
    def shifted(self, delay: float) -> GasProfile:
        """The profile delayed by ``delay`` seconds: ``t -> Tg(t - delay)``."""
        return GasProfile(self.breaks + delay, self.coeffs)

    def __add__(self, other: GasProfile | float) -> GasProfile:
        if not isinstance(other, GasProfile):
            coeffs = self.coeffs.copy()
            coeffs[:, 0] += float(other)
            return GasProfile(self.breaks, coeffs)
        breaks = np.union1d(self.breaks, other.breaks)
        if breaks.size == 0:
            return GasProfile(breaks, self.coeffs + other.coeffs)
        starts = np.concatenate(([breaks[0]], breaks))
        ends = np.concatenate((breaks, [breaks[-1]]))
        mids = 0.5 * (starts + ends)
        mids[0] = breaks[0] - 1.0
        mids[-1] = breaks[-1] + 1.0
        coeffs = self.local_coefficients(starts, mids) + other.local_coefficients(starts, mids)
        coeffs[0, 1:] = 0.0  # exact zeros for the unbounded pieces (remove shift roundoff)
        coeffs[-1, 1:] = 0.0
        return GasProfile(breaks, coeffs)

    __radd__ = __add__

    @classmethod
    def from_samples(cls, t: np.ndarray, values: np.ndarray, kind: str = "linear") -> GasProfile:
        """Profile through samples: ``linear`` interpolation, ``hold`` (zero-order hold, jumps
        at the sample times) or ``cubic`` (not-a-knot spline); constant outside the samples."""
        t = np.asarray(t, dtype=float)
        v = np.asarray(values, dtype=float)
        if t.ndim != 1 or t.shape != v.shape or t.size < 2:
            raise ValueError("GasProfile.from_samples: need two 1-D arrays of equal length >= 2")
        if np.any(np.diff(t) <= 0.0) or not np.all(np.isfinite(v)):
            raise ValueError("GasProfile.from_samples: times must increase, values be finite")
        coeffs = np.zeros((t.size + 1, _NCOEF))
        coeffs[0, 0] = v[0]
        coeffs[-1, 0] = v[-1]
        if kind == "hold":
            coeffs[1:-1, 0] = v[:-1]
            coeffs[-1, 0] = v[-1]
        elif kind == "linear":
            coeffs[1:-1, 0] = v[:-1]
            coeffs[1:-1, 1] = np.diff(v) / np.diff(t)
        elif kind == "cubic":
            spline = scipy.interpolate.CubicSpline(t, v, bc_type="not-a-knot")
            coeffs[1:-1, :] = spline.c[::-1].T  # scipy stores descending powers
        else:
            raise ValueError(f"GasProfile.from_samples: unknown kind {kind!r}")
        return cls(t, coeffs)


def _horner(coeffs: np.ndarray, x: np.ndarray) -> np.ndarray:
    out = coeffs[..., _DEGREE] * 1.0
    for m in range(_DEGREE - 1, -1, -1):
        out = out * x + coeffs[..., m]
    return out


def _taylor_shift(coeffs: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Coefficients of p(d + s) in s, for cubic p given in ascending powers (rows)."""
    c0, c1, c2, c3 = (coeffs[..., m] for m in range(_NCOEF))
    return np.stack(
        [
            c0 + d * (c1 + d * (c2 + d * c3)),
            c1 + d * (2.0 * c2 + 3.0 * d * c3),
            c2 + 3.0 * d * c3,
            c3,
        ],
        axis=-1,
    )


def constant_profile(value: float) -> GasProfile:
    """A constant gas temperature."""
    return GasProfile(np.empty(0), np.array([[float(value), 0.0, 0.0, 0.0]]))


def step_profile(t_step: float, before: float = 0.0, after: float = 1.0) -> GasProfile:
    """A single jump from ``before`` to ``after`` at ``t_step`` (any real time, off-grid fine)."""
    return GasProfile(
        np.array([float(t_step)]), np.array([[before, 0, 0, 0], [after, 0, 0, 0]], dtype=float)
    )


def multistep_profile(
    duration: float,
    *,
    levels: Sequence[float] | None = None,
    step_times: Sequence[float] | None = None,
    mean: float = 0.0,
    amplitude: float = 10.0,
    mean_hold: float | None = None,
    ramp_time: float | tuple[float, float] = 0.0,
    start: float = 0.0,
    rng: RngLike = None,
) -> GasProfile:
    """Piecewise-constant gas temperature with jumps (or linear ramps) between levels.

    Random by default: hold times uniform in [0.5, 1.5] * ``mean_hold`` (default duration/10),
    so step times fall off any sample grid; levels uniform in ``mean +/- amplitude``, each
    differing from the previous one by at least ``amplitude/4`` (every step excites the
    sensors). Give ``step_times`` and/or ``levels`` (len(step_times) + 1) to fix them.
    ``ramp_time``: 0 for jumps, a duration, or a (min, max) range drawn per step; the ramp
    starts at the step time and is clipped to 90 % of the following hold.
    """
    gen = _rng(rng)
    if not (math.isfinite(duration) and duration > 0.0):
        raise ValueError(f"multistep_profile: duration must be > 0, got {duration}")
    if step_times is None:
        hold = duration / 10.0 if mean_hold is None else float(mean_hold)
        if not hold > 0.0:
            raise ValueError(f"multistep_profile: mean_hold must be > 0, got {mean_hold}")
        n_max = math.ceil(2.0 * duration / hold) + 2
        times = start + np.cumsum(gen.uniform(0.5 * hold, 1.5 * hold, size=n_max))
        times = times[times < start + duration]
        if levels is not None:
            times = times[: len(levels) - 1]
    else:
        times = np.asarray(step_times, dtype=float)
    if np.any(np.diff(times) <= 0.0) or not np.all(np.isfinite(times)):
        raise ValueError("multistep_profile: step times must be finite and strictly increasing")
    if levels is None:
        lv = mean + amplitude * gen.uniform(-1.0, 1.0, size=times.size + 1)
        for k in range(1, lv.size):  # sequential by nature: redraw too-small changes
            while abs(lv[k] - lv[k - 1]) < 0.25 * amplitude:
                lv[k] = mean + amplitude * gen.uniform(-1.0, 1.0)
    else:
        lv = np.asarray(levels, dtype=float)
    if lv.size != times.size + 1:
        raise ValueError(
            f"multistep_profile: need len(levels) == len(step_times) + 1, "
            f"got {lv.size} and {times.size}"
        )
    if isinstance(ramp_time, tuple):
        ramps = gen.uniform(ramp_time[0], ramp_time[1], size=times.size)
    else:
        ramps = np.full(times.size, float(ramp_time))
    if np.any(ramps < 0.0):
        raise ValueError("multistep_profile: ramp times must be >= 0")
    following = np.append(np.diff(times), np.inf)
    ramps = np.minimum(ramps, 0.9 * following)

    breaks: list[float] = []
    coeffs: list[list[float]] = [[lv[0], 0.0, 0.0, 0.0]]
    for k, (tk, rk) in enumerate(zip(times, ramps, strict=True)):
        if rk > 0.0:
            breaks += [tk, tk + rk]
            coeffs += [[lv[k], (lv[k + 1] - lv[k]) / rk, 0.0, 0.0], [lv[k + 1], 0.0, 0.0, 0.0]]
        else:
            breaks.append(tk)
            coeffs.append([lv[k + 1], 0.0, 0.0, 0.0])
    return GasProfile(np.array(breaks), np.array(coeffs))


def fluctuating_profile(
    duration: float,
    *,
    mean: float = 0.0,
    std: float = 1.0,
    bandwidth: float = 1.0,
    start: float = 0.0,
    oversampling: int = 8,
    rng: RngLike = None,
) -> GasProfile:
    """Smooth band-limited random gas temperature around ``mean``.

    White Gaussian noise is low-passed with an ideal (brick-wall) filter at ``bandwidth`` Hz on
    a knot grid ``oversampling`` times finer than the Nyquist rate of the band, scaled to the
    exact standard deviation ``std`` over the knots, and interpolated by a C2 cubic spline
    (smooth and, with 8x oversampling, band-limited to well below 1 % leakage). The profile
    covers [start, start + duration] and is held constant outside.
    """
    gen = _rng(rng)
    if not (duration > 0.0 and bandwidth > 0.0 and std >= 0.0 and oversampling >= 2):
        raise ValueError(
            "fluctuating_profile: need duration > 0, bandwidth > 0, std >= 0, oversampling >= 2"
        )
    dt = 1.0 / (2.0 * oversampling * bandwidth)
    n = math.ceil(duration / dt) + 1
    n_fft = 2 * n  # padding: the FFT's periodic wrap-around does not join the two record ends
    spectrum = np.fft.rfft(gen.standard_normal(n_fft))
    spectrum[np.fft.rfftfreq(n_fft, dt) > bandwidth] = 0.0
    spectrum[0] = 0.0
    x = np.fft.irfft(spectrum, n_fft)[:n]
    x_std = float(np.std(x))
    x = mean + (std / x_std if x_std > 0.0 else 0.0) * (x - np.mean(x))
    return GasProfile.from_samples(start + dt * np.arange(n), x, kind="cubic")
