"""The compiled core's SVF cross-relation estimator, as the estimation runs it: the one engine.

:func:`fit` runs ``_core.estimate_svf`` (svf_estimator.hpp, the code the ECU links) on a record
and returns what the orchestration needs: the solution, the projected scatter and accumulated
noise covariance handed to GTLS (for sub-model solves and statistics), and, when asked, the
moment vectors of consecutive blocks (additive: the block jackknife of
:mod:`dualprobe.estimation.uncertainty` solves totals minus one block with :func:`solve`).
:func:`effective_samples` and :func:`noise_covariance` are the noise model's statistics, from
the core's exact discretisation of the filter.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import scipy.linalg
import scipy.signal

from dualprobe import _core

__all__ = [
    "STATIC_MODELS",
    "Fit",
    "effective_samples",
    "fit",
    "noise_covariance",
    "polynomial_time_constants",
    "solve",
]

STATIC_MODELS = ("unit", "affine")


@dataclass(frozen=True, eq=False)
class Fit:
    """One solve of the (scheduled) cross-relation (design.md 1.4-1.5); time constants per
    sensor, largest first (NaN where not real and positive). ``scatter``/``noise``: the
    projected scatter and the accumulated noise covariance (documented column order);
    ``blocks`` (B, L): moment vectors of consecutive blocks (None unless asked)."""

    status: str
    order: int
    static: str
    hysteresis: bool
    tf: float
    ts: float
    sigma: tuple[float, float]
    basis: int
    theta: np.ndarray
    eigenvalues: np.ndarray
    time_constants: tuple[tuple[float, ...], tuple[float, ...]]
    polynomials: tuple[tuple[float, ...], tuple[float, ...]]
    rows: float
    gain_ratio: float
    offset: float
    scatter: np.ndarray
    noise: np.ndarray
    offsets: tuple[float, float]
    blocks: np.ndarray | None = None
    heat: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    cool: tuple[tuple[float, ...], tuple[float, ...]] | None = None
    windows: tuple[int, int] = (0, 0)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def misfit(self) -> float:
        """Smallest generalised eigenvalue: the fit's residual in units of the noise's."""
        return float(self.eigenvalues[0]) if self.eigenvalues.size else math.inf

    @property
    def ok(self) -> bool:
        return self.status == "ok"

    def fast_time_constant(self) -> float:
        """Largest time constant of the faster sensor (NaN when the fit is unusable)."""
        if not self.ok:
            return math.nan
        fast = min(self.time_constants[0][0], self.time_constants[1][0])
        return fast if math.isfinite(fast) and fast > 0.0 else math.nan


def _pairs(value: Any) -> tuple[tuple[float, ...], tuple[float, ...]]:
    return (tuple(float(v) for v in value[0]), tuple(float(v) for v in value[1]))


def _from_result(out: dict[str, Any], *, order: int, static: str, hysteresis: bool, tf: float,
                 ts: float, sigma: tuple[float, float], basis: int,
                 windows: tuple[int, int]) -> Fit:
    heat = _pairs(out["time_constants_heat"]) if hysteresis else None
    cool = _pairs(out["time_constants_cool"]) if hysteresis else None
    blocks = out.get("block_moments")
    return Fit(
        status=str(out["status"]), order=order, static=static, hysteresis=hysteresis, tf=tf,
        ts=ts, sigma=sigma, basis=basis, theta=np.asarray(out["theta"], dtype=float),
        eigenvalues=np.asarray(out["eigenvalues"], dtype=float),
        time_constants=_pairs(out["time_constants"]), polynomials=_pairs(out["polynomials"]),
        rows=float(out["rows"]), gain_ratio=float(out.get("gain_ratio", 1.0)),
        offset=float(out.get("offset", 0.0)),
        scatter=np.asarray(out.get("scatter", np.zeros((0, 0))), dtype=float),
        noise=np.asarray(out.get("accumulated_noise_covariance", np.zeros((0, 0))), dtype=float),
        offsets=(float(out["offsets"][0]), float(out["offsets"][1])),
        blocks=None if blocks is None else np.asarray(blocks, dtype=float), heat=heat, cool=cool,
        windows=windows, extra={"moments": np.asarray(out["moments"], dtype=float)},
    )


def fit(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    *,
    tf: float,
    order: int = 1,
    static: str = "unit",
    hysteresis: bool = False,
    sigma: tuple[float, float] = (0.0, 0.0),
    schedule: np.ndarray | None = None,
    phi: np.ndarray | None = None,
    windows: tuple[int, int] | None = None,
    block_length: int = 0,
) -> Fit | None:
    """One run of the core's estimator over the record; None when the data give no usable
    scatter (a column without excitation). ``schedule``: psi (N,) or K basis weights (N, K)
    (design.md 1.5); ``phi`` (N,): 1/psi for order 2 with K > 1; ``windows``: the heating/
    cooling classification's half windows (hysteresis)."""
    if hysteresis and windows is None:
        windows = direction_half_windows(t1, t2, ts, tf, sigma)
    basis = 0 if schedule is None else (1 if np.ndim(schedule) == 1 else int(schedule.shape[1]))
    try:
        out = _core.estimate_svf(
            np.ascontiguousarray(t1, dtype=float), np.ascontiguousarray(t2, dtype=float),
            float(ts), float(tf), order=order, static=static, hysteresis=hysteresis,
            sigma1=float(sigma[0]), sigma2=float(sigma[1]),
            direction_half_window=None if windows is None else tuple(windows),
            schedule=None if schedule is None else np.ascontiguousarray(schedule, dtype=float),
            phi=None if phi is None else np.ascontiguousarray(phi, dtype=float),
            block_length=int(block_length))
    except ValueError:
        return None
    if str(out["status"]) == "insufficient_excitation" and not np.any(out["eigenvalues"]):
        return None
    return _from_result(out, order=order, static=static, hysteresis=hysteresis, tf=tf, ts=ts,
                        sigma=sigma, basis=basis, windows=windows or (0, 0))


