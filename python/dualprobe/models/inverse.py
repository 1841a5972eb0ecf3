"""The exact inverse of a sampled sensor (the paper's eq. 8, generalised): the one
implementation of the package (:mod:`dualprobe.reference.difference` keeps its own, independent
first-order one as a check).

A chain of 1 or 2 first-order stages sampled with the gas held over each sample interval
(zero-order hold) is inverted exactly: :func:`zoh_inverse` returns the held gas temperature of
each interval, for linear or hysteretic stages; :func:`zoh_inverse_pair` combines both
sensors with inverse-variance weights (:func:`inverse_noise_gain`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.signal

__all__ = [
    "as_time_constants",
    "inverse_noise_gain",
    "zoh_inverse",
    "zoh_inverse_pair",
]

_MAX_INVERSE_TAIL = 1_000_000  # samples of the inverse's impulse response for its noise gain


def as_time_constants(
    caller: str, name: str, taus: float | Sequence[float] | None
) -> tuple[float, ...] | None:
    """``taus`` as 1 or 2 finite positive time constants (None stays None); a ValueError
    naming ``caller`` and ``name`` otherwise."""
    if taus is None:
        return None
    values = np.atleast_1d(np.asarray(taus, dtype=float))
    if values.ndim != 1 or values.size not in (1, 2):
        raise ValueError(f"{caller}: {name} must hold 1 or 2 time constants")
    if not np.all(np.isfinite(values)) or np.any(values <= 0.0):
        raise ValueError(f"{caller}: {name} must be finite and > 0, got {values}")
    return tuple(float(v) for v in values)


def _stage_zoh(taus: Sequence[float], ts: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact ZOH discretisation of a chain of first-order stages (the first sees the input):
    ``z(k+1) = Phi z(k) + Gamma u(k)``."""
    return _stage_zoh_cached(tuple(float(t) for t in taus), float(ts))


@functools.lru_cache(maxsize=64)
def _stage_zoh_cached(taus: tuple[float, ...], ts: float) -> tuple[np.ndarray, np.ndarray]:
    count = len(taus)
    big = np.zeros((count + 1, count + 1))
    for j, tau in enumerate(taus):
        big[j, j] = -1.0 / tau
        big[j, j - 1 if j else count] = 1.0 / tau  # input: the previous stage or the gas
    e = scipy.linalg.expm(big * ts)  # stable for stiff stages (no -F block, unlike Van Loan)
    return e[:count, :count], e[:count, count]


def _linear_inverse(y: np.ndarray, taus: Sequence[float], ts: float) -> np.ndarray:
    """Held input u(k) on [t_k, t_k+1), k = 0..N-2, of a linear sensor at rest at t_0."""
    phi, gamma = _stage_zoh(taus, ts)
    if len(taus) == 1:
        return (y[1:] - phi[0, 0] * y[:-1]) / gamma[0]
    # hidden first stage z1: z1(k+1) = r z1(k) + (G1/G2) v(k), r the sampling zero (|r| < 1)
    v = y[1:] - phi[1, 1] * y[:-1]
    r = phi[0, 0] - gamma[0] * phi[1, 0] / gamma[1]
    z1 = np.empty(y.size)
    z1[0] = y[0]
    z1[1:] = scipy.signal.lfilter([gamma[0] / gamma[1]], [1.0, -r], v, zi=[r * y[0]])[0]
    return (v - phi[1, 0] * z1[:-1]) / gamma[1]


