"""The oracle of the field-condition tests: the best linear reconstruction that knows the truth.

Given the TRUE time-varying dynamics of both sensors (element and sheath time constants in
effect on every row interval, gains, offsets, noise levels), the gas temperature is estimated by
the linear-Gaussian smoother of a state-space model: gas samples with a random-walk or
integrated-random-walk prior, each sensor an exact chain of first-order stages driven by the
gas interpolated linearly between rows (first-order hold), the rows the sensors' outputs plus
white noise. The smoother's mean (what an RTS smoother returns) is the solution of one sparse
least-squares problem. The prior's intensity and kind are chosen to minimise the RMSE against
the true gas (a grid), so nothing the estimators do can do better with these sensors: it is the
"best achievable" that accuracy tests compare with.

Written independently of dualprobe's estimation and reconstruction code (SciPy sparse only).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

__all__ = ["OracleResult", "at_level", "oracle", "ratio_to_oracle", "schedule_blame", "smooth"]


def _chain_foh(taus: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-interval exact discretisation of a 1- or 2-stage chain with a linear input between
    the rows: x(k+1) = M x(k) + G0 u(k) + G1 u(k+1). taus (N-1, S)."""
    n = taus.shape[0]
    if taus.shape[1] == 1:
        z = h / taus[:, 0]
        a = np.exp(-z)
        c = -np.expm1(-z) / z
        return a[:, None, None], (c - a)[:, None], (1.0 - c)[:, None]
    a_, b_ = taus[:, 0], taus[:, 1]
    ea, eb = np.exp(-h / a_), np.exp(-h / b_)
    hd = h * (1.0 / b_ - 1.0 / a_)
    small = np.abs(hd) < 1e-8
    rel = np.where(small, 1.0 + 0.5 * hd, np.expm1(hd) / np.where(small, 1.0, hd))
    m = np.zeros((n, 2, 2))
    m[:, 0, 0], m[:, 1, 1], m[:, 1, 0] = ea, eb, (h / b_) * eb * rel

    def forced(u0: np.ndarray, u1: np.ndarray) -> np.ndarray:
        s = (u1 - u0) / h
        p0 = np.stack([u0 - s * a_, u0 - s * (a_ + b_)], axis=1)
        p1 = p0 + (s * h)[:, None]
        return p1 - np.einsum("nij,nj->ni", m, p0)

    one, zero = np.ones(n), np.zeros(n)
    return m, forced(one, zero), forced(zero, one)


def _stage_taus(element: np.ndarray, sheath: np.ndarray | None) -> np.ndarray:
    """(N-1, S) per-interval stage time constants (first stage sees the gas)."""
    mid = 0.5 * (element[1:] + element[:-1])
    if sheath is None or not np.any(sheath > 0.0):
        return mid[:, None]
    return np.column_stack([0.5 * (sheath[1:] + sheath[:-1]), mid])


