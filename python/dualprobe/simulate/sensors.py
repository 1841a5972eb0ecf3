"""Linear and hysteretic sensors driven by a gas profile, exactly; sensor pairs with noise and ADC.

A linear sensor ``gain / prod(1 + tau_i s)`` is integrated in closed form over every piece of
the profile, so steps and ramps that fall between samples are handled exactly. The sensor is
split into first-order modes (partial fractions) and the per-segment affine maps
``x -> a x + f`` are composed with a parallel prefix scan, so simulation is fully vectorised.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.signal

from dualprobe.simulate.profiles import _NCOEF, GasProfile, RngLike, _rng, _taylor_shift

__all__ = [
    "PT100_1P5MM_FIRST",
    "PT100_1P5MM_SECOND",
    "PT100_1P5MM_TAU_COOL",
    "PT100_1P5MM_TAU_HEAT",
    "PT100_4P5MM_FIRST",
    "PT100_4P5MM_SECOND",
    "THERMOCOUPLE_20MS",
    "THERMOCOUPLE_80MS",
    "PairRecording",
    "SensorModel",
    "difference_equation_pair",
    "simulate_hysteretic_sensor",
    "simulate_pair",
    "simulate_sensor",
]


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
