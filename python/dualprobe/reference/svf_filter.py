"""The state-variable filter of :mod:`dualprobe.reference.svf`: the exact FOH/ZOH
discretisation of ``F(s) = 1/(1 + tf s)^m``, its states and free responses, and the
heating/cooling direction read off the filtered slope (design.md 1.4)."""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.signal
import scipy.special

__all__ = [
    "FilterDiscretisation",
    "choose_direction_half_window",
    "direction_indicator",
    "discretise_filter",
    "filter_states",
    "filtered_derivatives",
    "free_response",
]


@dataclass(frozen=True)
class FilterDiscretisation:
    """Exact discretisation of ``F(s) = 1/(1 + tf s)^m`` as a cascade of m equal lags.

    Cascade states ``v_0 = G u, v_i = G v_{i-1}`` with ``G = 1/(1 + tf s)``; the recursion is
    ``v(k+1) = phi v(k) + ga u(k) + gb u(k+1)`` (FOH; for ZOH ``gb = 0``).
    ``derivative_map`` L (m x m) gives the scaled derivatives ``x_j = (tf s)^j F u = L[j] . v``.
    ``state_covariance`` is the stationary covariance of v for unit white input noise.
    """

    tf: float
    ts: float
    m: int
    hold: str
    phi: np.ndarray
    ga: np.ndarray
    gb: np.ndarray
    derivative_map: np.ndarray
    state_covariance: np.ndarray


@functools.lru_cache(maxsize=64)
def discretise_filter(tf: float, ts: float, m: int, hold: str = "foh") -> FilterDiscretisation:
    """Exact FOH (or ZOH) discretisation of the m-fold lag cascade with time constant ``tf``."""
    if not (math.isfinite(tf) and tf > 0.0 and math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"discretise_filter: need tf > 0 and ts > 0, got {tf!r}, {ts!r}")
    if m < 1:
        raise ValueError(f"discretise_filter: need m >= 1, got {m}")
    if hold not in ("foh", "zoh"):
        raise ValueError(f"discretise_filter: hold must be 'foh' or 'zoh', got {hold!r}")
    h = ts / tf
    # Closed form of the exact discretisation of the cascade (A = (N - I)/tf, B = e_0/tf,
    # N the down-shift): phi[j, i] = exp(-h) h^(j-i)/(j-i)!, Gamma0_j = P(j+1, h) and
    # (1/Ts) int_0^Ts exp(A r) B r dr = (j+1) P(j+2, h) / h, with P the regularised lower
    # incomplete gamma function (accurate for tiny h, no cancellation).
    phi = np.zeros((m, m))
    for j in range(m):
        for i in range(j + 1):
            phi[j, i] = math.exp(-h) * h ** (j - i) / math.factorial(j - i)
    j = np.arange(m)
    gamma0 = scipy.special.gammainc(j + 1.0, h)
    ramp = (j + 1.0) * scipy.special.gammainc(j + 2.0, h) / h
    if hold == "foh":
        ga = ramp
        gb = gamma0 - ramp
    else:
        ga = gamma0
        gb = np.zeros(m)
    # (tf s) v_i = v_{i-1} - v_i: the j-th scaled derivative of v_{m-1} is a binomial
    # difference of the last j+1 cascade states.
    lmap = np.zeros((m, m))
    for j in range(m):
        for i in range(j + 1):
            lmap[j, m - 1 - j + i] = (-1.0) ** i * math.comb(j, i)
    # w(k) = v(k) - gb u(k) obeys w(k+1) = phi w(k) + (phi gb + ga) u(k), independent of u(k).
    q = phi @ gb + ga
    p_w = scipy.linalg.solve_discrete_lyapunov(phi, np.outer(q, q))
    cov = p_w + np.outer(gb, gb)
    cov = 0.5 * (cov + cov.T)
    for array in (phi, ga, gb, lmap, cov):
        array.setflags(write=False)  # shared through the cache
    return FilterDiscretisation(
        tf=float(tf), ts=float(ts), m=m, hold=hold, phi=phi, ga=ga, gb=gb,
        derivative_map=lmap, state_covariance=cov,
    )


def filter_states(u: np.ndarray, disc: FilterDiscretisation) -> np.ndarray:
    """Cascade states (m, N) of the discretised filter for input ``u``, starting at rest.

    Column k is v(k); v(0) = 0 (the caller removes the first sample so that this is the
    steady state of the signal's own first value). The cascade matrix is lower triangular,
    so stage j is a first-order recursion driven by u and the earlier stages.
    """
    u = np.asarray(u, dtype=float)
    n = u.size
    m = disc.m
    den = np.array([1.0, -disc.phi[0, 0]])
    states = np.empty((m, n))
    drive = np.empty(n)
    for j in range(m):
        drive[0] = 0.0
        np.multiply(u[:-1], disc.ga[j], out=drive[1:])
        if disc.gb[j] != 0.0:
            drive[1:] += disc.gb[j] * u[1:]
        for i in range(j):
            drive[1:] += disc.phi[j, i] * states[i, :-1]
        states[j] = scipy.signal.lfilter([1.0], den, drive)
    return states


