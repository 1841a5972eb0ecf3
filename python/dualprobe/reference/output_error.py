"""Maximum-likelihood output-error fit of both sensors to one common gas: the independent check of
the flow-scheduled estimator (issue 11, item 6) by a different method.

The product (``dualprobe.estimation``, design.md 1.5) eliminates the gas from the two signals
and solves the scheduled cross-relation, a generalised total-least-squares problem on filtered
derivatives. This module never eliminates the gas: it models it, and fits both sensors' outputs
to it by maximum likelihood, the likelihood computed exactly by a Kalman filter's prediction
error decomposition. Nothing is shared with the product but the physics:

* gas ``g``: a random walk of intensity ``q`` (K^2/s), the gas's level free at the start;
* sensor i: a chain of first-order stages (1 or 2; the first sees the gas), each of time
  constant ``tau_ij,ref * (flow / flow_ref)^-m`` (paper eq. 1 with one exponent for every
  stage: eq. 5's constant ratio); sensor 1 reads its last stage, sensor 2 reads ``gain *
  (its last stage) + offset`` (``static="affine"``) or its last stage (``"unit"``);
* white noise ``sigma_i`` on each reading.

Per interval the flow is the mean of its two samples' flows and the model is discretised
exactly (Van Loan: the matrix exponential of every interval at once, checked against
``scipy.linalg.expm`` in the tests), the gas moving as Brownian
motion inside the interval. The initial state is the first readings' steady state with a wide
prior (``_PRIOR_STD``), and the first ``_BURN_IN`` innovations are left out of the likelihood
(the diffuse start). Every parameter is fitted: ``log tau``, ``m``, ``log q``, ``log sigma``
and the static map, by ``scipy.optimize.minimize`` (L-BFGS-B; its gradient by central
differences, every perturbed parameter set filtered in the same pass over the rows); standard
deviations from the inverse of a central-difference Hessian of the negative log-likelihood.

Slow (a Python loop over the rows): 10-20 s for 1,500 rows with one or two stages per sensor,
minutes with two on each and a static map. Meant for short records in tests, not recordings.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize

__all__ = ["OutputErrorFit", "fit_output_error", "negative_log_likelihood"]

_PRIOR_STD = 100.0  # K: the initial states' prior about the first readings (diffuse)
_BURN_IN = 20  # innovations left out while the diffuse start settles
# Taylor degree 18 on a matrix of norm <= 0.5: remainder 0.5^19/19! < 1e-22 (relative to 1)
_TAYLOR = 18
_TAYLOR_RADIUS = 0.5
_GRADIENT_STEP = 1e-5  # central differences in the parameters (logs, m, the gain: all ~1)
_HESSIAN_STEP = 1e-3  # the Hessian's (its error ~h^2 of the curvature, far below sampling)


@dataclass(frozen=True)
class OutputErrorFit:
    """``taus`` per sensor at the reference flow (stage that sees the gas first), ``exponent``
    m, ``q``, ``sigma`` per sensor, ``static`` (gain, offset) of sensor 2, and the standard
    deviations of the time constants and m (NaN when the Hessian is not positive definite);
    ``nll`` the negative log-likelihood at the optimum, ``success`` the optimiser's flag."""

    taus: tuple[tuple[float, ...], tuple[float, ...]]
    taus_std: tuple[tuple[float, ...], tuple[float, ...]]
    exponent: float
    exponent_std: float
    q: float
    sigma: tuple[float, float]
    static: tuple[float, float]
    nll: float
    success: bool


def _expm(a: np.ndarray) -> np.ndarray:
    """expm of a stack of small matrices: scaling and squaring with a degree-``_TAYLOR`` Taylor
    polynomial, one scaling for the whole stack. ``scipy.linalg.expm`` gives the same to
    ~1e-15 (tested) but costs 30 us per 6 x 6 matrix, and a fit needs millions of them."""
    norm = float(np.max(np.sum(np.abs(a), axis=-1))) if a.size else 0.0
    squarings = max(0, math.ceil(math.log2(norm / _TAYLOR_RADIUS))) if norm > 0.0 else 0
    a = a / 2.0**squarings
    eye = np.eye(a.shape[-1])
    result = eye + a / _TAYLOR  # Horner: I + a (I + a/2 (I + a/3 (...)))
    for k in range(_TAYLOR - 1, 0, -1):
        result = eye + (a @ result) / k
    for _ in range(squarings):
        result = result @ result
    return result