def smooth(
    t: np.ndarray,
    y1: np.ndarray,
    y2: np.ndarray,
    taus1: np.ndarray,
    taus2: np.ndarray,
    sigma: tuple[float, float],
    q: float,
    gas: str = "rw",
) -> np.ndarray:
    """Smoother mean of the gas at the rows. ``taus_i`` (N-1, S_i) per-interval stage time
    constants; ``y_i`` already mapped to unit gain, zero offset; ``q``: K^2/s (rw), K^2/s^3
    (irw). The sensor dynamics are hard constraints up to 1e-6 K (exact sensors)."""
    n = y1.size
    h = np.diff(t)
    models = [_chain_foh(taus1, h), _chain_foh(taus2, h)]
    sizes = [taus1.shape[1], taus2.shape[1]]
    nx = 1 + sum(sizes)
    centre = 0.5 * (float(np.mean(y1)) + float(np.mean(y2)))
    rows: list[np.ndarray] = []
    cols: list[np.ndarray] = []
    vals: list[np.ndarray] = []
    rhs: list[np.ndarray] = []
    count = 0

    def add(r: np.ndarray, c: np.ndarray, v: np.ndarray) -> None:
        rows.append(r)
        cols.append(c)
        vals.append(v)

    k_all = np.arange(n)
    out_index = [sizes[0], sizes[0] + sizes[1]]
    for y, idx, s in zip((y1, y2), out_index, sigma, strict=True):
        add(count + k_all, k_all * nx + idx, np.full(n, 1.0 / s))
        rhs.append((y - centre) / s)
        count += n
    k = np.arange(n - 1)
    eps = 1e-6
    base = 1
    for (m, g0, g1), size in zip(models, sizes, strict=True):
        for j in range(size):
            r = count + k
            add(r, (k + 1) * nx + base + j, np.full(n - 1, 1.0 / eps))
            for i in range(size):
                add(r, k * nx + base + i, -m[:, j, i] / eps)
            add(r, k * nx, -g0[:, j] / eps)
            add(r, (k + 1) * nx, -g1[:, j] / eps)
            rhs.append(np.zeros(n - 1))
            count += n - 1
        base += size
    if gas == "rw":
        sd = np.sqrt(q * h)
        add(count + k, (k + 1) * nx, 1.0 / sd)
        add(count + k, k * nx, -1.0 / sd)
        rhs.append(np.zeros(n - 1))
        count += n - 1
    else:
        k2 = np.arange(1, n - 1)
        sd = np.sqrt(q * (2.0 / 3.0) * h[1:] ** 3)
        for offset, weight in ((1, 1.0), (0, -2.0), (-1, 1.0)):
            add(count + k2 - 1, (k2 + offset) * nx, weight / sd)
        rhs.append(np.zeros(n - 2))
        count += n - 2
    for j in range(nx - 1):  # weak start: every stage at the first readings
        add(np.array([count]), np.array([1 + j]), np.array([1e-3]))
        first = y1[0] if j < sizes[0] else y2[0]
        rhs.append(np.array([1e-3 * (first - centre)]))
        count += 1
    design = sp.csr_matrix(
        (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(count, n * nx)
    )
    b = np.concatenate(rhs)
    x = spl.spsolve((design.T @ design).tocsc(), design.T @ b)
    return x[0::nx] + centre


@dataclass(frozen=True)
class OracleResult:
    rmse: float
    gas: np.ndarray
    prior: str
    q: float


def oracle(
    t: np.ndarray,
    y1: np.ndarray,
    y2: np.ndarray,
    truth: np.ndarray,
    element1: np.ndarray,
    element2: np.ndarray,
    sigma: tuple[float, float],
    *,
    sheath1: np.ndarray | None = None,
    sheath2: np.ndarray | None = None,
    static1: tuple[float, float] = (1.0, 0.0),
    static2: tuple[float, float] = (1.0, 0.0),
    gases: tuple[str, ...] = ("rw", "irw"),
) -> OracleResult:
    """Best smoother over a grid of prior intensities (and rw/irw) against the true gas.

    ``element_i``/``sheath_i``: true time constants in effect at the rows; ``static_i``: the
    true (gain, offset) of each sensor, removed before smoothing."""
    u1 = (np.asarray(y1, float) - static1[1]) / static1[0]
    u2 = (np.asarray(y2, float) - static2[1]) / static2[0]
    s = (sigma[0] / static1[0], sigma[1] / static2[0])
    taus1 = _stage_taus(np.asarray(element1, float), sheath1)
    taus2 = _stage_taus(np.asarray(element2, float), sheath2)
    best: OracleResult | None = None
    for prior in gases:
        grid = np.logspace(-3, 3, 13) if prior == "rw" else np.logspace(-2, 5, 15)
        scores = []
        for q in grid:
            g = smooth(t, u1, u2, taus1, taus2, s, float(q), prior)
            rmse = float(np.sqrt(np.mean((g - truth) ** 2)))
            scores.append(rmse)
            if best is None or rmse < best.rmse:
                best = OracleResult(rmse, g, prior, float(q))
        # refine around the best grid point (golden section on log q)
        i = int(np.argmin(scores))
        lo, hi = math.log(grid[max(i - 1, 0)]), math.log(grid[min(i + 1, grid.size - 1)])
        for _ in range(6):
            m1, m2 = lo + 0.382 * (hi - lo), lo + 0.618 * (hi - lo)
            r = []
            for lq in (m1, m2):
                g = smooth(t, u1, u2, taus1, taus2, s, math.exp(lq), prior)
                rmse = float(np.sqrt(np.mean((g - truth) ** 2)))
                r.append(rmse)
                if best is None or rmse < best.rmse:
                    best = OracleResult(rmse, g, prior, math.exp(lq))
            lo, hi = (lo, m2) if r[0] < r[1] else (m1, hi)
    assert best is not None
    return best


def through_stage(t: np.ndarray, u: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """``u`` through a first-order stage of per-row time constant ``tau``, exact for ``u``
    linear between rows (written apart from the product's stage chains)."""
    x = np.empty_like(u)
    x[0] = u[0]
    for k in range(u.size - 1):
        h = t[k + 1] - t[k]
        z = h / tau[k]
        a = np.exp(-z)
        c = -np.expm1(-z) / z
        x[k + 1] = a * x[k] + (c - a) * u[k] + (1.0 - c) * u[k + 1]
    return x


def common_part_error(t: np.ndarray, gas: np.ndarray, sheath1: np.ndarray | None,
                      sheath2: np.ndarray | None) -> float:
    """RMSE against ``gas`` of the gas seen through the part of the two sheaths that both
    sensors share (the smaller one on every row; 0 where a sensor has none): what an estimate
    that undoes everything but that part still misses. A lag both sensors share cancels from
    the pair's cross-relation, and near-equal sheaths leave the shared part weakly determined
    (the direction that moves both sheaths alike), so a pair-only estimate near this error
    has undone what the pair can tell apart."""
    if sheath1 is None or sheath2 is None:
        return 0.0
    seen = through_stage(t, gas, np.minimum(sheath1, sheath2))
    return float(np.sqrt(np.mean((seen - gas) ** 2)))


def at_level(values: np.ndarray) -> float:
    """The geometric mean: a per-row time constant at the schedule's level (mean log psi 0)."""
    return float(np.exp(np.mean(np.log(values))))


def schedule_blame(t: np.ndarray, y1: np.ndarray, y2: np.ndarray, gas: np.ndarray,
                   truth: tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None],
                   sigma: tuple[float, float], static2: tuple[float, float],
                   stages: tuple[tuple[float, ...], tuple[float, ...]], psi: np.ndarray,
                   found_static2: tuple[float, float]) -> tuple[float, float]:
    """Where a tracked estimate's gas error comes from: the oracle's smoother given one part of
    the estimate and the rest true. ``truth``: the per-row element and sheath time constants
    (element1, element2, sheath1, sheath2; None: no sheath), which all follow one schedule
    (eq. 1: the generator's stages scale alike); ``static2`` the true (gain, offset) of sensor
    2 in sensor 1's calibration. The estimate: ``stages`` (each sensor's time constants at
    the level of ``psi``, element first, then its sheath), its per-row ``psi`` (time constants
    in effect = stage / psi) and ``found_static2`` (sensor 2's gain and offset as found).
    Returns the RMSE against ``gas`` of (the estimate's stages and static map on the TRUE
    schedule, the TRUE stages on the estimate's schedule): near the oracle's in the first,
    the schedule is the error; in the second, the stages."""
    element1, element2, sheath1, sheath2 = truth
    true_psi = at_level(element1) / np.asarray(element1, float)  # mean log 0, as psi's
    found = np.asarray(psi, float)

    def run(pair: tuple[tuple[float, ...], tuple[float, ...]], schedule: np.ndarray,
            static: tuple[float, float]) -> float:
        rows = [[tau / schedule for tau in sensor] for sensor in pair]
        return oracle(t, y1, y2, gas, rows[0][0], rows[1][0], sigma,
                      sheath1=rows[0][1] if len(rows[0]) > 1 else None,
                      sheath2=rows[1][1] if len(rows[1]) > 1 else None,
                      static2=static, gases=("rw",)).rmse

    true_stages = tuple((at_level(e),) + (() if s is None else (at_level(s),))
                        for e, s in ((element1, sheath1), (element2, sheath2)))
    return (run(stages, true_psi, found_static2),
            run((true_stages[0], true_stages[1]), found, static2))


def worst_factor(*ratios: np.ndarray) -> float:
    """The largest factor by which any row of these estimate-over-truth ratios is off, either
    way (2.0 for a row at twice or at half the truth)."""
    return float(np.exp(max(np.max(np.abs(np.log(r))) for r in ratios)))


def ratio_to_oracle(estimate: np.ndarray, rec: Any) -> float:
    """RMSE of a gas ``estimate`` against ``rec.gas`` over the oracle's, for an unsheathed
    record of tests/python/field_independent.py (its true per-row time constants ``tau1``,
    ``tau2`` and its ``noise``)."""
    ours = float(np.sqrt(np.mean((np.asarray(estimate) - rec.gas) ** 2)))
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  gases=("rw",)).rmse
    return ours / best
