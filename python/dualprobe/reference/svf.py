"""State-variable-filter (SVF) cross-relation estimator: the reference for design.md 1.4.

This docstring is the specification of the streaming C++ port; the functions below are the
batch reference (numbers must agree to rounding).

Model
-----
Sensor i sees the gas through ``1/P_i(s)``, ``P_i = 1 + p_i1 s + ... + p_in s^n`` (n = order,
1 or 2). Eliminating Tg: ``P1(s) T1 = g P2(s) T2 + o``; the *unit* static model has g = 1,
o = 0 (design.md), the *affine* one estimates the gain ratio g = gain1/gain2 and an offset o
(real Pt-100s: Tables I/II give gains 0.99 and 1.03, which break every unit-gain estimator:
the plain GTLS gives 27 s / 50 s instead of 12.48 s / 28.95 s on 100-300 K steps; the affine
SVF 12.4796 s / 28.9499 s). Any common linear filter preserves the relation.

Filter and discretisation
-------------------------
``F(s) = 1/(1 + tf s)^m``, m = order + 1, realised as a cascade of m equal lags with states
v_0 = G u, v_i = G v_{i-1} (G = 1/(1 + tf s)). Exact first-order-hold (FOH) discretisation,
h = Ts/tf, P(a, x) the regularised lower incomplete gamma function:

    v(k+1) = phi v(k) + ga u(k) + gb u(k+1)
    phi[j][i] = exp(-h) h^(j-i) / (j-i)!   (i <= j, else 0; lower triangular Toeplitz)
    ramp_j = (j+1) P(j+2, h) / h;   ga_j = ramp_j;   gb_j = P(j+1, h) - ramp_j

(ZOH, used only for the hysteresis columns: ga_j = P(j+1, h), gb = 0.) The input is
``u(k) = T(k) - T(0)`` and v(0) = 0, i.e. the filter starts in steady state at the signal's
first sample. Scaled filtered derivatives ``x_j = (tf s)^j F T`` (j = 0..order) are binomial
differences of the last cascade states, ``x_j = sum_i (-1)^i C(j, i) v_{m-1-j+i}``
(x_0 = v_{m-1} + T(0), x_1 = v_{m-2} - v_{m-1}, x_2 = v_{m-3} - 2 v_{m-2} + v_{m-1}).
FOH because the filter then sees the straight-line interpolation of the samples exactly:
noise-free 10 Hz Pt-100 pair, off-grid 100-300 K steps: FOH tau error 2e-6 at tf = 0.3 s
and 8e-7 at tf = 10 s; ZOH 0.9 % at tf = 0.3 s, 0.07 % at 1 s. m = order + 2 gave no
measurable gain over m = order + 1 (tau1 spread 0.57 % vs 0.58 %, 12 records).

Regression row (column order), theta and parameters
-----------------------------------------------------
unit:    z = [x_1..x_n(T1), -x_1..x_n(T2), x_0(T2) - x_0(T1)]
affine:  z = [x_1..x_n(T1), -x_1..x_n(T2), -x_0(T2), -x_0(T1)]   (+ a constant, see below)
theta (normalised to last entry -1): unit ``[p1_j/tf^j, p2_j/tf^j, -1]``, affine
``[p1_j/tf^j, g p2_j/tf^j, g, -1]``. So p1_j = theta_j tf^j, p2_j = theta_{n+j} tf^j / g.
Time constants: roots of P_i (order 2: ``tau = (c +/- sqrt(c^2 - 4 d))/2`` with c = p_i1,
d = p_i2), largest first. Hysteresis (order 1): each x_1 column is replaced by a heating
and a cooling column, ``z = [H1, K1, -H2, -K2, static...]``, theta =
``[tau_h1, tau_c1, g tau_h2, g tau_c2, (g,) -1] / tf``, where H_i (K_i) is ``tf F`` applied
(ZOH cascade, its last state) to ``h_i(k) dT_i(k)/Ts`` (``(1 - h_i(k)) dT_i(k)/Ts``) on the
interval k between samples k and k+1; H + K equals x_1 exactly.

Start-up transients (replaces a warm-up)
----------------------------------------
Every start-up error of the filtered columns (sensors not at rest at t0) is a combination
of the free responses ``b(k) = phi^k e_0``, ``b_j(k) = (k h)^j exp(-k h)/j!``. They are
projected out of the scatter: accumulate ``S = sum z z^T``, ``Szb = sum z b^T`` and
``Sbb = sum b b^T`` (b may be dropped once below 1e-18, after (60 + 2m) tf) and use
``S - Szb Sbb^-1 Szb^T``. The affine model appends a constant 1 to b (accumulated for all
k), which removes the offset o. No sample is skipped (warmup = 0). Measured, record
starting 3 s after a 100-300 K step: projection 1e-6 error; without it +0.1 % (tf = 1 s),
+2.3 % (5 s), +53 % (20 s).

Noise covariance and solve
--------------------------
White noise sigma_i on T_i enters the cascade like u. With w(k) = v(k) - gb u(k):
``w(k+1) = phi w(k) + q u(k)``, q = phi gb + ga, so the stationary covariance per unit
variance is ``P = P_w + gb gb^T`` with ``P_w = phi P_w phi^T + q q^T`` (discrete Lyapunov;
C++: doubling P <- P + A P A^T, A <- A^2 from P = q q^T, A = phi, ~60 steps). With the maps
M_i of :func:`column_maps` (z = M1 x(T1) + M2 x(T2)) and the derivative map L:
``C = sum_i sigma_i^2 M_i L P L^T M_i^T``, accumulated as ``rows * C``. Hysteresis: each
row contributes ``E C E^T`` with E spreading the x_1 noise as (h, 1 - h) over its two
columns (count the (h1, h2) combinations), plus the switch term where h changes
(:func:`switch_covariance`). GTLS: the eigenvector of the smallest
generalised eigenvalue of ``S v = mu (rows C) v`` after scaling both by ``diag(S)^-1/2``
and adding ``1e-12 max(trace, 1) I`` to the scaled C (noise-free data -> TLS); theta =
-v / v_last. With the right noise level mu_1 ~ 1 (test); only sigma1/sigma2 changes
theta. Effective rows for statistics: ``rows R(0)^2 / sum_l R(l)^2`` (R: autocovariance of
theta . z_noise), see :func:`effective_samples`.

Heating/cooling classification (hysteresis)
-------------------------------------------
``h(k) = 1`` if mean(T[k+2 .. k+1+w]) - mean(T[k-w .. k-1]) > 0 else 0, and 1/2 where
that difference is below 2 sigma sqrt(1/n_after + 1/n_before) (dead zone). The interval's
own samples k, k+1 are left out: including them correlates h with the interval's noise and
biased tau_heat/tau_cool by 17-20 % (+/-5 K moves, 0.05 K). Window: the smallest w with
``sigma sqrt(2/w) / ((w+1) Ts) <= 0.01 * RMS(x_1/tf)``, capped at tf/Ts (short at steps,
long for slow moves). Streaming needs a look-ahead of w + 2 samples (delay line).
Measured (10 Hz, heating 25-35 % faster, tf auto): max error 0.4 % (100-300 K steps, 0.1 K),
1.1 % (band-limited +/-5 K, 0.05 K), 3.4 % (+/-5 K steps and ramps, 0.05 K, 1200 s).

Choice of tf (dualprobe.estimation)
-----------------------------------
tf = kappa tau_fast at its fixed point, kappa = 0.5 (order 1), 0.25 (order 2). Measured
tau1 spread, 10 Hz Pt-100, +/-5 K, 0.1 K, 1200 s: tf 0.5 s 3.5 %, 1 s 1.1 %, 2-8 s
0.8-0.6 %, 16 s 0.6 %; 300 s records prefer 4-8 s (1.6 %) to 16 s (2.1 %) and 30 s (5 %).
1 kHz thermocouples (20/80 ms): tf 1 ms 6.7 %, 3-50 ms 0.6-0.8 %. Order 2 (100 Hz, 0.1 K,
150 K steps), spread of the 0.17 s pole: tf 0.1 s 19 %, 0.3 s 4.4 %, 1 s 2.2 %, 3 s 1.7 %,
10 s 4.9 %.

Against the plain difference GTLS (``dualprobe.estimation.compare.compare_methods``, first-order
Pt-100 pair, +/-5 K steps, 1200 s, 5 records; median / max |tau1 error|, failed runs):
1 Hz 0.1 K: 100 % (2 failed) vs 1.2 / 2.7 %; 10 Hz 0.1 K: all 5 failed vs 0.10 / 0.76 %;
100 Hz 0.01 K: 96 % / 920 % vs 0.015 / 0.045 %.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.signal

from dualprobe.reference.svf_filter import (
    FilterDiscretisation,
    _last_state,
    _zoh_of,
    choose_direction_half_window,
    direction_indicator,
    discretise_filter,
    filter_states,
    filtered_derivatives,
    free_response,
)

__all__ = [
    "DIRECTION_DEAD_ZONE",
    "DIRECTION_TOLERANCE",
    "STATIC_MODELS",
    "SvfResult",
    "column_maps",
    "effective_samples",
    "estimate",
    "merged_theta",
    "noise_covariance",
    "polynomial_time_constants",
    "projected_scatter",
    "regression_columns",
    "residual_effective_samples",
    "solve_gtls",
    "split_switch_noise",
    "switch_covariance",
]


DIRECTION_DEAD_ZONE = 2.0  # |slope| below 2 noise std: direction undecided (h = 1/2)
DIRECTION_TOLERANCE = 0.01  # slope-noise std / RMS filtered slope for the direction window
STATIC_MODELS = ("unit", "affine")


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


def column_maps(order: int, static: str = "unit") -> tuple[np.ndarray, np.ndarray]:
    """Maps (p, order+1) of the unsplit layout: ``z = M1 x(T1) + M2 x(T2)``, with
    ``x_j = (tf s)^j F T`` (j = 0..order).

    unit:   ``[x_1..x_n(T1), -x_1..x_n(T2), x_0(T2) - x_0(T1)]``  (design.md 1.4)
    affine: ``[x_1..x_n(T1), -x_1..x_n(T2), -x_0(T2), -x_0(T1)]``, constant projected out
    """
    if static not in STATIC_MODELS:
        raise ValueError(f"static model must be one of {', '.join(STATIC_MODELS)}, got {static!r}")
    p = 2 * order + (1 if static == "unit" else 2)
    m1 = np.zeros((p, order + 1))
    m2 = np.zeros((p, order + 1))
    for j in range(1, order + 1):
        m1[j - 1, j] = 1.0
        m2[order + j - 1, j] = -1.0
    if static == "unit":
        m1[-1, 0] = -1.0
        m2[-1, 0] = 1.0
    else:
        m2[-2, 0] = -1.0
        m1[-1, 0] = -1.0
    return m1, m2


def regression_columns(
    t1: np.ndarray,
    t2: np.ndarray,
    disc: FilterDiscretisation,
    order: int,
    directions: tuple[np.ndarray, np.ndarray] | None = None,
    static: str = "unit",
) -> np.ndarray:
    """Regression columns (p, N): row i of the result is column i of z(k) (scaled: derivative
    columns are ``(tf s)^j F T``), in the order of :func:`column_maps`. With ``directions``
    (order 1) each sensor's derivative column is split into a heating and a cooling column
    ``(tf s) F`` applied (ZOH) to ``h ΔT/Ts`` and ``(1 - h) ΔT/Ts``."""
    x1 = filtered_derivatives(t1, disc)[: order + 1]
    x2 = filtered_derivatives(t2, disc)[: order + 1]
    m1, m2 = column_maps(order, static)
    z = np.zeros((m1.shape[0], x1.shape[1]))
    for mat, x in ((m1, x1), (m2, x2)):
        for row, col in zip(*np.nonzero(mat), strict=True):
            z[row] += mat[row, col] * x[col]
    if directions is None:
        return z
    if order != 1:
        raise ValueError("regression_columns: the hysteresis split is defined for order 1 only")
    n = x1.shape[1]
    zoh = _zoh_of(disc)
    split = []
    for sign, x, h in ((1.0, t1, directions[0]), (-1.0, t2, directions[1])):
        slope = np.diff(np.asarray(x, dtype=float)) * (disc.tf / disc.ts)
        heat = _last_state(slope * h, zoh, n)
        cool = _last_state(slope * (1.0 - h), zoh, n)
        split += [sign * heat, sign * cool]
    return np.vstack([np.array(split), z[2:]])


def projected_scatter(
    cols: np.ndarray, disc: FilterDiscretisation, start: int = 0, constant: bool = False
) -> np.ndarray:
    """Scatter of the columns from sample ``start`` on, with the start-up transients (the span
    of the free responses) and, if ``constant``, a constant projected out."""
    z = cols[:, start:]
    scatter = z @ z.T
    h = free_response(disc, cols.shape[1])[:, start:]
    k = h.shape[1]
    if constant:
        basis = np.zeros((h.shape[0] + 1, z.shape[1]))
        basis[:-1, :k] = h
        basis[-1] = 1.0
        zh = z @ basis.T
    elif k:
        basis = h
        zh = z[:, :k] @ h.T
    else:
        return scatter
    hh = basis @ basis.T
    scatter -= zh @ np.linalg.solve(hh, zh.T)
    return 0.5 * (scatter + scatter.T)


def noise_covariance(
    disc: FilterDiscretisation, order: int, sigma1: float, sigma2: float, static: str = "unit"
) -> np.ndarray:
    """Stationary covariance of the noise part of z (unsplit layout) under white noise
    sigma1, sigma2: ``sum_i sigma_i^2 M_i L P L^T M_i^T`` with P the filter's state
    covariance (discrete Lyapunov) and L the derivative map."""
    lmap = disc.derivative_map[: order + 1]
    cov_x = lmap @ disc.state_covariance @ lmap.T  # covariance of x_0..x_order
    m1, m2 = column_maps(order, static)
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
    static: str = "unit",
) -> float:
    """Effective number of independent rows for the equation error ``theta . z_noise``
    (unsplit layout).

    The filtered noise is correlated over ~tf, so a sample second moment over ``rows`` rows
    scatters like one over ``rows * R(0)^2 / sum_l R(l)^2`` independent rows (R: the
    autocovariance of the equation error, from the filter's impulse response).
    """
    m1, m2 = column_maps(order, static)
    length = min(math.ceil((40.0 + 4.0 * disc.m) * disc.tf / disc.ts) + 2, 4 * rows + 2)
    impulse = np.zeros(length)
    impulse[0] = 1.0
    states = filter_states(impulse, disc)  # v(k) for a unit sample at k = 0
    acov = np.zeros(2 * length - 1)
    for weight, mat in ((sigma1, m1), (sigma2, m2)):
        if weight == 0.0:
            continue
        c = (theta @ mat) @ disc.derivative_map[: order + 1]  # e = c . v
        h = c @ states
        acov += weight**2 * scipy.signal.fftconvolve(h, h[::-1])
    r0 = acov[length - 1]
    total = float(np.sum(acov**2))
    if not (r0 > 0.0 and total > 0.0):
        return float(rows)
    return float(rows) * r0**2 / total


def residual_effective_samples(cols: np.ndarray, theta: np.ndarray, max_lag: int) -> float:
    """Effective number of independent rows from the empirical autocovariance (lags up to
    ``max_lag``) of the equation error ``theta . z`` itself: conservative when the residual
    holds more than white sensor noise (model error, coloured noise)."""
    e = theta @ cols
    e = e - np.mean(e)
    n = e.size
    lag = int(min(max_lag, n - 1))
    nfft = 1 << math.ceil(math.log2(n + lag + 1))
    spec = np.fft.rfft(e, nfft)
    acov = np.fft.irfft(spec * np.conj(spec), nfft)[: lag + 1] / n
    total = acov[0] ** 2 + 2.0 * float(np.sum(acov[1:] ** 2))
    if not (acov[0] > 0.0 and total > 0.0):
        return float(n)
    return float(n) * float(acov[0]) ** 2 / total


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
    static: str = "unit",
    m: int | None = None,
    hold: str = "foh",
    warmup: int = 0,
    hysteresis: bool = False,
    direction_half_window: int | None = None,
    project_initial: bool = True,
    dead_zone: float = DIRECTION_DEAD_ZONE,
    direction_tolerance: float = DIRECTION_TOLERANCE,
    diagnostics: bool = True,
) -> SvfResult:
    """SVF cross-relation estimate with a fixed filter time constant ``tf`` (batch).

    Raises numpy.linalg.LinAlgError when a regression column is identically zero (no
    excitation at all). ``status`` is "infeasible" when the time constants are not all
    real and positive (``time_constants`` then hold NaN; ``polynomials`` keep the fit).
    """
    t1 = np.asarray(t1, dtype=float)
    t2 = np.asarray(t2, dtype=float)
    m = order + 1 if m is None else m
    disc = discretise_filter(tf, ts, m, hold)
    directions = None
    windows = (0, 0)
    if hysteresis:
        if order != 1:
            raise ValueError("estimate: the hysteresis split is defined for order 1 only")
        if direction_half_window is None:
            windows = (
                choose_direction_half_window(t1, disc, sigma1, direction_tolerance),
                choose_direction_half_window(t2, disc, sigma2, direction_tolerance),
            )
        else:
            windows = (direction_half_window, direction_half_window)
        directions = (
            direction_indicator(t1, windows[0], sigma1, dead_zone),
            direction_indicator(t2, windows[1], sigma2, dead_zone),
        )
    cols = regression_columns(t1, t2, disc, order, directions, static)
    rows = cols.shape[1] - warmup
    constant = static == "affine"
    if project_initial or constant:
        scatter = projected_scatter(cols, disc, warmup, constant)
    else:
        scatter = cols[:, warmup:] @ cols[:, warmup:].T
    cov = noise_covariance(disc, order, sigma1, sigma2, static)
    if directions is not None:
        g1 = split_switch_noise(disc)
        cov = _split_covariance(cov, directions, warmup, (sigma1**2 * g1, sigma2**2 * g1))
    else:
        cov = cov * rows
    theta, mu, _ = solve_gtls(scatter, cov)
    n_eff_residual = float("nan")
    if diagnostics:
        lag = math.ceil((20.0 + 4.0 * m) * tf / ts)
        n_eff_residual = residual_effective_samples(cols[:, warmup:], theta, lag)
    extra: dict[str, object] = {"residual_effective_samples": n_eff_residual}
    n_dyn = 4 if hysteresis else 2 * order
    gain = float(theta[n_dyn]) if constant else 1.0
    extra["gain_ratio"] = gain
    if constant:
        extra["offset"] = float(np.mean(theta @ cols[:, warmup:]))
    if hysteresis:
        taus = theta[:4] * disc.tf / np.array([1.0, 1.0, gain, gain])
        heat = ((float(taus[0]),), (float(taus[2]),))
        cool = ((float(taus[1]),), (float(taus[3]),))
        ok = bool(np.all(taus > 0.0)) and gain > 0.0
        extra.update(heat=heat, cool=cool, direction_half_windows=windows)
        mean = ((0.5 * float(taus[0] + taus[1]),), (0.5 * float(taus[2] + taus[3]),))
        return SvfResult(
            status="ok" if ok else "infeasible", order=1, theta=theta, time_constants=mean,
            polynomials=mean, eigenvalues=mu, rows=rows, tf=tf, warmup=warmup, extra=extra,
        )
    scale = np.array([disc.tf ** (j + 1) for j in range(order)])
    p1 = tuple(float(v) for v in theta[:order] * scale)
    p2 = tuple(float(v) for v in theta[order : 2 * order] * scale / gain)
    tc1 = polynomial_time_constants(p1)
    tc2 = polynomial_time_constants(p2)
    ok = all(math.isfinite(v) for v in tc1 + tc2) and gain > 0.0
    return SvfResult(
        status="ok" if ok else "infeasible", order=order, theta=theta,
        time_constants=(tc1, tc2), polynomials=(p1, p2), eigenvalues=mu, rows=rows,
        tf=tf, warmup=warmup, extra=extra,
    )


def merged_theta(theta: np.ndarray) -> np.ndarray:
    """Unsplit parameter vector of a hysteresis fit (heating/cooling averaged)."""
    return np.concatenate(([0.5 * (theta[0] + theta[1]), 0.5 * (theta[2] + theta[3])],
                           theta[4:]))


def split_switch_noise(disc: FilterDiscretisation) -> float:
    """``(tf/Ts)^2 G1`` for unit noise: G1 the lag-1 sum of the split column's response g to
    one interval's slope (ZOH cascade, last state), summed from that response itself."""
    zoh = _zoh_of(disc)
    n = math.ceil((60.0 + 2.0 * disc.m) * disc.tf / disc.ts) + 2
    pulse = np.zeros(n - 1)
    pulse[0] = 1.0
    g = _last_state(pulse, zoh, n)
    return float(g[1:] @ g[:-1]) * (disc.tf / disc.ts) ** 2


def switch_covariance(weights: np.ndarray, previous: np.ndarray, k: float) -> np.ndarray:
    """The split columns' noise beyond ``C0 sum w_a w_b`` (rows of ``weights``: each column's
    per-row weight, h or 1 - h; ``previous``: the same on the row before; ``k``: sigma^2 times
    :func:`split_switch_noise`). A column carries ``sum_j g_{k-j} w_j (e_{j+1} - e_j) tf/Ts``,
    whose accumulated covariance is ``sigma^2 (tf/Ts)^2 [2 G0 sum w_a w_b - G1 sum (w_a(k)
    w_b(k-1) + w_a(k-1) w_b(k))]``; C0 = sigma^2 (tf/Ts)^2 (2 G0 - 2 G1) counts all but this."""
    lagged = weights @ previous.T
    return k * (2.0 * (weights @ weights.T) - lagged - lagged.T)


def _previous(h: np.ndarray, start: int) -> np.ndarray:
    """h on the interval before each of ``h[start:]`` (undecided, 1/2, before the first)."""
    return np.concatenate(([h[start - 1] if start > 0 else 0.5], h[start:-1]))


def _split_covariance(
    cov: np.ndarray, directions: tuple[np.ndarray, np.ndarray], warmup: int,
    switch: tuple[float, float],
) -> np.ndarray:
    """Accumulated noise covariance of the split rows: each row's derivative noise is
    attributed to the heating/cooling columns with the weights (h, 1 - h) of its current
    interval (exact while h is constant over the filter memory), plus the switch term of
    sensor i's pair of columns (``switch[i]``: sigma_i^2 times :func:`split_switch_noise`)."""
    start = max(warmup - 1, 0)
    h1 = directions[0][start:]
    h2 = directions[1][start:]
    pairs, counts = np.unique(np.column_stack((h1, h2)), axis=0, return_counts=True)
    p = cov.shape[0]
    total = np.zeros((p + 2, p + 2))
    for (a, b), count in zip(pairs, counts, strict=True):
        e = np.zeros((p + 2, p))
        e[0, 0], e[1, 0] = a, 1.0 - a
        e[2, 1], e[3, 1] = b, 1.0 - b
        for i in range(2, p):
            e[i + 2, i] = 1.0
        total += float(count) * (e @ cov @ e.T)
    for i, h in enumerate(directions):
        h = np.asarray(h, dtype=float)
        hp = _previous(h, start)
        weights = np.array([h[start:], 1.0 - h[start:]])
        previous = np.array([hp, 1.0 - hp])
        total[2 * i:2 * i + 2, 2 * i:2 * i + 2] += switch_covariance(weights, previous, switch[i])
    # the first row (interval -1) has no direction: count it like its successor
    return total * (h1.size + 1) / h1.size