def _discretise(taus1: np.ndarray, taus2: np.ndarray, psi: np.ndarray, h: np.ndarray,
                ) -> tuple[np.ndarray, np.ndarray]:
    """(Phi, Qunit) per parameter set and interval, (B, K, n, n): exact for a gas that is
    Brownian motion of unit intensity and stage rates ``psi / tau`` constant over the interval.
    ``taus_i`` (B, S_i), ``psi`` (B, K), ``h`` (K,)."""
    n = 1 + taus1.shape[1] + taus2.shape[1]
    f = np.zeros((*psi.shape, n, n))
    row = 1
    for taus in (taus1, taus2):
        source = 0
        for j in range(taus.shape[1]):
            rate = psi / taus[:, j:j + 1]
            f[..., row, row] = -rate
            f[..., row, source] = rate
            source = row
            row += 1
    big = np.zeros((*psi.shape, 2 * n, 2 * n))
    big[..., :n, :n] = -f
    big[..., 0, n] = 1.0  # L L^T with L = e_0
    big[..., n:, n:] = np.swapaxes(f, -1, -2)
    e = _expm(big * h[:, None, None])
    phi = np.swapaxes(e[..., n:, n:], -1, -2)
    qunit = phi @ e[..., :n, n:]
    return phi, 0.5 * (qunit + np.swapaxes(qunit, -1, -2))


def _nll(t: np.ndarray, y1: np.ndarray, y2: np.ndarray, psi: np.ndarray, taus1: np.ndarray,
         taus2: np.ndarray, q: np.ndarray, sigma: np.ndarray, static: np.ndarray) -> np.ndarray:
    """-log p(y1, y2) for B parameter sets at once (one pass over the rows: NumPy's per-call
    overhead, not the arithmetic, sets the cost for a few states). Shapes: psi (B, N), taus_i
    (B, S_i), q (B,), sigma and static (B, 2)."""
    b = psi.shape[0]
    phi, qunit = _discretise(taus1, taus2, 0.5 * (psi[:, 1:] + psi[:, :-1]), np.diff(t))
    n = phi.shape[-1]
    out1, out2 = taus1.shape[1], taus1.shape[1] + taus2.shape[1]
    gain, offset = static[:, 0], static[:, 1]
    x = np.repeat(np.full((1, n), float(y1[0])), b, axis=0)
    x[:, out1 + 1:] = ((float(y2[0]) - offset) / gain)[:, None]
    p = np.repeat(np.eye(n)[None] * _PRIOR_STD**2, b, axis=0)
    qs = q[:, None, None, None] * qunit
    phi_t = np.swapaxes(phi, -1, -2)
    # R is diagonal: the two readings update one after the other (exact), scalar by scalar
    readings = ((out1, np.ones(b), np.zeros(b), sigma[:, 0] ** 2, y1),
                (out2, gain, offset, sigma[:, 1] ** 2, y2))
    total = np.zeros(b)
    for k in range(1, t.size):
        x = np.einsum("bij,bj->bi", phi[:, k - 1], x)
        p = phi[:, k - 1] @ p @ phi_t[:, k - 1] + qs[:, k - 1]
        for out, g, o, var, y in readings:
            ph = g[:, None] * p[:, :, out]
            s = g * ph[:, out] + var
            v = y[k] - o - g * x[:, out]
            if k >= _BURN_IN:
                total += 0.5 * (v * v / s + np.log(2.0 * math.pi * s))
            gk = ph / s[:, None]
            x = x + gk * v[:, None]
            p = p - gk[:, :, None] * ph[:, None, :]
        p = 0.5 * (p + np.swapaxes(p, -1, -2))
    return total


def negative_log_likelihood(t: np.ndarray, y1: np.ndarray, y2: np.ndarray, psi: np.ndarray,
                            taus1: Sequence[float], taus2: Sequence[float], q: float,
                            sigma: tuple[float, float], static: tuple[float, float] = (1.0, 0.0),
                            ) -> float:
    """-log p(y1, y2) of the model (module docstring) with the schedule ``psi`` per row (time
    constants ``tau / psi``), by the Kalman filter's prediction error decomposition."""
    t, y1, y2, psi = (np.asarray(v, dtype=float) for v in (t, y1, y2, psi))
    return float(_nll(t, y1, y2, psi[None], np.asarray(taus1, float)[None],
                      np.asarray(taus2, float)[None], np.array([q]), np.array([sigma]),
                      np.array([static], dtype=float))[0])