def solve(like: Fit, moments: np.ndarray) -> Fit:
    """The same model as ``like`` solved from a moment vector (a total minus a block)."""
    out = _core.solve_svf_moments(
        np.ascontiguousarray(moments, dtype=float), like.ts, like.tf, order=like.order,
        static=like.static, hysteresis=like.hysteresis, sigma1=like.sigma[0],
        sigma2=like.sigma[1], basis=like.basis, offsets=like.offsets)
    out.setdefault("offsets", like.offsets)
    out.setdefault("moments", moments)
    return _from_result(out, order=like.order, static=like.static, hysteresis=like.hysteresis,
                        tf=like.tf, ts=like.ts, sigma=like.sigma, basis=like.basis,
                        windows=like.windows)


# --------------------------------------------------------------------------------------------
# The noise model's statistics (from the core's exact discretisation of the filter)
# --------------------------------------------------------------------------------------------


def _column_maps(order: int, static: str) -> tuple[np.ndarray, np.ndarray]:
    """z = M1 x(T1) + M2 x(T2) for the unsplit layout (design.md 1.4)."""
    p = 2 * order + (1 if static == "unit" else 2)
    m1 = np.zeros((p, order + 1))
    m2 = np.zeros((p, order + 1))
    for j in range(1, order + 1):
        m1[j - 1, j] = 1.0
        m2[order + j - 1, j] = -1.0
    if static == "unit":
        m1[-1, 0], m2[-1, 0] = -1.0, 1.0
    else:
        m2[-2, 0], m1[-1, 0] = -1.0, -1.0
    return m1, m2


def noise_covariance(ts: float, tf: float, order: int, sigma: tuple[float, float],
                     static: str = "unit") -> np.ndarray:
    """Stationary noise covariance of one unscheduled, unsplit row under white noise sigma."""
    disc = _core.svf_discretisation(ts, tf, order + 1, "foh")
    lmap = np.asarray(disc["derivative_map"])[: order + 1]
    cov_x = lmap @ np.asarray(disc["state_covariance"]) @ lmap.T
    m1, m2 = _column_maps(order, static)
    c = sigma[0] ** 2 * (m1 @ cov_x @ m1.T) + sigma[1] ** 2 * (m2 @ cov_x @ m2.T)
    return 0.5 * (c + c.T)


