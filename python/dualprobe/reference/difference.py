"""Independent NumPy/SciPy reference of the difference-equation dual estimator (design 1.2)
and of the exact-inverse reconstruction (design 1.3); the check on the C++ core.

Model (paper eqs. 8-12): ``dT2(k) = beta dT1(k) + b2 dT12(k-1)`` with ``beta = b2/b1``,
``b_i = 1 - exp(-Ts/tau_i)``. Rows ``z(k) = [dT1(k), dT12(k-1), dT2(k)]``, k = 1..N-1; row k
(0-based among the M rows) carries weight ``forgetting**(M-1-k)``.

Choices where the contract is silent:
* GTLS needs both ``sigma1 > 0`` and ``sigma2 > 0`` (only their ratio matters); otherwise the
  status is ``invalid_argument`` (no silent fallback to TLS, whose noise model is wrong here).
* Invalid numbers (ts, sigma, forgetting) give status ``invalid_argument``; any non-finite
  sample gives ``non_finite_input`` for the whole batch. Wrong shapes or an unknown method
  name are programming errors and raise ``ValueError``.
* ``insufficient_excitation``: fewer than 3 rows, a regressor column (dT1 or dT12) that is
  identically zero, or regressors collinear to within 1e-10 (condition of the normalised
  regressor Gram matrix above ~2e10).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg
import scipy.signal

__all__ = [
    "METHODS",
    "STATUSES",
    "DifferenceResult",
    "estimate",
    "exact_inverse",
    "noise_covariance",
    "reconstruct",
    "regression_rows",
    "sensor1_weight",
]

METHODS = ("ls", "tls", "gtls")
STATUSES = ("ok", "insufficient_excitation", "infeasible", "non_finite_input", "invalid_argument")
_COLLINEARITY_TOL = 1e-10  # 1 - |corr(dT1, dT12)| below this: the two regressors are one


@dataclass(frozen=True, eq=False)
class DifferenceResult:
    """Outcome of :func:`estimate`. All numbers are NaN unless ``status == "ok"``;
    ``raw_theta`` keeps the solver's [beta, b2] (when one was computed) for diagnosis."""

    status: str
    beta: float
    b1: float
    b2: float
    tau1: float
    tau2: float
    theta: np.ndarray
    method: str = "gtls"
    rows: int = 0
    raw_theta: np.ndarray = field(default_factory=lambda: np.full(2, np.nan))

    @property
    def ok(self) -> bool:
        return self.status == "ok"


def _failed(
    status: str, method: str, rows: int = 0, raw: np.ndarray | None = None
) -> DifferenceResult:
    nan = float("nan")
    return DifferenceResult(
        status=status,
        beta=nan,
        b1=nan,
        b2=nan,
        tau1=nan,
        tau2=nan,
        theta=np.full(2, nan),
        method=method,
        rows=rows,
        raw_theta=np.full(2, nan) if raw is None else raw,
    )