def fit_output_error(t: np.ndarray, y1: np.ndarray, y2: np.ndarray, flow: np.ndarray,
                     start1: Sequence[float], start2: Sequence[float], *,
                     exponent: float = 0.5, static: str = "unit") -> OutputErrorFit:
    """Maximum-likelihood fit (module docstring) from the stage time constants ``start1``,
    ``start2`` (their count sets each sensor's order) and ``exponent``; the flow's median is
    the reference flow."""
    t, y1, y2, flow = (np.asarray(v, dtype=float) for v in (t, y1, y2, flow))
    if not (t.size == y1.size == y2.size == flow.size) or t.size <= _BURN_IN + 10:
        raise ValueError("output_error: t, y1, y2 and flow need one equal length > 30")
    if not np.all(np.isfinite(flow) & (flow > 0.0)):
        raise ValueError("output_error: the flow must be finite and positive")
    n1, n2 = len(start1), len(start2)
    affine = static == "affine"
    log_ratio = np.log(flow / float(np.median(flow)))
    scale = float(np.mean(np.abs(y1)))  # the offset is fitted in units of the signal's level
    noise = [max(float(np.std(np.diff(y))) / math.sqrt(2.0), 1e-3) for y in (y1, y2)]
    gas_moves = float(np.mean(np.diff(y1) ** 2)) / float(np.mean(np.diff(t)))
    # parameters: log taus, m, log q, log sigma1, log sigma2, (gain, offset / scale)
    u0 = np.concatenate([np.log(start1), np.log(start2),
                         [exponent, math.log(10.0 * gas_moves + 1e-6)], np.log(noise),
                         [1.0, 0.0] if affine else []])

    def batch(u: np.ndarray) -> np.ndarray:
        u = np.atleast_2d(u)
        k = n1 + n2
        stat = (np.column_stack([u[:, k + 4], u[:, k + 5] * scale]) if affine
                else np.tile([1.0, 0.0], (u.shape[0], 1)))
        values = np.full(u.shape[0], math.inf)
        ok = np.all(np.isfinite(u), axis=1) & (stat[:, 0] > 0.0)
        if np.any(ok):
            v = u[ok]
            with np.errstate(all="ignore"):
                values[ok] = _nll(t, y1, y2, np.exp(v[:, k:k + 1] * log_ratio[None]),
                                  np.exp(v[:, :n1]), np.exp(v[:, n1:k]), np.exp(v[:, k + 1]),
                                  np.exp(v[:, k + 2:k + 4]), stat[ok])
        return np.where(np.isfinite(values), values, math.inf)

    def value_and_gradient(u: np.ndarray) -> tuple[float, np.ndarray]:
        # central differences, all 2P + 1 points in one pass over the rows
        steps = _GRADIENT_STEP * np.eye(u.size)
        values = batch(np.vstack([u, u + steps, u - steps]))
        grad = (values[1:u.size + 1] - values[u.size + 1:]) / (2.0 * _GRADIENT_STEP)
        return float(values[0]), np.where(np.isfinite(grad), grad, 0.0)

    result = scipy.optimize.minimize(value_and_gradient, u0, jac=True, method="L-BFGS-B")
    u = result.x
    cov = _inverse_hessian(batch, u)
    std = np.sqrt(np.diag(cov)) if cov is not None else np.full(u.size, math.nan)
    taus1, taus2 = np.exp(u[:n1]), np.exp(u[n1:n1 + n2])
    k = n1 + n2
    # the standard deviation of log tau times tau: that of tau itself (to first order)
    return OutputErrorFit(
        (tuple(float(v) for v in taus1), tuple(float(v) for v in taus2)),
        (tuple(float(v) for v in taus1 * std[:n1]),
         tuple(float(v) for v in taus2 * std[n1:k])),
        float(u[k]), float(std[k]), math.exp(u[k + 1]),
        (math.exp(u[k + 2]), math.exp(u[k + 3])),
        (float(u[k + 4]), float(u[k + 5]) * scale) if affine else (1.0, 0.0),
        float(result.fun), bool(result.success))


def _inverse_hessian(batch: Callable[[np.ndarray], np.ndarray], u: np.ndarray,
                     ) -> np.ndarray | None:
    """The inverse of the central-difference Hessian of the negative log-likelihood at ``u``
    (every point in one batch; None if not positive definite)."""
    n = u.size
    h = _HESSIAN_STEP
    steps = np.eye(n) * h
    points = []
    for i in range(n):
        for j in range(i, n):
            ei, ej = steps[i], steps[j]
            points += [u + ei + ej, u + ei - ej, u - ei + ej, u - ei - ej]
    values = batch(np.vstack(points))
    hess = np.zeros((n, n))
    at = 0
    for i in range(n):
        for j in range(i, n):
            pp, pm, mp, mm = values[at:at + 4]
            at += 4
            hess[i, j] = hess[j, i] = (pp - pm - mp + mm) / (4.0 * h * h)
    if not np.all(np.isfinite(hess)):
        return None
    try:
        chol = np.linalg.cholesky(hess)
    except np.linalg.LinAlgError:
        return None
    return np.asarray(scipy.linalg.cho_solve((chol, True), np.eye(n)))
