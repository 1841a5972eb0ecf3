"""The central-difference Jacobian of a model's output: the one behind the standard
uncertainties of ``identify``'s fits (a transfer function to a reference, a plunge's step)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["central_jacobian"]


def central_jacobian(output: Callable[[np.ndarray], np.ndarray], theta: np.ndarray,
                     hi: np.ndarray, lo: np.ndarray) -> np.ndarray:
    """Column j: ``(output(theta, theta_j = hi_j) - output(theta, theta_j = lo_j)) /
    (hi_j - lo_j)``. The caller places the points (a relative step for a time constant,
    which an absolute one can drive through zero; one-sided at a bound): the divisor is the
    points' actual distance, not the step asked for, so rounding of ``theta +- step`` does
    not enter."""
    columns = []
    for j in range(theta.size):
        up, down = theta.copy(), theta.copy()
        up[j], down[j] = hi[j], lo[j]
        columns.append((output(up) - output(down)) / (hi[j] - lo[j]))
    return np.column_stack(columns)
