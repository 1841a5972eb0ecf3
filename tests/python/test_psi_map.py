"""The joint MAP's Jacobian in log psi (dualprobe.estimation.psi_map._Problem.system) is
analytic (the chain's step depends on h / tau only); here it is checked against central
differences of the residuals themselves, knot by knot, for chains of one and two stages."""

from __future__ import annotations

import numpy as np
import pytest

from dualprobe.estimation import psi_map


@pytest.mark.parametrize("stages", [([0.7, 3.0], [6.0]), ([2.0], [0.4, 5.0]), ([1.5], [4.0])])
def test_the_knots_jacobian_is_the_residuals_derivative(
        stages: tuple[list[float], list[float]]) -> None:
    rng = np.random.default_rng(5)
    rows, spacing = 240, 10
    # uneven steps (a jittering logger clock), a moving gas, psi far from 1 at some knots
    t = np.cumsum(rng.uniform(0.07, 0.13, rows))
    gas = 600.0 + np.cumsum(rng.normal(0.0, 0.5, rows))
    y1 = gas + rng.normal(0.0, 0.05, rows)
    y2 = gas + rng.normal(0.0, 0.05, rows)
    problem = psi_map._Problem(t, (y1, y2), (np.array(stages[0]), np.array(stages[1])),
                               (0.05, 0.05), 1.0, spacing, 0.05)
    z = rng.normal(0.0, 0.4, problem.knots)
    static = np.array([1.01, 0.2])
    # states that nearly satisfy the dynamics (so the residuals are of the noise's size)
    # plus a perturbation (the Jacobian holds for any states)
    x, _ = problem.states_for(z, static, np.zeros(rows * problem.nx))
    x = x + rng.normal(0.0, 0.3, x.size)
    _, _, drive, _ = problem.system(x, z, static)
    analytic = drive.toarray()
    delta = 1e-5  # log psi: truncation ~delta^2 (1e-10 relative), rounding ~1e-16 / delta
    numeric = np.empty_like(analytic)
    for i in range(problem.knots):
        step = np.zeros(problem.knots)
        step[i] = delta
        up = problem.system(x, z + step, static)[0]
        down = problem.system(x, z - step, static)[0]
        numeric[:, i] = (up - down) / (2.0 * delta)
    scale = np.max(np.abs(analytic))
    assert scale > 0.0
    # measured: agreement to ~1e-9 of the largest entry (the differences' rounding: residuals
    # weighted 1 / 1e-4 K at 600 K, 1e-16 of that over delta); 1e-6 leaves room for other
    # machines' rounding and would still catch any wrong term (those are O(1) relative)
    np.testing.assert_allclose(analytic, numeric, rtol=0.0, atol=1e-6 * scale)