def filtered_derivatives(u: np.ndarray, disc: FilterDiscretisation) -> np.ndarray:
    """Scaled filtered derivatives ``x_j = (tf s)^j F u`` (m, N), the filter starting in
    steady state at ``u[0]``."""
    u = np.asarray(u, dtype=float)
    states = filter_states(u - u[0], disc)
    out = np.zeros_like(states)
    lmap = disc.derivative_map
    for j in range(disc.m):
        for i in range(disc.m):
            if lmap[j, i] != 0.0:
                out[j] += lmap[j, i] * states[i]
    out[0] += u[0]
    return out


def direction_indicator(
    x: np.ndarray, half_window: int, sigma: float = 0.0, dead_zone: float = 0.0
) -> np.ndarray:
    """1.0 where the signal rises over interval k (between samples k and k+1), else 0.0.

    Zero-lag: the sign of (mean of x[k+2 .. k+1+w]) - (mean of x[k-w .. k-1]), windows
    clipped at the ends. The two samples of the interval itself are left out, so the
    classification is independent of that interval's noise (otherwise the heating column
    collects a spurious positive mean wherever the slope is below the noise).
    """
    x = np.asarray(x, dtype=float)
    n = x.size
    w = max(1, int(half_window))
    csum = np.concatenate(([0.0], np.cumsum(x - x[0])))
    k = np.arange(n - 1)
    a_lo = np.minimum(k + 2, n - 1)
    a_hi = np.minimum(k + 2 + w, n)
    b_hi = np.maximum(k, 1)
    b_lo = np.maximum(k - w, 0)
    after = (csum[a_hi] - csum[a_lo]) / (a_hi - a_lo)
    before = (csum[b_hi] - csum[b_lo]) / (b_hi - b_lo)
    d = after - before
    h = (d > 0.0).astype(float)
    if sigma > 0.0 and dead_zone > 0.0:
        s_d = sigma * np.sqrt(1.0 / (a_hi - a_lo) + 1.0 / (b_hi - b_lo))
        h[np.abs(d) < dead_zone * s_d] = 0.5
    return h


def choose_direction_half_window(
    x: np.ndarray, disc: FilterDiscretisation, sigma: float, tolerance: float = 0.01
) -> int:
    """Half window w of :func:`direction_indicator` for one signal.

    The smallest w whose slope-noise standard deviation ``sigma sqrt(2/w) / ((w+1) Ts)`` is
    at most ``tolerance`` times the RMS filtered slope ``(sF x)`` of the record, capped at
    tf/Ts: short windows keep direction changes sharp at steps, long ones keep slow
    episodes from being classified by noise.
    """
    w_max = max(1, round(disc.tf / disc.ts))
    if sigma <= 0.0:
        return 1
    slope = filtered_derivatives(x, disc)[1] / disc.tf
    scale = float(np.sqrt(np.mean(slope * slope)))
    if not scale > 0.0:
        return w_max
    w = np.arange(1, w_max + 1, dtype=float)
    ok = sigma * np.sqrt(2.0 / w) / ((w + 1.0) * disc.ts) <= tolerance * scale
    return int(w[ok][0]) if np.any(ok) else w_max


def _zoh_of(disc: FilterDiscretisation) -> FilterDiscretisation:
    return disc if disc.hold == "zoh" else discretise_filter(disc.tf, disc.ts, disc.m, "zoh")


def _last_state(drive: np.ndarray, zoh: FilterDiscretisation, n: int) -> np.ndarray:
    """F applied (ZOH) to the piecewise-constant input ``drive[k]`` on interval k."""
    u = np.zeros(n)
    u[:-1] = drive  # ZOH uses u(k) on [t_k, t_k+1)
    return filter_states(u, zoh)[-1]


def free_response(disc: FilterDiscretisation, n: int) -> np.ndarray:
    """Free responses (m, K) of the cascade, ``h(k) = phi^k e_0``, K <= n samples (beyond K
    they are below 1e-18 of their peak): every start-up transient of the filtered columns is
    a combination of these rows."""
    k_max = min(n, math.ceil((60.0 + 2.0 * disc.m) * disc.tf / disc.ts) + 1)
    r = np.arange(k_max) * (disc.ts / disc.tf)
    decay = np.exp(-r)
    # phi^k e_0 has entries (k ts/tf)^j exp(-k ts/tf) / j!
    return np.array([r**j / math.factorial(j) * decay for j in range(disc.m)])