def _hysteretic_inverse(
    y: np.ndarray, heat: Sequence[float], cool: Sequence[float], ts: float
) -> np.ndarray:
    """As :func:`_linear_inverse` with each stage heating while its input is above its state,
    cooling otherwise. One stage: the mode is the sign of the output's change. Two stages:
    the first stage, whose input is the held gas, keeps one mode over the interval (it moves
    monotonically towards the gas); the output stage switches where the first stage crosses
    it, at most once per interval (a lag cannot overtake its monotone input); the output at
    t_k+1 increases with the gas, which is found by root finding when the output stage
    switches and in closed form otherwise."""
    if len(heat) == 1:
        modes = {c: _stage_zoh([cool[0] if c else heat[0]], ts) for c in (False, True)}
        cooling = y[1:] < y[:-1]
        a = np.where(cooling, modes[True][0][0, 0], modes[False][0][0, 0])
        b = np.where(cooling, modes[True][1][0], modes[False][1][0])
        return (y[1:] - a * y[:-1]) / b

    def advance(state: np.ndarray, gas: float, span: float) -> np.ndarray:
        first_cooling = gas < state[0]
        out_cooling = state[0] < state[1] or (state[0] == state[1] and first_cooling)
        taus = (cool[0] if first_cooling else heat[0], cool[1] if out_cooling else heat[1])
        phi, gamma = _stage_zoh(taus, span)
        end = phi @ state + gamma * gas
        if (end[0] < end[1]) == out_cooling or state[0] == state[1]:
            return end
        # the output stage switches where the first stage crosses it
        def gap(t: float) -> float:
            p, g = _stage_zoh(taus, t)
            mid = p @ state + g * gas
            return float(mid[0] - mid[1])

        cross = scipy.optimize.brentq(gap, 0.0, span, xtol=1e-12 * span)
        p, g = _stage_zoh(taus, cross)
        mid = p @ state + g * gas
        mid[1] = mid[0]
        return advance(mid, gas, span - cross) if span - cross > 0.0 else mid

    u = np.empty(y.size - 1)
    state = np.array([y[0], y[0]], dtype=float)
    for k in range(y.size - 1):
        state[1] = y[k]
        target = float(y[k + 1])

        def miss(gas: float, start: np.ndarray = state, target: float = target) -> float:
            return float(advance(start, gas, ts)[1] - target)

        # closed form with the first stage's mode from the output reached with gas = z1 (the
        # boundary) and the output stage's mode at the start; kept when no switch follows
        first_cooling = miss(float(state[0])) > 0.0
        out_cooling = bool(state[0] < state[1]) or (state[0] == state[1] and first_cooling)
        phi, gamma = _stage_zoh(
            (cool[0] if first_cooling else heat[0], cool[1] if out_cooling else heat[1]), ts
        )
        guess = (target - phi[1] @ state) / gamma[1]
        if abs(miss(guess)) > 1e-9 * (abs(target) + 1.0):
            low, high = guess - 1.0, guess + 1.0
            while miss(low) > 0.0:
                low -= 2.0 * (high - low)
            while miss(high) < 0.0:
                high += 2.0 * (high - low)
            guess = scipy.optimize.brentq(miss, low, high, xtol=1e-12 * (abs(guess) + 1.0))
        u[k] = guess
        state = advance(state, guess, ts)
    return u


def _check_inverse_args(
    temps: np.ndarray, taus: Sequence[float], ts: float, taus_cool: Sequence[float] | None
) -> tuple[np.ndarray, tuple[float, ...], tuple[float, ...]]:
    y = np.asarray(temps, dtype=float)
    if y.ndim != 1 or y.size < 2 or not np.all(np.isfinite(y)):
        raise ValueError("zoh_inverse: temps must be a finite 1-D array of >= 2 samples")
    if not (math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"zoh_inverse: ts must be finite and > 0, got {ts}")
    heat = as_time_constants("zoh_inverse", "taus", taus)
    cool = heat if taus_cool is None else as_time_constants("zoh_inverse", "taus_cool", taus_cool)
    assert heat is not None and cool is not None
    if len(cool) != len(heat):
        raise ValueError(f"zoh_inverse: taus_cool needs {len(heat)} time constants")
    return y, heat, cool


