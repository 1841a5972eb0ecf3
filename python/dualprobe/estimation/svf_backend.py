"""The SVF computations the orchestration (:mod:`dualprobe.estimation.svf`) calls: the only
module of the estimation that touches an SVF implementation.

Today that is the NumPy reference :mod:`dualprobe.reference.svf` (design.md 1.4: filter,
regression columns, projected scatter, noise covariance, GTLS); issue 12 replaces it with the
compiled core's ``SvfEstimator`` here, behind the same functions, so that the reference is a
check again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualprobe.reference import svf  # issue 12: replaced by the compiled core next (lead)

STATIC_MODELS = svf.STATIC_MODELS
SvfResult = svf.SvfResult

__all__ = [
    "STATIC_MODELS",
    "SubModelFit",
    "SvfResult",
    "effective_samples",
    "estimate_or_none",
    "fast_time_constant",
    "sensor_order_fits",
]


def fast_time_constant(res: SvfResult | None) -> float:
    """Largest time constant of the faster sensor (NaN when the fit is unusable)."""
    if res is None or res.status != "ok":
        return float("nan")
    fast = min(res.time_constants[0][0], res.time_constants[1][0])
    return fast if math.isfinite(fast) and fast > 0.0 else float("nan")


def estimate_or_none(
    t1: np.ndarray, t2: np.ndarray, ts: float, **kwargs: Any
) -> SvfResult | None:
    """One SVF fit (keyword arguments of :func:`dualprobe.reference.svf.estimate`); None when
    the data give no usable scatter."""
    try:
        return svf.estimate(t1, t2, ts, **kwargs)
    except (np.linalg.LinAlgError, ValueError):
        return None


def effective_samples(res: SvfResult, ts: float, sigma: tuple[float, float],
                       static: str) -> float:
    """Effective independent rows: the smaller of the noise model's and the residual's."""
    disc = svf.discretise_filter(res.tf, ts, res.order + 1)
    theta = svf.merged_theta(res.theta) if "heat" in res.extra else res.theta
    model = svf.effective_samples(disc, theta, res.order, sigma[0], sigma[1], res.rows, static)
    residual = float(res.extra["residual_effective_samples"])  # type: ignore[arg-type]
    return min(model, residual) if math.isfinite(residual) else model


@dataclass(frozen=True)
class SubModelFit:
    """GTLS fit of the order-2 relation with some d_i fixed at zero."""

    theta: np.ndarray  # full layout, zeros where d_i is dropped
    eigenvalues: np.ndarray
    polynomials: tuple[tuple[float, ...], tuple[float, ...]]
    time_constants: tuple[tuple[float, ...], tuple[float, ...]]
    feasible: bool

    @property
    def mu(self) -> float:
        return float(self.eigenvalues[0])


def sensor_order_fits(
    t1: np.ndarray, t2: np.ndarray, ts: float, tf: float, sigma: tuple[float, float],
    static: str,
) -> dict[tuple[int, int], SubModelFit]:
    """Order-2 SVF scatter (as :func:`dualprobe.reference.svf.estimate`) solved with the
    sensors' orders (2, 2), (1, 2), (2, 1) and (1, 1): the d_i columns (1 and 3 of the
    layout) are dropped from the scatter and the noise covariance."""
    disc = svf.discretise_filter(tf, ts, 3)
    cols = svf.regression_columns(t1, t2, disc, 2, None, static)
    scatter = svf.projected_scatter(cols, disc, 0, static == "affine")
    cov = svf.noise_covariance(disc, 2, sigma[0], sigma[1], static) * cols.shape[1]
    size = scatter.shape[0]
    out: dict[tuple[int, int], SubModelFit] = {}
    for orders in ((2, 2), (1, 2), (2, 1), (1, 1)):
        keep = [i for i in range(size) if not (i == 1 and orders[0] == 1)
                and not (i == 3 and orders[1] == 1)]
        sub, mu, _ = svf.solve_gtls(scatter[np.ix_(keep, keep)], cov[np.ix_(keep, keep)])
        theta = np.zeros(size)
        theta[keep] = sub
        gain = float(theta[4]) if static == "affine" else 1.0
        polys = []
        taus = []
        for i in range(2):
            c = float(theta[2 * i]) * tf / gain ** i
            d = float(theta[2 * i + 1]) * tf**2 / gain ** i
            if orders[i] == 1:
                polys.append((c,))
                taus.append((c,) if math.isfinite(c) and c > 0.0 else (float("nan"),))
            else:
                polys.append((c, d))
                taus.append(svf.polynomial_time_constants((c, d)))
        feasible = gain > 0.0 and all(math.isfinite(t) and t > 0.0 for ts_ in taus for t in ts_)
        out[orders] = SubModelFit(theta, mu, (polys[0], polys[1]), (taus[0], taus[1]), feasible)
    return out
