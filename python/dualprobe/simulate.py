"""Simulation of dual-sensor recordings: sensor models, gas temperature profiles, noise, ADC.

Everything here is exact up to rounding: gas temperature profiles are piecewise polynomials
(degree <= 3, with jumps), and a linear sensor ``gain / prod(1 + tau_i s)`` is integrated in
closed form over every piece, so steps and ramps that fall between samples are handled exactly.
The sensor is split into first-order modes (partial fractions) and the per-segment affine maps
``x -> a x + f`` are composed with a parallel prefix scan, so simulation is fully vectorised.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import scipy.interpolate
import scipy.optimize
import scipy.signal

__all__ = [
    "PT100_1P5MM_FIRST",
    "PT100_1P5MM_SECOND",
    "PT100_1P5MM_TAU_COOL",
    "PT100_1P5MM_TAU_HEAT",
    "PT100_4P5MM_FIRST",
    "PT100_4P5MM_SECOND",
    "THERMOCOUPLE_20MS",
    "THERMOCOUPLE_80MS",
    "GasProfile",
    "PairRecording",
    "SensorModel",
    "constant_profile",
    "difference_equation_pair",
    "fluctuating_profile",
    "multistep_profile",
    "pt100_resistance",
    "pt100_temperature",
    "simulate_hysteretic_sensor",
    "simulate_pair",
    "simulate_sensor",
    "step_profile",
]

_DEGREE = 3  # profiles are piecewise cubic at most
_NCOEF = _DEGREE + 1

RngLike = np.random.Generator | int | None


def _rng(rng: RngLike) -> np.random.Generator:
    return rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)


# --------------------------------------------------------------------------------------------
# Sensor models
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SensorModel:
    """Linear sensor ``gain * exp(-delay s) / prod_i (1 + taus[i] s)`` (time constants in s).

    A zero time constant is an instantaneous pole and is ignored.
    """

    taus: tuple[float, ...]
    gain: float = 1.0
    delay: float = 0.0

    def __post_init__(self) -> None:
        taus = tuple(float(x) for x in np.atleast_1d(np.asarray(self.taus, dtype=float)))
        if not all(math.isfinite(x) and x >= 0.0 for x in taus):
            raise ValueError(f"SensorModel: time constants must be finite and >= 0, got {taus}")
        if not (math.isfinite(self.gain) and self.gain != 0.0):
            raise ValueError(f"SensorModel: gain must be finite and non-zero, got {self.gain}")
        if not (math.isfinite(self.delay) and self.delay >= 0.0):
            raise ValueError(f"SensorModel: delay must be finite and >= 0, got {self.delay}")
        object.__setattr__(self, "taus", taus)
        object.__setattr__(self, "gain", float(self.gain))
        object.__setattr__(self, "delay", float(self.delay))

    @property
    def order(self) -> int:
        """Number of (non-zero) poles."""
        return sum(1 for x in self.taus if x > 0.0)

    def transfer_function(self) -> scipy.signal.TransferFunction:
        """``gain / prod(1 + tau s)`` as a scipy.signal system (the dead time is not included)."""
        den = np.array([1.0])
        for tau in self.taus:
            if tau > 0.0:
                den = np.polymul(den, [tau, 1.0])
        return scipy.signal.TransferFunction([self.gain], den)

    def with_gain(self, gain: float) -> SensorModel:
        """Same dynamics, another steady-state gain (e.g. 1.0 for the estimator's model)."""
        return dataclasses.replace(self, gain=gain)


# Paper, Tables I and II (wire-wound Pt-100s at 15 m/s gas velocity).
PT100_1P5MM_FIRST = SensorModel((12.48,), gain=0.99)
PT100_1P5MM_SECOND = SensorModel((12.30, 0.17), gain=0.99)
PT100_4P5MM_FIRST = SensorModel((28.95,), gain=1.03)
PT100_4P5MM_SECOND = SensorModel((25.72, 1.08), gain=1.01)
# Paper, Figs. 15-16: heating and cooling time constants of the 1.5 mm Pt-100 (hysteresis).
PT100_1P5MM_TAU_HEAT = 21.96
PT100_1P5MM_TAU_COOL = 28.86
# Fine-wire thermocouple beads (typical exhaust-gas pair).
THERMOCOUPLE_20MS = SensorModel((0.020,))
THERMOCOUPLE_80MS = SensorModel((0.080,))


# --------------------------------------------------------------------------------------------
# Gas temperature profiles: piecewise polynomials with constant extension at both ends
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Exact simulation of linear sensors
# --------------------------------------------------------------------------------------------


def _phi(z: np.ndarray) -> np.ndarray:
    """``g_m(z) = z * int_0^1 exp(-z w) (1 - w)^m dw`` for m = 0..3, shape (4,) + z.shape.

    The zero-state response of ``x' = (u - x)/tau`` over a segment of length L to the input
    ``u = s^m`` is ``L^m g_m(L/tau)``. Series for small z (no cancellation), recurrence
    ``g_m = 1 - (m/z) g_{m-1}`` for larger z.
    """
    z_in = np.asarray(z, dtype=float)
    z = z_in.reshape(-1)
    out = np.empty((_NCOEF, z.size))
    small = z < 2.0
    zs = z[small]
    for m in range(_NCOEF):
        # z m! sum_j (-z)^j / (j+m+1)!, 30 terms: 2^30/31! is far below rounding
        term = np.full_like(zs, math.factorial(m) / math.factorial(m + 1))
        total = term.copy()
        for j in range(1, 30):
            term = term * (-zs) / (j + m + 1)
            total += term
        out[m][small] = zs * total
    zl = z[~small]
    g = -np.expm1(-zl)
    out[0][~small] = g
    for m in range(1, _NCOEF):
        g = 1.0 - (m / zl) * g
        out[m][~small] = g
    return out.reshape((_NCOEF, *z_in.shape))


def _modes(taus: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """Partial fractions: ``1/prod(1 + tau_i s) = sum_i r_i / (1 + tau_i s)``.

    Repeated (or nearly repeated, within 1e-6 relative) time constants are spread
    symmetrically about their mean by a small relative step d (1e-5 for a double pole, 3e-4
    otherwise). The symmetric spread keeps the sum of the taus, so the model changes by O(d^2)
    while the partial fractions lose O(eps/d^(k-1)): measured ~3e-11 relative for a double
    pole, ~3e-8 for a triple one (Jordan blocks would be exact but are not worth it here).
    """
    tau = np.sort(np.array([x for x in taus if x > 0.0], dtype=float))[::-1]
    if tau.size == 0:
        return tau, tau
    cluster_starts = [0] + [
        i for i in range(1, tau.size) if tau[i - 1] - tau[i] >= 1e-6 * tau[i - 1]
    ]
    bounds = [*cluster_starts, tau.size]
    for lo, hi in itertools.pairwise(bounds):
        k = hi - lo
        if k > 1:
            step = 1e-5 if k == 2 else 3e-4
            center = float(np.mean(tau[lo:hi]))
            tau[lo:hi] = center * (1.0 + step * ((k - 1) / 2.0 - np.arange(k)))
    residues = np.array(
        [
            tau[i] ** (tau.size - 1) / np.prod([tau[i] - tau[j] for j in range(tau.size) if j != i])
            for i in range(tau.size)
        ]
    )
    return tau, residues


def _prefix_affine(a: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inclusive prefix composition of affine maps ``x -> a[j] x + f[j]`` along the last axis.

    Hillis-Steele scan: log2(N) vector passes; numerically benign since |a| <= 1 (products
    only, no division).
    """
    a = a.copy()
    f = f.copy()
    n = a.shape[-1]
    shift = 1
    while shift < n:
        f[..., shift:] = a[..., shift:] * f[..., :-shift] + f[..., shift:]
        a[..., shift:] = a[..., shift:] * a[..., :-shift]
        shift *= 2
    return a, f


def _check_times(t: np.ndarray) -> np.ndarray:
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size == 0:
        raise ValueError("simulate: t must be a non-empty 1-D array of times")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0.0):
        raise ValueError("simulate: t must be finite and strictly increasing")
    return t


def _check_profile(profile: object) -> None:
    if not isinstance(profile, GasProfile):
        raise TypeError(
            f"expected a GasProfile, got {type(profile).__name__}; wrap sampled data with "
            "GasProfile.from_samples"
        )


def _segments(profile: GasProfile, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Union grid of sample times and profile breaks inside (t0, t_end).

    Returns (segment starts, segment lengths, index into the grid of each sample time - 1),
    i.e. the state at sample k (k >= 1) is the state at the end of segment ``sample_end[k-1]``.
    """
    inner = profile.breaks[(profile.breaks > t[0]) & (profile.breaks < t[-1])]
    grid = np.union1d(t, inner)
    starts = grid[:-1]
    lengths = np.diff(grid)
    sample_end = np.searchsorted(grid, t[1:]) - 1
    return starts, lengths, sample_end


def simulate_sensor(
    profile: GasProfile, sensor: SensorModel, t: np.ndarray, *, initial: float | None = None
) -> np.ndarray:
    """Noise-free sensor output at the times ``t`` (strictly increasing, any spacing).

    Exact (to rounding) for any profile, including jumps and ramps between samples. The
    sensor starts in steady state with the input at ``t[0]`` (i.e. ``gain * Tg(t0 - delay)``)
    unless ``initial`` (an output temperature) is given.
    """
    t = _check_times(t)
    _check_profile(profile)
    seen = profile.shifted(sensor.delay) if sensor.delay > 0.0 else profile
    u0 = float(seen(t[0]))
    x0 = u0 if initial is None else float(initial) / sensor.gain
    taus, residues = _modes(sensor.taus)
    if taus.size == 0:
        return sensor.gain * seen(t)
    starts, lengths, sample_end = _segments(seen, t)
    coeffs = seen.local_coefficients(starts, starts + 0.5 * lengths)  # (N, 4)
    z = lengths[None, :] / taus[:, None]  # (modes, N)
    g = _phi(z)  # (4, modes, N)
    powers = lengths[None, :] ** np.arange(_NCOEF)[:, None]  # (4, N)
    forced = np.einsum("nm,mn,mkn->kn", coeffs, powers, g)  # (modes, N)
    decay = np.exp(-z)
    a_cum, f_cum = _prefix_affine(decay, forced)
    states = a_cum[:, sample_end] * x0 + f_cum[:, sample_end]  # (modes, samples-1)
    out = np.empty(t.size)
    out[0] = x0
    out[1:] = residues @ states
    return sensor.gain * out


@dataclass
class PairRecording:
    """A simulated dual-sensor recording at the sample times ``t``.

    ``tg`` is the gas temperature at the sample instants, ``t1``/``t2`` the (noisy,
    quantised) sensor outputs, ``jumps`` the gas-temperature discontinuities within the record.
    """

    t: np.ndarray
    tg: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    ts: float
    jumps: np.ndarray
    t1_clean: np.ndarray | None = None
    t2_clean: np.ndarray | None = None
    noise_std: tuple[float, float] = (0.0, 0.0)
    quantisation: float = 0.0

    def to_csv(self, path: str | os.PathLike[str]) -> None:
        """Write columns ``t,T_m1,T_m2,T_g`` (round-trip precision)."""
        data = np.column_stack([self.t, self.t1, self.t2, self.tg])
        np.savetxt(path, data, delimiter=",", header="t,T_m1,T_m2,T_g", comments="", fmt="%.17g")

    def jump_mask(self, margin: int = 1) -> np.ndarray:
        """True for samples k with a gas jump in (t[k - margin], t[k + margin]] (clipped).

        Use it to exclude samples whose ZOH-based inverse mixes the levels either side of a step.
        """
        mask = np.zeros(self.t.size, dtype=bool)
        if self.jumps.size == 0:
            return mask
        idx = np.searchsorted(self.t, self.jumps, side="left")  # first sample at/after jump
        for off in range(-margin, margin):
            k = idx + off
            mask[k[(k >= 0) & (k < self.t.size)]] = True
        return mask


def simulate_pair(
    profile: GasProfile,
    sensor1: SensorModel,
    sensor2: SensorModel,
    *,
    ts: float,
    duration: float,
    noise_std: float | tuple[float, float] = (0.0, 0.0),
    quantisation: float = 0.0,
    rng: RngLike = None,
    start: float = 0.0,
) -> PairRecording:
    """Two sensors seeing ``profile``, sampled every ``ts`` from ``start`` to start + duration
    (inclusive, ``floor(duration/ts) + 1`` samples), plus white Gaussian noise of
    ``noise_std`` (one value or one per sensor) and ADC quantisation to multiples of
    ``quantisation`` (0 = none)."""
    if not (math.isfinite(ts) and ts > 0.0 and math.isfinite(duration) and duration >= ts):
        raise ValueError(f"simulate_pair: need ts > 0 and duration >= ts, got {ts}, {duration}")
    sig = np.broadcast_to(np.asarray(noise_std, dtype=float), (2,))
    if np.any(sig < 0.0) or not np.all(np.isfinite(sig)) or not quantisation >= 0.0:
        raise ValueError("simulate_pair: noise_std and quantisation must be finite and >= 0")
    gen = _rng(rng)
    n = math.floor(duration / ts + 1e-9) + 1
    t = start + ts * np.arange(n)
    clean1 = simulate_sensor(profile, sensor1, t)
    clean2 = simulate_sensor(profile, sensor2, t)
    noisy = [
        c + s * gen.standard_normal(n) if s > 0 else c.copy()
        for c, s in zip((clean1, clean2), sig, strict=True)
    ]
    if quantisation > 0.0:
        noisy = [np.round(x / quantisation) * quantisation for x in noisy]
    jumps = profile.jumps[(profile.jumps >= t[0]) & (profile.jumps <= t[-1])]
    return PairRecording(
        t=t,
        tg=profile(t),
        t1=noisy[0],
        t2=noisy[1],
        ts=float(ts),
        jumps=jumps.copy(),
        t1_clean=clean1,
        t2_clean=clean2,
        noise_std=(float(sig[0]), float(sig[1])),
        quantisation=float(quantisation),
    )


# --------------------------------------------------------------------------------------------
# Hysteretic first-order sensor
# --------------------------------------------------------------------------------------------


def _phi_scalar(z: float) -> tuple[float, float, float, float]:
    """Scalar version of :func:`_phi` (plain floats: this runs in a sequential loop)."""
    if z < 2.0:
        out = []
        for m in range(_NCOEF):
            term = math.factorial(m) / math.factorial(m + 1)
            total = term
            for j in range(1, 30):
                term *= -z / (j + m + 1)
                total += term
                if abs(term) < 1e-17 * abs(total):
                    break
            out.append(z * total)
        return out[0], out[1], out[2], out[3]
    g0 = -math.expm1(-z)
    g1 = 1.0 - g0 / z
    g2 = 1.0 - 2.0 * g1 / z
    return g0, g1, g2, 1.0 - 3.0 * g2 / z


def _poly(c: Sequence[float], s: float) -> float:
    return c[0] + s * (c[1] + s * (c[2] + s * c[3]))


def _segment_response(x0: float, c: Sequence[float], tau: float, s: float) -> float:
    """State after time s of ``x' = (u - x)/tau`` from x0, with u = sum c_m s^m."""
    g0, g1, g2, g3 = _phi_scalar(s / tau)
    return math.exp(-s / tau) * x0 + c[0] * g0 + s * (c[1] * g1 + s * (c[2] * g2 + s * c[3] * g3))


def simulate_hysteretic_sensor(
    profile: GasProfile,
    tau_heat: float,
    tau_cool: float,
    t: np.ndarray,
    *,
    initial: float | None = None,
) -> np.ndarray:
    """First-order unit-gain sensor with ``tau_heat`` while heating (Tg > T) and ``tau_cool``
    while cooling, at the times ``t``.

    Exact exponential integration of each polynomial piece; where T crosses Tg inside a piece
    the crossing is located by root finding and the time constant switched there. (Two
    crossings within one sample interval are resolved as none; near a crossing dT/dt ~ 0 with
    either time constant, so the error is second order.)
    """
    t = _check_times(t)
    _check_profile(profile)
    if not (tau_heat > 0.0 and tau_cool > 0.0):
        raise ValueError("simulate_hysteretic_sensor: time constants must be > 0")
    x = float(profile(t[0])) if initial is None else float(initial)
    starts, lengths, sample_end = _segments(profile, t)
    coeffs = profile.local_coefficients(starts, starts + 0.5 * lengths)
    ends = np.empty(starts.size)
    for j, (c_row, length) in enumerate(zip(coeffs.tolist(), lengths.tolist(), strict=True)):
        c = c_row
        remaining = length
        while True:
            diff0 = c[0] - x
            heating = diff0 > 0.0 or (diff0 == 0.0 and c[1] > 0.0)
            tau = tau_heat if heating else tau_cool
            x_end = _segment_response(x, c, tau, remaining)
            diff_end = _poly(c, remaining) - x_end
            if diff0 != 0.0 and diff_end != 0.0 and (diff_end > 0.0) != (diff0 > 0.0):

                def gap(s: float, c: list[float] = c, x: float = x, tau: float = tau) -> float:
                    return _poly(c, s) - _segment_response(x, c, tau, s)

                s_cross = scipy.optimize.brentq(gap, 0.0, remaining, xtol=1e-15, rtol=1e-15)
                if 0.0 < s_cross < remaining:
                    x = _poly(c, s_cross)  # on the crossing T = Tg
                    c = _taylor_shift(np.array(c), np.array(s_cross)).tolist()
                    remaining -= s_cross
                    continue
            x = x_end
            break
        ends[j] = x
    out = np.empty(t.size)
    out[0] = float(profile(t[0])) if initial is None else float(initial)
    out[1:] = ends[sample_end]
    return out


# --------------------------------------------------------------------------------------------
# Data that satisfy the discrete model (eq. 8) exactly
# --------------------------------------------------------------------------------------------


def difference_equation_pair(
    tg: np.ndarray,
    tau1: float,
    tau2: float,
    ts: float,
    t1_0: float | None = None,
    t2_0: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Sensor samples obeying ``T(k) = a T(k-1) + b Tg(k-1)`` (eq. 8) exactly for both sensors.

    ``tg`` are the gas samples Tg(0..N-1); returns T1(0..N-1), T2(0..N-1), starting at
    ``t1_0``/``t2_0`` (default: steady state ``tg[0]``).
    """
    tg = np.asarray(tg, dtype=float)
    if tg.ndim != 1 or tg.size < 1 or not np.all(np.isfinite(tg)):
        raise ValueError("difference_equation_pair: tg must be a finite 1-D array")
    if not (ts > 0.0 and tau1 > 0.0 and tau2 > 0.0):
        raise ValueError("difference_equation_pair: ts, tau1, tau2 must be > 0")
    out = []
    for tau, x0 in ((tau1, t1_0), (tau2, t2_0)):
        a = math.exp(-ts / tau)
        b = -math.expm1(-ts / tau)
        start = tg[0] if x0 is None else float(x0)
        # y[k] = a y[k-1] + b x[k-1]; the transposed direct form state is y[0]
        y = scipy.signal.lfilter([0.0, b], [1.0, -a], tg, zi=[start])[0]
        out.append(y)
    return out[0], out[1]


# --------------------------------------------------------------------------------------------
# Pt-100 (IEC 60751 Callendar-Van Dusen)
# --------------------------------------------------------------------------------------------

_R0 = 100.0
_A = 3.9083e-3
_B = -5.775e-7
_C = -4.183e-12
_T_MIN, _T_MAX = -200.0, 850.0  # IEC 60751 validity range (degC)


def pt100_resistance(temp_c: np.ndarray | float) -> np.ndarray | float:
    """Pt-100 resistance (ohm) at ``temp_c`` (degC), IEC 60751, valid -200..850 degC."""
    temp = np.asarray(temp_c, dtype=float)
    if not np.all(np.isfinite(temp)) or np.any((temp < _T_MIN) | (temp > _T_MAX)):
        raise ValueError(f"pt100_resistance: temperature outside {_T_MIN}..{_T_MAX} degC")
    cubic = np.where(temp < 0.0, _C * (temp - 100.0) * temp**3, 0.0)
    r = _R0 * (1.0 + _A * temp + _B * temp**2 + cubic)
    return float(r) if r.ndim == 0 else r


def pt100_temperature(resistance_ohm: np.ndarray | float) -> np.ndarray | float:
    """Inverse of :func:`pt100_resistance`: closed form at and above 0 degC, Newton below."""
    r = np.asarray(resistance_ohm, dtype=float) / _R0
    lo, hi = (pt100_resistance(_T_MIN) / _R0, pt100_resistance(_T_MAX) / _R0)
    if not np.all(np.isfinite(r)) or np.any((r < lo * (1 - 1e-12)) | (r > hi * (1 + 1e-12))):
        raise ValueError(
            f"pt100_temperature: resistance outside {lo * _R0:.4f}..{hi * _R0:.4f} ohm"
        )
    # Quadratic root in the cancellation-free form 2(r-1) / (A + sqrt(A^2 + 4B(r-1)))
    temp = 2.0 * (r - 1.0) / (_A + np.sqrt(_A**2 + 4.0 * _B * (r - 1.0)))
    below = r < 1.0
    if np.any(below):
        tb = temp[below]
        rb = r[below]
        for _ in range(50):  # quadratic start is within ~0.1 K: converges in 2-3 steps
            f = 1.0 + _A * tb + _B * tb**2 + _C * (tb - 100.0) * tb**3 - rb
            df = _A + 2.0 * _B * tb + _C * (4.0 * tb**3 - 300.0 * tb**2)
            step = f / df
            tb = tb - step
            if np.all(np.abs(step) <= 1e-13 * (1.0 + np.abs(tb))):
                break
        temp = temp.copy()
        temp[below] = tb
    return float(temp) if temp.ndim == 0 else temp
