"""State-variable-filter (SVF) cross-relation estimator, design.md section 1.4 (reference).

(Docstring with the full specification is written at the end of development.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.signal

__all__ = [
    "DIRECTION_DEAD_ZONE",
    "FilterDiscretisation",
    "SvfResult",
    "direction_indicator",
    "discretise_filter",
    "effective_samples",
    "estimate",
    "filter_states",
    "filtered_derivatives",
    "free_response",
    "noise_covariance",
    "polynomial_time_constants",
    "projected_scatter",
    "regression_columns",
    "solve_gtls",
]


DIRECTION_DEAD_ZONE = 2.0  # |slope| below 2 noise std: direction undecided (h = 1/2)


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


def discretise_filter(tf: float, ts: float, m: int, hold: str = "foh") -> FilterDiscretisation:
    """Exact FOH (or ZOH) discretisation of the m-fold lag cascade with time constant ``tf``."""
    if not (math.isfinite(tf) and tf > 0.0 and math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"discretise_filter: need tf > 0 and ts > 0, got {tf!r}, {ts!r}")
    if m < 1:
        raise ValueError(f"discretise_filter: need m >= 1, got {m}")
    if hold not in ("foh", "zoh"):
        raise ValueError(f"discretise_filter: hold must be 'foh' or 'zoh', got {hold!r}")
    a_cont = (np.eye(m, k=-1) - np.eye(m)) / tf
    b_cont = np.zeros(m)
    b_cont[0] = 1.0 / tf
    # expm([[A Ts, B Ts, 0], [0, 0, 1], [0, 0, 0]]) = [[Phi, Gamma0, Gamma1/Ts], ...]
    aug = np.zeros((m + 2, m + 2))
    aug[:m, :m] = a_cont * ts
    aug[:m, m] = b_cont * ts
    aug[m, m + 1] = 1.0
    ex = scipy.linalg.expm(aug)
    phi = ex[:m, :m]
    gamma0 = ex[:m, m]
    gamma1 = ex[:m, m + 1]
    if hold == "foh":
        ga = gamma0 - gamma1
        gb = gamma1.copy()
    else:
        ga = gamma0.copy()
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


@dataclass(frozen=True)
class SvfResult:
    """Outcome of one SVF estimate (time constants in seconds, per sensor largest first)."""

    status: str
    order: int
    theta: np.ndarray
    time_constants: tuple[tuple[float, ...], tuple[float, ...]]
    polynomials: tuple[tuple[float, ...], tuple[float, ...]]
    eigenvalues: np.ndarray
    rows: int
    tf: float
    warmup: int
    extra: dict[str, object] = field(default_factory=dict)


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


def regression_columns(
    t1: np.ndarray,
    t2: np.ndarray,
    disc: FilterDiscretisation,
    order: int,
    directions: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Regression columns (p, N): row i of the result is column i of z(k), design.md 1.4
    order, scaled (derivative columns are ``(tf s)^j F T``)."""
    x1 = filtered_derivatives(t1, disc)
    x2 = filtered_derivatives(t2, disc)
    n = x1.shape[1]
    if directions is None:
        cols = [x1[j] for j in range(1, order + 1)]
        cols += [-x2[j] for j in range(1, order + 1)]
        cols.append(x2[0] - x1[0])
        return np.array(cols)
    if order != 1:
        raise ValueError("regression_columns: the hysteresis split is defined for order 1 only")
    zoh = _zoh_of(disc)
    cols = []
    for sign, x, h in ((1.0, t1, directions[0]), (-1.0, t2, directions[1])):
        slope = np.diff(np.asarray(x, dtype=float)) * (disc.tf / disc.ts)
        heat = _last_state(slope * h, zoh, n)
        cool = _last_state(slope * (1.0 - h), zoh, n)
        cols += [sign * heat, sign * cool]
    cols.append(x2[0] - x1[0])
    return np.array(cols)


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


def projected_scatter(cols: np.ndarray, disc: FilterDiscretisation, start: int = 0) -> np.ndarray:
    """Scatter of the columns from sample ``start`` on, with the start-up transients (the span
    of the free responses) projected out."""
    z = cols[:, start:]
    scatter = z @ z.T
    h = free_response(disc, cols.shape[1])[:, start:]
    k = h.shape[1]
    if k == 0:
        return scatter
    zh = z[:, :k] @ h.T
    hh = h @ h.T
    scatter -= zh @ np.linalg.solve(hh, zh.T)
    return 0.5 * (scatter + scatter.T)