def _pair(t1: np.ndarray, t2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.asarray(t1, dtype=float)
    b = np.asarray(t2, dtype=float)
    if a.ndim != 1 or a.shape != b.shape:
        raise ValueError(f"sensor signals must be 1-D of equal length, got {a.shape} and {b.shape}")
    return a, b


def regression_rows(t1: np.ndarray, t2: np.ndarray) -> np.ndarray:
    """Rows ``[dT1(k), dT12(k-1), dT2(k)]`` for k = 1..N-1, shape (N-1, 3) (eq. 11)."""
    a, b = _pair(t1, t2)
    return np.column_stack([np.diff(a), a[:-1] - b[:-1], np.diff(b)])


def noise_covariance(sigma1: float, sigma2: float) -> np.ndarray:
    """Covariance of the noise part of a row under white noise sigma1 on T1, sigma2 on T2.

    dT1 and dT12 share e1(k-1) (with opposite signs), dT12 and dT2 share e2(k-1).
    """
    v1 = float(sigma1) ** 2
    v2 = float(sigma2) ** 2
    return np.array([[2 * v1, -v1, 0.0], [-v1, v1 + v2, v2], [0.0, v2, 2 * v2]])


def _time_constant(b: float, ts: float) -> float:
    return -ts / math.log1p(-b)


def estimate(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    method: str = "gtls",
    sigma1: float = 0.0,
    sigma2: float = 0.0,
    forgetting: float = 1.0,
) -> DifferenceResult:
    """Estimate beta, b1, b2 and the two time constants from the whole record (batch).

    ``ls``: ordinary least squares of dT2 on [dT1, dT12] (biased when T1 is noisy);
    ``tls``: smallest right singular vector of the weighted row matrix;
    ``gtls``: smallest generalised eigenvector of ``S v = mu C v`` with ``C`` from
    :func:`noise_covariance` (consistent under white noise; Hung et al. 2005).
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    a, b = _pair(t1, t2)
    params = (ts, sigma1, sigma2, forgetting)
    if not all(isinstance(p, (int, float, np.floating, np.integer)) for p in params):
        raise ValueError("ts, sigma1, sigma2 and forgetting must be real numbers")
    valid = (
        math.isfinite(ts)
        and ts > 0.0
        and 0.0 < forgetting <= 1.0
        and all(math.isfinite(s) and s >= 0.0 for s in (sigma1, sigma2))
        and (method != "gtls" or (sigma1 > 0.0 and sigma2 > 0.0))
    )
    if not valid:
        return _failed("invalid_argument", method)
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return _failed("non_finite_input", method)
    rows = regression_rows(a, b)
    m = rows.shape[0]
    if m < 3:
        return _failed("insufficient_excitation", method, m)
    if forgetting < 1.0:
        # Exponential forgetting: the newest row has weight 1 (underflow to 0 is harmless).
        weights = float(forgetting) ** np.arange(m - 1, -1, -1, dtype=float)
        weighted = rows * np.sqrt(weights)[:, None]
    else:
        weighted = rows
    gram = weighted[:, :2].T @ weighted[:, :2]
    d = np.diag(gram)
    if not np.all(d > 0.0):
        return _failed("insufficient_excitation", method, m)
    corr = gram[0, 1] / math.sqrt(d[0] * d[1])
    if 1.0 - abs(corr) < _COLLINEARITY_TOL:
        return _failed("insufficient_excitation", method, m)

    if method == "ls":
        theta = np.linalg.lstsq(weighted[:, :2], weighted[:, 2], rcond=None)[0]
    else:
        if method == "tls":
            v = scipy.linalg.svd(weighted, full_matrices=False)[2][-1]
        else:
            scatter = weighted.T @ weighted
            v = scipy.linalg.eigh(scatter, noise_covariance(sigma1, sigma2))[1][:, 0]
        if not abs(v[2]) > np.finfo(float).eps * np.linalg.norm(v):
            return _failed("infeasible", method, m)
        theta = -v[:2] / v[2]
    beta, b2 = (float(x) for x in theta)
    raw = np.array([beta, b2])
    if not (math.isfinite(beta) and math.isfinite(b2)) or not beta > 0.0:
        return _failed("infeasible", method, m, raw)
    b1 = b2 / beta
    if not (0.0 < b1 < 1.0 and 0.0 < b2 < 1.0):
        return _failed("infeasible", method, m, raw)
    return DifferenceResult(
        status="ok",
        beta=beta,
        b1=b1,
        b2=b2,
        tau1=_time_constant(b1, ts),
        tau2=_time_constant(b2, ts),
        theta=raw.copy(),
        method=method,
        rows=m,
        raw_theta=raw,
    )


def exact_inverse(temps: np.ndarray, tau: float, ts: float) -> np.ndarray:
    """Exact inverse of eq. 8: ``out[k-1] = (T(k) - a T(k-1)) / b``; ``out[-1] = nan``."""
    x = np.asarray(temps, dtype=float)
    if x.ndim != 1:
        raise ValueError("exact_inverse: temps must be 1-D")
    if not (math.isfinite(tau) and tau > 0.0 and math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"exact_inverse: tau and ts must be finite and > 0, got {tau}, {ts}")
    a = math.exp(-ts / tau)
    b = -math.expm1(-ts / tau)
    out = np.full(x.shape, np.nan)
    out[:-1] = (x[1:] - a * x[:-1]) / b
    return out


def sensor1_weight(tau1: float, tau2: float) -> float:
    """Inverse-variance weight of sensor 1: the inverse's noise gain is ~ tau/Ts."""
    return tau2**2 / (tau1**2 + tau2**2)


def reconstruct(
    t1: np.ndarray,
    t2: np.ndarray,
    tau1: float,
    tau2: float,
    ts: float,
    which: str = "weighted",
    lowpass_tau: float | None = None,
) -> np.ndarray:
    """Gas temperature ``Tg(k-1)`` at index k-1 from sensor1, sensor2 or their inverse-variance
    weighted combination; optional first-order low-pass ``y(k) = c y(k-1) + (1-c) x(k)``,
    ``c = exp(-Ts/lowpass_tau)`` (None or 0: none), started at its first input.
    The last value is NaN (no later sample)."""
    a, b = _pair(t1, t2)
    if which == "sensor1":
        out = exact_inverse(a, tau1, ts)
    elif which == "sensor2":
        out = exact_inverse(b, tau2, ts)
    elif which == "weighted":
        w = sensor1_weight(tau1, tau2)
        out = w * exact_inverse(a, tau1, ts) + (1.0 - w) * exact_inverse(b, tau2, ts)
    else:
        raise ValueError(f"reconstruct: which must be sensor1, sensor2 or weighted, got {which!r}")
    if lowpass_tau is not None and not (math.isfinite(lowpass_tau) and lowpass_tau >= 0.0):
        raise ValueError(f"reconstruct: lowpass_tau must be finite and >= 0, got {lowpass_tau}")
    if lowpass_tau and out.size > 1:  # None or 0: no low-pass stage (as in the C++ core)
        c = math.exp(-ts / lowpass_tau)
        x = out[:-1]
        out[:-1] = scipy.signal.lfilter([1.0 - c], [1.0, -c], x, zi=[c * x[0]])[0]
    return out