def zoh_inverse(
    temps: np.ndarray,
    taus: float | Sequence[float],
    ts: float,
    *,
    taus_cool: float | Sequence[float] | None = None,
) -> np.ndarray:
    """Gas temperature on each sample interval from one sensor's samples: the exact inverse
    of the whole ZOH-sampled sensor (the paper's eq. 8 for one time constant, any chain of 1
    or 2 stages here; the first time constant is the stage that sees the gas, which only
    matters with hysteresis). Exact when the gas is constant over each interval and the
    sensor starts at rest at ``temps[0]``. For two stages the hidden first stage is carried
    along; its start-up error decays as ``r^k`` with r the sampling zero (|r| < 1).

    ``out[k]`` is the gas temperature on [t_k, t_k+1); ``out[-1]`` is NaN.
    """
    y, heat, cool = _check_inverse_args(temps, _as_tuple(taus), float(ts), taus_cool)
    out = np.full(y.size, np.nan)
    out[:-1] = (
        _linear_inverse(y, heat, float(ts)) if heat == cool
        else _hysteretic_inverse(y, heat, cool, float(ts))
    )
    return out


def _as_tuple(taus: float | Sequence[float]) -> tuple[float, ...]:
    return tuple(float(t) for t in np.atleast_1d(np.asarray(taus, dtype=float)))


def _impulse_response(taus: Sequence[float], ts: float) -> np.ndarray:
    """Held values of the linear inverse for a unit sample at t_1 (the sensor at rest at 0),
    long enough for the decay through the sampling zero r (|r| < 1) to reach 1e-12."""
    phi, gamma = _stage_zoh(taus, ts)
    ratio = 0.0 if len(taus) == 1 else abs(phi[0, 0] - gamma[0] * phi[1, 0] / gamma[1])
    tail = 16 if ratio < 1e-3 else math.ceil(math.log(1e-12) / math.log(ratio))
    impulse = np.zeros(min(max(tail, 16), _MAX_INVERSE_TAIL) + 4)
    impulse[1] = 1.0
    return _linear_inverse(impulse, taus, ts)


def inverse_noise_gain(taus: Sequence[float], ts: float, *, aligned: bool) -> float:
    """Squared noise gain of :func:`zoh_inverse` (white noise of variance s^2 on the samples
    becomes ``gain * s^2`` on the output): the sum of squares of its impulse response, of the
    held values (``aligned=False``) or of the values aligned to the sample instants,
    ``(u(k-1) + u(k)) / 2`` (``aligned=True``)."""
    u = _impulse_response(taus, ts)
    if not aligned:
        return float(np.sum(u * u))
    mid = 0.5 * (u[1:] + u[:-1])
    return float(np.sum(mid * mid) + 0.25 * u[0] ** 2)


def zoh_inverse_pair(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    taus1: float | Sequence[float],
    taus2: float | Sequence[float],
    *,
    taus1_cool: float | Sequence[float] | None = None,
    taus2_cool: float | Sequence[float] | None = None,
    noise_std: Sequence[float] = (1.0, 1.0),
    aligned: bool = False,
) -> np.ndarray:
    """Both sensors' :func:`zoh_inverse` combined with inverse-variance weights (noise gain
    times noise variance; design.md 1.3 for one time constant each; equal noise by default).

    ``aligned=False``: gas temperature on each interval [t_k, t_k+1), NaN last (the studies on
    gas held over each interval). ``aligned=True``: at the sample instants, the mean of the
    held values either side of t_k, NaN at both ends (``reconstruct_pair(mode="inverse")``).
    """
    estimates, variances = [], []
    for temps, taus, cool, sigma in ((t1, taus1, taus1_cool, noise_std[0]),
                                     (t2, taus2, taus2_cool, noise_std[1])):
        held = zoh_inverse(temps, taus, ts, taus_cool=cool)
        if aligned:
            out = np.full(held.size, np.nan)
            out[1:-1] = 0.5 * (held[:-2] + held[1:-1])
            held = out
        estimates.append(held)
        variances.append(inverse_noise_gain(_as_tuple(taus), ts, aligned=aligned)
                         * float(sigma) ** 2)
    w1 = variances[1] / (variances[0] + variances[1])
    return w1 * estimates[0] + (1.0 - w1) * estimates[1]