def noise_covariance(
    disc: FilterDiscretisation, order: int, sigma1: float, sigma2: float
) -> np.ndarray:
    """Stationary covariance of the noise part of z under white noise sigma1, sigma2."""
    lmap = disc.derivative_map
    cov_x = lmap @ disc.state_covariance @ lmap.T  # covariance of x_0..x_{m-1}
    p = 2 * order + 1
    # z = M1 x(T1) + M2 x(T2)
    m1 = np.zeros((p, disc.m))
    m2 = np.zeros((p, disc.m))
    for j in range(1, order + 1):
        m1[j - 1, j] = 1.0
        m2[order + j - 1, j] = -1.0
    m1[-1, 0] = -1.0
    m2[-1, 0] = 1.0
    c = sigma1**2 * (m1 @ cov_x @ m1.T) + sigma2**2 * (m2 @ cov_x @ m2.T)
    return 0.5 * (c + c.T)


def solve_gtls(scatter: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Generalised TLS: eigen-decomposition of ``S v = mu C v``; returns (theta, mu, V).

    theta is normalised so that its last entry is -1. C is regularised by a tiny multiple of
    diag(S) so that noise-free data (C = 0) give the TLS solution.
    """
    d = np.sqrt(np.diag(scatter))
    if not np.all(np.isfinite(d)) or np.any(d <= 0.0):
        raise np.linalg.LinAlgError("solve_gtls: a regression column is identically zero")
    s_n = scatter / np.outer(d, d)
    c_n = cov / np.outer(d, d)
    c_n = c_n + 1e-12 * max(float(np.trace(c_n)), 1.0) * np.eye(d.size)
    mu, vecs = scipy.linalg.eigh(s_n, c_n)
    vecs = vecs / d[:, None]
    v = vecs[:, 0]
    theta = -v / v[-1] if v[-1] != 0.0 else np.full(v.size, np.nan)
    return theta, mu, vecs


def effective_samples(
    disc: FilterDiscretisation,
    theta: np.ndarray,
    order: int,
    sigma1: float,
    sigma2: float,
    rows: int,
) -> float:
    """Effective number of independent rows for the equation error ``theta . z_noise``.

    The filtered noise is correlated over ~tf, so a sample second moment over ``rows`` rows
    scatters like one over ``rows * R(0)^2 / sum_l R(l)^2`` independent rows (R: the
    autocovariance of the equation error, computed from the filter's impulse response).
    """
    p = 2 * order + 1
    m1 = np.zeros((p, disc.m))
    m2 = np.zeros((p, disc.m))
    for j in range(1, order + 1):
        m1[j - 1, j] = 1.0
        m2[order + j - 1, j] = -1.0
    m1[-1, 0] = -1.0
    m2[-1, 0] = 1.0
    length = min(math.ceil((40.0 + 4.0 * disc.m) * disc.tf / disc.ts) + 2, 4 * rows + 2)
    impulse = np.zeros(length)
    impulse[0] = 1.0
    states = filter_states(impulse, disc)  # v(k) for a unit sample at k = 0
    acov = np.zeros(2 * length - 1)
    for weight, mat in ((sigma1, m1), (sigma2, m2)):
        if weight == 0.0:
            continue
        c = (theta[:p] @ mat) @ disc.derivative_map  # e = c . v
        h = c @ states
        acov += weight**2 * scipy.signal.fftconvolve(h, h[::-1])
    r0 = acov[length - 1]
    total = float(np.sum(acov**2))
    if not (r0 > 0.0 and total > 0.0):
        return float(rows)
    return float(rows) * r0**2 / total


def polynomial_time_constants(coeffs: tuple[float, ...]) -> tuple[float, ...]:
    """Time constants of ``1 + c1 s + c2 s^2 + ...`` (largest first); NaN if not real > 0."""
    poly = np.concatenate((np.asarray(coeffs, dtype=float)[::-1], [1.0]))
    while poly.size > 1 and poly[0] == 0.0:
        poly = poly[1:]
    roots = np.roots(poly)
    taus = -1.0 / roots
    if np.any(np.abs(taus.imag) > 1e-9 * np.abs(taus)) or np.any(taus.real <= 0.0):
        return tuple(float("nan") for _ in coeffs)
    return tuple(sorted((float(t) for t in taus.real), reverse=True))


def estimate(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    *,
    tf: float,
    order: int = 1,
    sigma1: float = 0.0,
    sigma2: float = 0.0,
    m: int | None = None,
    hold: str = "foh",
    warmup: int = 0,
    hysteresis: bool = False,
    direction_half_window: int | None = None,
    project_initial: bool = True,
    dead_zone: float = DIRECTION_DEAD_ZONE,
) -> SvfResult:
    """SVF cross-relation estimate with a fixed filter time constant ``tf``."""
    t1 = np.asarray(t1, dtype=float)
    t2 = np.asarray(t2, dtype=float)
    m = order + 1 if m is None else m
    disc = discretise_filter(tf, ts, m, hold)
    directions = None
    if hysteresis:
        w = direction_half_window
        if w is None:
            w = max(1, round(tf / ts))
        directions = (
            direction_indicator(t1, w, sigma1, dead_zone),
            direction_indicator(t2, w, sigma2, dead_zone),
        )
    cols = regression_columns(t1, t2, disc, order, directions)
    rows = cols.shape[1] - warmup
    if project_initial:
        scatter = projected_scatter(cols, disc, warmup)
    else:
        scatter = cols[:, warmup:] @ cols[:, warmup:].T
    cov = noise_covariance(disc, order, sigma1, sigma2)
    if hysteresis and directions is not None:
        cov = _hysteresis_covariance(cov, directions, warmup)
    else:
        cov = cov * rows
    theta, mu, _ = solve_gtls(scatter, cov)
    scale = np.array([disc.tf ** (j + 1) for j in range(order)])
    if hysteresis:
        taus = theta[:4] * disc.tf
        heat = ((float(taus[0]),), (float(taus[2]),))
        cool = ((float(taus[1]),), (float(taus[3]),))
        ok = bool(np.all(taus > 0.0))
        return SvfResult(
            status="ok" if ok else "infeasible", order=1, theta=theta,
            time_constants=(((taus[0] + taus[1]) / 2,), ((taus[2] + taus[3]) / 2,)),
            polynomials=heat, eigenvalues=mu, rows=rows, tf=tf, warmup=warmup,
            extra={"heat": heat, "cool": cool},
        )
    p1 = tuple(float(v) for v in theta[:order] * scale)
    p2 = tuple(float(v) for v in theta[order : 2 * order] * scale)
    tc1 = polynomial_time_constants(p1)
    tc2 = polynomial_time_constants(p2)
    ok = all(math.isfinite(v) for v in tc1 + tc2)
    return SvfResult(
        status="ok" if ok else "infeasible", order=order, theta=theta,
        time_constants=(tc1, tc2), polynomials=(p1, p2), eigenvalues=mu, rows=rows,
        tf=tf, warmup=warmup,
    )


def _hysteresis_covariance(
    cov3: np.ndarray, directions: tuple[np.ndarray, np.ndarray], warmup: int
) -> np.ndarray:
    """Accumulated noise covariance of the split rows: each row's derivative noise is
    attributed to the heating/cooling columns with the weights (h, 1 - h) of its current
    interval (exact while h is constant over the filter memory)."""
    h1 = directions[0][max(warmup - 1, 0):]
    h2 = directions[1][max(warmup - 1, 0):]
    pairs, counts = np.unique(np.column_stack((h1, h2)), axis=0, return_counts=True)
    total = np.zeros((5, 5))
    for (a, b), count in zip(pairs, counts, strict=True):
        e = np.zeros((5, 3))
        e[0, 0], e[1, 0] = a, 1.0 - a
        e[2, 1], e[3, 1] = b, 1.0 - b
        e[4, 2] = 1.0
        total += float(count) * (e @ cov3 @ e.T)
    # the first row (interval -1) has no direction: count it like its successor
    return total * (h1.size + 1) / h1.size