def effective_samples(like: Fit, theta: np.ndarray | None = None) -> float:
    """Effective number of independent rows for the equation error ``theta . z_noise``: the
    filtered noise is correlated over ~tf, so a second moment over ``rows`` rows scatters like
    one over ``rows R(0)^2 / sum_l R(l)^2`` independent rows (R: the autocovariance of the
    equation error, from the filter's impulse response). The split (hysteresis) parameters
    count with their mean."""
    order, m = like.order, like.order + 1
    th = np.asarray(like.theta if theta is None else theta, dtype=float)
    if like.hysteresis:
        th = np.concatenate(([0.5 * (th[0] + th[1]), 0.5 * (th[2] + th[3])], th[4:]))
    th = th[: 2 * order + (1 if like.static == "unit" else 2)]
    m1, m2 = _column_maps(order, like.static)
    length = int(min(math.ceil((40.0 + 4.0 * m) * like.tf / like.ts) + 2, 4 * like.rows + 2))
    impulse = np.zeros(length)
    impulse[0] = 1.0
    x = _core.svf_filter(impulse, like.ts, like.tf, m, "foh")[0][: order + 1]  # (order+1, L)
    acov = np.zeros(2 * length - 1)
    for weight, mat in ((like.sigma[0], m1), (like.sigma[1], m2)):
        if weight == 0.0:
            continue
        h = (th @ mat) @ x
        acov += weight**2 * scipy.signal.fftconvolve(h, h[::-1])
    r0 = acov[length - 1]
    total = float(np.sum(acov**2))
    if not (r0 > 0.0 and total > 0.0):
        return float(like.rows)
    return float(like.rows) * r0**2 / total


def polynomial_time_constants(coeffs: tuple[float, ...]) -> tuple[float, ...]:
    """Time constants of ``1 + c1 s (+ c2 s^2)``, largest first; NaN unless real and > 0."""
    if len(coeffs) == 1:
        c = float(coeffs[0])
        return (c,) if math.isfinite(c) and c > 0.0 else (math.nan,)
    c, d = (float(v) for v in coeffs)
    disc = c * c - 4.0 * d
    if disc < 0.0 and -disc <= 16.0 * np.finfo(float).eps * c * c:
        disc = 0.0  # a double pole comes out with a discriminant of rounding size
    if not (c > 0.0 and d > 0.0 and disc >= 0.0 and math.isfinite(c) and math.isfinite(d)):
        return (math.nan, math.nan)
    big = 0.5 * (c + math.sqrt(disc))
    return (big, d / big)


def solve_gtls(scatter: np.ndarray, cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Generalised TLS on a (sub-)scatter as the core solves it: scaling by diag(S)^-1/2, C
    regularised by 1e-12 max(trace, 1) I; returns (theta with last entry -1, eigenvalues)."""
    diagonal = np.diag(scatter)
    if not np.all(np.isfinite(diagonal)) or np.any(diagonal <= 0.0):
        raise np.linalg.LinAlgError("solve_gtls: a regression column is identically zero")
    d = np.sqrt(diagonal)
    s_n = scatter / np.outer(d, d)
    c_n = cov / np.outer(d, d)
    c_n = c_n + 1e-12 * max(float(np.trace(c_n)), 1.0) * np.eye(d.size)
    mu, vecs = scipy.linalg.eigh(s_n, c_n)
    v = vecs[:, 0] / d
    theta = -v / v[-1] if v[-1] != 0.0 else np.full(v.size, np.nan)
    return theta, mu


def direction_half_windows(t1: np.ndarray, t2: np.ndarray, ts: float, tf: float,
                           sigma: tuple[float, float], tolerance: float = 0.01
                           ) -> tuple[int, int]:
    """Half windows of the heating/cooling classification (design.md 1.4, hysteresis): per
    sensor the smallest w whose slope-noise std ``sigma sqrt(2/w) / ((w+1) Ts)`` is at most
    ``tolerance`` times the RMS filtered slope, capped at tf/Ts."""
    out = []
    w_max = max(1, round(tf / ts))
    for x, s in ((t1, sigma[0]), (t2, sigma[1])):
        if s <= 0.0:
            out.append(1)
            continue
        xs = np.asarray(x, dtype=float)
        slope = _core.svf_filter(xs - xs[0], ts, tf, 2, "foh")[0][1] / tf
        scale = float(np.sqrt(np.mean(slope * slope)))
        if not scale > 0.0:
            out.append(w_max)
            continue
        w = np.arange(1, w_max + 1, dtype=float)
        ok = s * np.sqrt(2.0 / w) / ((w + 1.0) * ts) <= tolerance * scale
        out.append(int(w[ok][0]) if np.any(ok) else w_max)
    return out[0], out[1]
