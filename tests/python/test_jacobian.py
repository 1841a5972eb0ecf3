"""dualprobe.models.jacobian: the central-difference Jacobian identify's uncertainties rest on,
against the analytic one."""

from __future__ import annotations

import numpy as np

from dualprobe.models.jacobian import central_jacobian

T = np.linspace(0.0, 10.0, 50)


def _response(theta: np.ndarray) -> np.ndarray:
    gain, tau = theta
    return gain * (1.0 - np.exp(-T / tau))


def _analytic(theta: np.ndarray) -> np.ndarray:
    gain, tau = theta
    e = np.exp(-T / tau)
    return np.column_stack([1.0 - e, -gain * T / tau**2 * e])


def test_central_points_match_the_analytic_jacobian() -> None:
    theta = np.array([80.0, 2.5])
    step = 1e-5 * theta
    jac = central_jacobian(_response, theta, theta + step, theta - step)
    # central differences: truncation ~ step^2 f''' / 6 (2.5e-5 s on a 2.5 s time constant:
    # ~1e-9 relative) and rounding ~ eps |f| / step (1e-16 * 80 / 2.5e-5: ~3e-10 K/s) of
    # columns of order 1-30: 1e-6 relative leaves both orders of magnitude of margin
    np.testing.assert_allclose(jac, _analytic(theta), rtol=1e-6, atol=1e-6)


def test_a_one_sided_column_is_a_forward_difference_over_the_points_distance() -> None:
    theta = np.array([80.0, 2.5])
    hi = theta * (1.0 + 1e-6)
    lo = theta.copy()  # one-sided in both (as at a bound)
    jac = central_jacobian(_response, theta, hi, lo)
    # forward differences: truncation ~ step f'' / 2, ~1e-6 relative for a step of 1e-6
    np.testing.assert_allclose(jac, _analytic(theta), rtol=1e-5, atol=1e-5)
    # the divisor is hi - lo, the points' distance: each column is exactly that quotient
    for j in range(2):
        up = theta.copy()
        up[j] = hi[j]
        np.testing.assert_array_equal(jac[:, j], (_response(up) - _response(theta))
                                      / (hi[j] - lo[j]))
