"""Which order each sensor of an order-2 SVF fit needs: the sub-models with a sensor's
second-order coefficient dropped, solved on the same projected scatter."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualprobe.estimation import engine
from dualprobe.estimation.engine import Fit

__all__ = ["COMPLEX_NOTE", "SubModelFit", "resolved", "sensor_order_fits"]

COMPLEX_NOTE = "complex pole pair: reported as a double pole"


def resolved(taus: tuple[float, ...], poly: tuple[float, ...]) -> tuple[tuple[float, ...], str]:
    """Time constants of one sensor's polynomial, with a note when only part is resolved."""
    if all(math.isfinite(t) and t > 0.0 for t in taus):
        return taus, ""
    c = poly[0]
    if len(poly) == 2 and math.isfinite(c) and c > 0.0:
        d = poly[1]
        if d <= 0.0:
            return (c,), "second time constant below resolution (first-order response)"
        if c * c < 4.0 * d:
            return (0.5 * c, 0.5 * c), COMPLEX_NOTE
    return taus, "no positive real time constants"


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


def sensor_order_fits(res: Fit, which: tuple[tuple[int, int], ...] = ((2, 2), (1, 2), (2, 1),
                                                                      (1, 1)),
                      ) -> dict[tuple[int, int], SubModelFit]:
    """The order-2 fit's projected scatter and noise covariance solved with the sensors'
    orders ``which`` (all four by default): the d_i columns (1 and 3 of the layout) are
    dropped from both."""
    scatter, cov, tf = res.scatter, res.noise, res.tf
    size = scatter.shape[0]
    out: dict[tuple[int, int], SubModelFit] = {}
    for orders in which:
        keep = [i for i in range(size) if not (i == 1 and orders[0] == 1)
                and not (i == 3 and orders[1] == 1)]
        sub, mu = engine.solve_gtls(scatter[np.ix_(keep, keep)], cov[np.ix_(keep, keep)])
        theta = np.zeros(size)
        theta[keep] = sub
        gain = float(theta[4]) if res.static == "affine" else 1.0
        polys = []
        taus = []
        for i in range(2):
            c = float(theta[2 * i]) * tf / gain ** i
            d = float(theta[2 * i + 1]) * tf**2 / gain ** i
            if orders[i] == 1:
                polys.append((c,))
                taus.append(engine.polynomial_time_constants((c,)))
            else:
                polys.append((c, d))
                taus.append(engine.polynomial_time_constants((c, d)))
        feasible = gain > 0.0 and all(math.isfinite(t) and t > 0.0 for ts_ in taus for t in ts_)
        out[orders] = SubModelFit(theta, mu, (polys[0], polys[1]), (taus[0], taus[1]), feasible)
    return out
