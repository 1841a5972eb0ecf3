"""The exact state-space model of a sensor pair and its causal filter, as the reconstruction uses
them: the only module of the reconstruction that touches a Kalman implementation.

Today :func:`pair_model` (Van Loan discretisation of the gas as a random walk or integrated random
walk and each sensor a chain of first-order stages), :func:`kalman_filter` (causal, with GLR jump
detection) and the model-error floors come from the NumPy reference
:mod:`dualprobe.reference.kalman`; issue 12 replaces them with the compiled core's
``KalmanReconstructor`` here, so that the reference is a check again.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from dualprobe.reference.kalman import (  # issue 12: replaced by the compiled core next (lead)
    FLOOR_DYN,
    FLOOR_REL,
    GAS_MODELS,
    PairModel,
    kalman_filter,
    pair_model,
)

__all__ = [
    "GAS_MODELS",
    "PairModel",
    "continuous_matrix",
    "kalman_filter",
    "pair_model",
    "process_floor",
]


def process_floor(model: PairModel, sigma: Sequence[float] | np.ndarray, q: float) -> np.ndarray:
    """The smoother's model-error floor on the sensor stages: :meth:`PairModel.floor` with the
    within-interval share of a stage ``Ts/tau`` replaced by the exact fraction of a gas move
    that reaches it within one interval, ``1 - exp(-Ts/tau)`` (the same for tau >> Ts; for a
    stage faster than Ts the floor saturates at the gas step's own variance / 12 instead of
    growing as (Ts/tau)^2 and cutting the sensor off from the gas)."""
    taus = np.array(model.taus_heat[0] + model.taus_heat[1])
    gas_step = q * float(model.q_unit[0, 0, 0])
    diag = np.zeros(model.n)
    diag[model.stage_state] = (
        FLOOR_REL * np.square(np.asarray(sigma, dtype=float))[model.stage_sensor]
        + FLOOR_DYN * gas_step * (-np.expm1(-model.ts / taus)) ** 2 / 12.0
    )
    return np.diag(diag)


def continuous_matrix(model: PairModel) -> np.ndarray:
    """F of the continuous-time model (heating time constants), as in
    :mod:`dualprobe.reference.kalman` section 1."""
    n = model.n
    f = np.zeros((n, n))
    if model.gas == "irw":
        f[0, 1] = 1.0
    taus = np.array(model.taus_heat[0] + model.taus_heat[1])
    f[model.stage_state, model.stage_input] += 1.0 / taus
    f[model.stage_state, model.stage_state] -= 1.0 / taus
    return f
