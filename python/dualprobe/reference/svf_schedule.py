"""Flow-scheduled SVF cross-relation estimator: the batch reference of design.md 1.5.

This docstring specifies the scheduled variants of the streaming C++ estimator
(``SvfEstimator<..., Basis>``, svf_estimator.hpp); the functions below compute the same
estimate in batch with NumPy/SciPy (numbers agree to rounding). Everything not said here is
as in :mod:`dualprobe.reference.svf` (filter, FOH discretisation, transient projection,
GTLS).

Physics
-------
In an exhaust the gas velocity v(t) follows the engine, so each sensor's time constants vary
with one common factor: ``tau(t) = tau_ref phi(t)``, ``phi = (v/v_ref)^-m``, ``psi = 1/phi``.
First-order sensors, ``Tg = T_i + tau_i(t) T_i'``: eliminating Tg and dividing by phi,

    psi (T2 - T1) = tau1,ref T1' - tau2,ref T2'            (exact, linear in the unknowns)

Two-stage sensors whose stages both scale with phi (gas -> a -> b, ``tau_a = a phi``,
``tau_b = b phi``): ``Tg - T = (a + b) phi T' + a b phi (phi T')'``, so with c = a + b, d = a b

    psi (T2 - T1) = c1 T1' + d1 (phi T1')' - c2 T2' - d2 (phi T2')'

Affine static model (T1 + tau1 T1' = g (T2 + tau2 T2') + o, g = gain1/gain2):
``psi (g T2 + o - T1) = tau1,ref T1' - g tau2,ref T2'`` (order 2 likewise).
A common LTI filter F preserves all of these, so the SVF estimator carries over with new
columns. The schedule may be a combination of K basis weights, ``psi(k) = sum_j a_j b_j(k)``
with unknown a_j (K = 1: ``b_1 = psi`` itself, a_1 = 1 by the normalisation).

Columns (x_j = (tf s)^j F T as in :mod:`.svf`, FOH; every F starts in steady state at the
first value of its input)
--------------------------------------------------------------------------------------------
order 1, unit:  ``z = [x_1(T1), -x_1(T2), F(b_1 (T2 - T1)), ..., F(b_K (T2 - T1))]``
order 2, unit:  ``z = [x_1(T1), y_1(T1), -x_1(T2), -y_1(T2), F(b_1 (T2 - T1)), ...]``
affine (K = 1): the static columns are ``[-F(psi T2), -F(psi T1)]``; the offset regressor
``r = F(psi)`` (equal to 1 when psi == 1) is projected out together with the start-up
transients, as the constant is in :mod:`.svf` (``theta . z = o r``).
hysteresis (order 1, K = 1): the derivative columns are split as in :mod:`.svf`, the static
column is scheduled.

``y_1(T) = tf s F(tf phi s T)``: a ZOH cascade driven on interval k (t_k .. t_k+1) by
``phi_k (T(k+1) - T(k)) tf/Ts`` with ``phi_k = (phi(k) + phi(k+1))/2`` (the trapezoidal mean
of phi over the interval: second-order accurate like the FOH of the other columns; phi(k)
alone leaves a first-order error of about Ts/2 phi' T', which on one noise-free 10 Hz drive
cycle (tf = 1 s) biased the sheath time constants by 0.1-0.5 % and the fitted exponent by
1.3e-3, against <= 1.1e-5 and 6e-6 with the mean), and y_1 its first scaled derivative (row
1 of the derivative map applied to that cascade's states). With phi == 1 the cascade is the
FOH cascade of tf s T, and y_1 equals x_2 exactly.

theta (last entry -1): order 1 ``[tau1/tf, tau2/tf, -a_1/a_K, ..., -1]``, order 2
``[c1/tf, d1/tf^2, c2/tf, d2/tf^2, -a_1/a_K, ..., -1]`` (taus at psi = 1; for K > 1 the
time constants are reported as if a_K were 1, i.e. divided by a_K: the caller renormalises);
affine ``[..., g, -1]`` as in :mod:`.svf`, offset ``o = sum_k (theta . z) r / sum_k r^2``
(the mean of theta . z when psi == 1).

Noise covariance (for the GTLS bias correction)
------------------------------------------------
To first order in the variation of the weights over the filter memory, each column's noise is
a per-row weight times the stationary noise of its unscheduled source column (``C0``,
:func:`dualprobe.reference.svf.noise_covariance`, unsplit layout): derivative columns weight 1
(split: h and 1 - h of the row's interval; the first row, which has no interval, counts as
undecided, h = 1/2), y_1 columns weight phi (source: x_2 of the same sensor), static columns
weight b_j (source: the unscheduled static column; affine: both psi). So the accumulated
``C[a][b] = C0[src a][src b] sum_rows w_a w_b`` (split: plus the switch term,
:func:`dualprobe.reference.svf.switch_covariance`); the streaming core accumulates the moments
of ``omega(k) = [1, h1, h2, phi, b_1..b_K, p1, p2]`` (the entries the variant has; p_i: h_i on
the row before) for this.

Transients are projected out as in :mod:`.svf` with ``Sbb^+``: the pseudo-inverse of the
Gram matrix scaled by its diagonal, eigen-directions below 256 eps of the largest dropped
(the inverse for a whole record; it matters only when the kept rows see the free responses
where they have decayed, e.g. a jackknife replicate without the first block).

Moments (resampling)
--------------------
Everything the solve reads is a sum over rows (scatter of ``[z, extra]``, transient cross and
Gram moments, omega moments, the row count) plus the first samples T1(0), T2(0). So moments
over disjoint stretches of rows add up, and deleting a block of rows (jackknife) is the
estimate from the sums over the remaining rows: :func:`estimate` takes ``keep``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.optimize

from dualprobe.reference import svf

__all__ = [
    "ScheduledColumns",
    "ScheduledResult",
    "estimate",
    "fit_exponent",
    "scheduled_columns",
]


@dataclass(frozen=True)
class ScheduledColumns:
    """Regression columns (p, N) in the documented order, the per-row noise weights (p, N) and
    each column's source column in the unscheduled layout (p,); ``offset_regressor`` r (N,)
    for the affine model (else None)."""

    z: np.ndarray
    weights: np.ndarray
    sources: np.ndarray
    offset_regressor: np.ndarray | None
    disc: svf.FilterDiscretisation


@dataclass(frozen=True)
class ScheduledResult:
    status: str
    order: int
    theta: np.ndarray
    time_constants: tuple[tuple[float, ...], tuple[float, ...]]
    polynomials: tuple[tuple[float, ...], tuple[float, ...]]
    eigenvalues: np.ndarray
    rows: int
    scatter: np.ndarray
    noise: np.ndarray
    extra: dict[str, object] = field(default_factory=dict)


def _as_basis(basis: np.ndarray, n: int) -> np.ndarray:
    b = np.asarray(basis, dtype=float)
    if b.ndim == 1:
        b = b[:, None]
    if b.ndim != 2 or b.shape[0] != n:
        raise ValueError(f"schedule: need shape (N,) or (N, K) with N = {n}, got {b.shape}")
    if not np.all(np.isfinite(b)):
        raise ValueError("schedule: values must be finite")
    if b.shape[1] == 1 and not np.all(b > 0.0):
        raise ValueError("schedule: psi must be > 0")
    return b


def _steady(u: np.ndarray, disc: svf.FilterDiscretisation) -> np.ndarray:
    """F u, the filter starting in steady state at u[0]."""
    return svf.filtered_derivatives(u, disc)[0]


def scheduled_columns(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    tf: float,
    schedule: np.ndarray,
    *,
    order: int = 1,
    static: str = "unit",
    phi: np.ndarray | None = None,
    directions: tuple[np.ndarray, np.ndarray] | None = None,
) -> ScheduledColumns:
    """The scheduled regression columns of the module docstring (batch)."""
    t1 = np.asarray(t1, dtype=float)
    t2 = np.asarray(t2, dtype=float)
    n = t1.size
    b = _as_basis(schedule, n)
    k_basis = b.shape[1]
    if static not in svf.STATIC_MODELS:
        raise ValueError(f"static must be one of {svf.STATIC_MODELS}, got {static!r}")
    if static == "affine" and k_basis != 1:
        raise ValueError("the affine static model takes a single schedule psi (K = 1)")
    if directions is not None and (order != 1 or k_basis != 1):
        raise ValueError("the hysteresis split is defined for order 1 and K = 1")
    disc = svf.discretise_filter(tf, ts, order + 1)
    x1 = svf.filtered_derivatives(t1, disc)
    x2 = svf.filtered_derivatives(t2, disc)
    cols: list[np.ndarray] = []
    weights: list[np.ndarray] = []
    sources: list[int] = []
    ones = np.ones(n)
    if directions is not None:
        split = svf.regression_columns(t1, t2, disc, 1, directions, static)[:4]
        for i, h in enumerate(directions):
            hr = np.concatenate(([0.5], np.asarray(h, dtype=float)))  # row 0: undecided
            cols += [split[2 * i], split[2 * i + 1]]
            weights += [hr, 1.0 - hr]
            sources += [i, i]
    elif order == 1:
        cols += [x1[1], -x2[1]]
        weights += [ones, ones]
        sources += [0, 1]
    elif order == 2:
        if phi is None:
            if k_basis != 1:
                raise ValueError("order 2 with K > 1 needs phi")
            phi = 1.0 / b[:, 0]
        phi = np.asarray(phi, dtype=float)
        if phi.shape != (n,) or not np.all(np.isfinite(phi)) or not np.all(phi > 0.0):
            raise ValueError("phi: need N finite values > 0")
        zoh = svf.discretise_filter(tf, ts, order + 1, "zoh")
        lmap = disc.derivative_map
        mean_phi = 0.5 * (phi[:-1] + phi[1:])
        for sign, x, xd, src in ((1.0, t1, x1, 0), (-1.0, t2, x2, 2)):
            drive = np.zeros(n)
            drive[:-1] = mean_phi * np.diff(x) * (tf / ts)
            y1 = lmap[1] @ svf.filter_states(drive, zoh)
            cols += [sign * xd[1], sign * y1]
            weights += [ones, phi]
            sources += [src, src + 1]
    else:
        raise ValueError(f"order must be 1 or 2, got {order}")
    p_dyn = 2 * order
    r = None
    if static == "unit":
        for j in range(k_basis):
            cols.append(_steady(b[:, j] * (t2 - t1), disc))
            weights.append(b[:, j])
            sources.append(p_dyn)
    else:
        psi = b[:, 0]
        cols += [-_steady(psi * t2, disc), -_steady(psi * t1, disc)]
        weights += [psi, psi]
        sources += [p_dyn, p_dyn + 1]
        r = _steady(psi, disc)
    return ScheduledColumns(z=np.array(cols), weights=np.array(weights),
                            sources=np.array(sources), offset_regressor=r, disc=disc)


def estimate(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    schedule: np.ndarray,
    *,
    tf: float,
    order: int = 1,
    sigma1: float = 0.0,
    sigma2: float = 0.0,
    static: str = "unit",
    phi: np.ndarray | None = None,
    hysteresis: bool = False,
    direction_half_window: int | tuple[int, int] | None = None,
    dead_zone: float = svf.DIRECTION_DEAD_ZONE,
    keep: np.ndarray | None = None,
    transients: np.ndarray | None = None,
) -> ScheduledResult:
    """Scheduled SVF estimate (batch). ``keep``: boolean mask of the rows that count (the
    filters still run over every sample; default all), for delete-a-block resampling.
    ``transients``: mask of the rows whose free responses enter the transient projection
    (default all): moments formed as differences of running totals keep the transient moments
    of late rows only to the rounding of the totals, so a replicate without the first block
    sees none where they have decayed below it (e^-25 and less at a block of 25 tf)."""
    t1 = np.asarray(t1, dtype=float)
    t2 = np.asarray(t2, dtype=float)
    directions = None
    extra: dict[str, object] = {}
    if hysteresis:
        if direction_half_window is None:
            raise ValueError("estimate: hysteresis needs direction_half_window")
        w = direction_half_window
        windows = (w, w) if isinstance(w, int) else (int(w[0]), int(w[1]))
        directions = (svf.direction_indicator(t1, windows[0], sigma1, dead_zone),
                      svf.direction_indicator(t2, windows[1], sigma2, dead_zone))
        extra["direction_half_windows"] = windows
    sc = scheduled_columns(t1, t2, ts, tf, schedule, order=order, static=static, phi=phi,
                           directions=directions)
    disc = sc.disc
    n = t1.size
    mask = np.ones(n, bool) if keep is None else np.asarray(keep, dtype=bool)
    z = sc.z[:, mask]
    # transients: free responses (zero beyond the window), and the offset regressor (affine)
    free = svf.free_response(disc, n)
    basis = np.zeros((free.shape[0], n))
    basis[:, : free.shape[1]] = free
    if transients is not None:
        basis[:, ~np.asarray(transients, dtype=bool)] = 0.0
    if sc.offset_regressor is not None:
        basis = np.vstack([basis, sc.offset_regressor])
    basis = basis[:, mask]
    scatter = z @ z.T
    zb = z @ basis.T
    scatter = scatter - zb @ _gram_pseudo_inverse(basis @ basis.T) @ zb.T
    scatter = 0.5 * (scatter + scatter.T)
    w = sc.weights[:, mask]
    c0 = svf.noise_covariance(disc, order, sigma1, sigma2, static)
    noise = c0[np.ix_(sc.sources, sc.sources)] * (w @ w.T)
    if hysteresis:  # the switch term (svf.switch_covariance); row 0's previous h: undecided
        g1 = svf.split_switch_noise(disc)
        for i, sigma in enumerate((sigma1, sigma2)):
            block = slice(2 * i, 2 * i + 2)
            full = sc.weights[block]
            previous = np.column_stack((np.full(2, 0.5), full[:, :-1]))[:, mask]
            noise[block, block] += svf.switch_covariance(w[block], previous, sigma**2 * g1)
    theta, mu, _ = svf.solve_gtls(scatter, noise)
    rows = int(np.count_nonzero(mask))
    n_dyn = 4 if hysteresis else 2 * order
    gain = float(theta[n_dyn]) if static == "affine" else 1.0
    extra["gain_ratio"] = gain
    if sc.offset_regressor is not None:
        r = sc.offset_regressor[mask]
        extra["offset"] = float((theta @ z) @ r / (r @ r))
    common = {"order": order, "theta": theta, "eigenvalues": mu, "rows": rows,
              "scatter": scatter, "noise": noise}
    if hysteresis:
        taus = theta[:4] * tf / np.array([1.0, 1.0, gain, gain])
        extra.update(heat=((float(taus[0]),), (float(taus[2]),)),
                     cool=((float(taus[1]),), (float(taus[3]),)))
        ok = bool(np.all(taus > 0.0)) and gain > 0.0
        mean = ((0.5 * float(taus[0] + taus[1]),), (0.5 * float(taus[2] + taus[3]),))
        return ScheduledResult(status="ok" if ok else "infeasible", time_constants=mean,
                               polynomials=mean, extra=extra, **common)  # type: ignore[arg-type]
    scale = np.array([tf ** (j + 1) for j in range(order)])
    p1 = tuple(float(v) for v in theta[:order] * scale)
    p2 = tuple(float(v) for v in theta[order:2 * order] * scale / gain)
    tc1 = svf.polynomial_time_constants(p1)
    tc2 = svf.polynomial_time_constants(p2)
    ok = all(math.isfinite(v) for v in tc1 + tc2) and gain > 0.0
    return ScheduledResult(status="ok" if ok else "infeasible", time_constants=(tc1, tc2),
                           polynomials=(p1, p2), extra=extra, **common)  # type: ignore[arg-type]


def _gram_pseudo_inverse(gram: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of the transient Gram matrix Sbb as the estimator defines it: scaled by
    its diagonal, eigen-directions below ``256 eps`` of the largest eigenvalue dropped. Equal
    to the inverse for a whole record; a record (or kept rows, resampling) that sees the free
    responses only where they have decayed to ~1e-11 leaves Sbb nearly singular, and then the
    rule decides which transient directions are projected out."""
    d = np.sqrt(np.diag(gram))
    scale = np.divide(1.0, d, out=np.zeros_like(d), where=d > 0.0)
    values, vectors = np.linalg.eigh(gram * np.outer(scale, scale))
    keep = values > 256.0 * np.finfo(float).eps * values[-1]
    inner = (vectors[:, keep] / values[keep]) @ vectors[:, keep].T
    return inner * np.outer(scale, scale)


def fit_exponent(
    smallest_eigenvalue: Callable[[float], float],
    lower: float = -0.5,
    upper: float = 1.5,
    points: int = 41,
    xtol: float = 1e-9,
) -> tuple[float, float]:
    """Exponent m of ``psi = (v/v_ref)^m`` that minimises the smallest generalised eigenvalue
    of the scheduled fit (the GTLS cost normalised by the noise: comparable across m): a grid
    over [lower, upper], then bounded Brent around the best grid point. Returns (m, mu_min)."""
    grid = np.linspace(lower, upper, points)
    values = np.array([smallest_eigenvalue(float(m)) for m in grid])
    i = int(np.nanargmin(values))
    lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, points - 1)]
    res = scipy.optimize.minimize_scalar(smallest_eigenvalue, bounds=(lo, hi), method="bounded",
                                         options={"xatol": xtol})
    return float(res.x), float(res.fun)
