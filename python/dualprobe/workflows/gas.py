"""The characterisation's gas: the reconstruction with an estimate's time constants (on its
schedule, with that schedule's noise), what it predicts each sensor reads, and the noise levels
those residuals are judged by."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from dualprobe.estimation import PairEstimate
from dualprobe.io import EstimationError
from dualprobe.reconstruction import Reconstruction, reconstruct
from dualprobe.workflows.refusals import in_first_scale

__all__ = ["estimate_gas", "format_taus", "noise_levels", "residuals_of"]


def format_taus(taus: Sequence[Sequence[float]]) -> str:
    """Each sensor's time constants for a message: "(a, b) s and (c) s"."""
    return " and ".join("(" + ", ".join(f"{tau:.5g}" for tau in sensor) + ") s" for sensor in taus)


def estimate_gas(
    t1: np.ndarray, t2: np.ndarray, ts: float, estimate: PairEstimate, mode: str,
    hysteresis: bool, static: tuple[float, float] | None, near: Reconstruction | None = None,
) -> Reconstruction:
    """The reconstruction (``mode``) with ``estimate``'s time constants (heating and cooling
    where ``hysteresis``), on its flow model's schedule with that schedule's noise, sensor 2
    mapped by ``static``; an :class:`EstimationError` where the data do not support it.
    ``near``: the gas of nearby time constants, whose smoother this one starts from."""
    heat = estimate.time_constants_heat
    cool = estimate.time_constants_cool
    hysteretic = hysteresis and heat is not None and cool is not None
    model = estimate.flow_model
    schedule = None if model is None or model.kind == "constant" else 1.0 / model.psi
    # a schedule's error (a tracked one's noise, tracking.split_noise, and the sheathed path's
    # measured bias; a flow column's own noise) is part of the gas's uncertainty: the error
    # over T_g_std (to the bandwidth) had an RMS of 1.7-3.6 without it on separately simulated
    # unsheathed tracked pairs, 0.7-1.2 with it (README); sheathed, see field.py
    log_std = model.schedule_error if model is not None else 0.0
    try:
        result = reconstruct(
            t1, t2, ts,
            heat[0] if hysteretic and heat is not None else estimate.time_constants[0],
            heat[1] if hysteretic and heat is not None else estimate.time_constants[1],
            mode=mode, noise_std=estimate.noise_std,
            taus1_cool=cool[0] if hysteretic and cool is not None else None,
            taus2_cool=cool[1] if hysteretic and cool is not None else None,
            relative_static=static, schedule=schedule,
            schedule_log_std=log_std, near=None if near is None else near.fit,
        )
    except ValueError as exc:
        # the inputs were validated above: what is left is the data not supporting the
        # reconstruction with these time constants (exit 3, not 2)
        raise EstimationError(
            f"reconstruction ({mode}) with time constants "
            f"{format_taus(estimate.time_constants)} failed: {exc}"
        ) from None
    if result.gas.shape != t1.shape:
        raise EstimationError(
            f"reconstruction returned {result.gas.shape[0] if result.gas.ndim else 0} samples "
            f"for {t1.size} inputs"
        )
    return result


def residuals_of(
    result: Reconstruction, t1: np.ndarray, t2: np.ndarray, static: tuple[float, float] | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """Each sensor's reading minus the smoother model's prediction (sensor 2 in sensor 1's
    calibration when the affine static model holds)."""
    fit = result.fit
    if fit is None:
        return None
    outputs = np.argmax(fit.model.h, axis=1)
    predicted = fit.states[:, outputs] + fit.offset
    return t1 - predicted[:, 0], in_first_scale((t1, t2), static, 1) - predicted[:, 1]


def noise_levels(estimate: PairEstimate, static: tuple[float, float] | None
                  ) -> tuple[float, float]:
    """The noise levels the residuals are judged by: those the estimation used, sensor 2's
    in sensor 1's calibration under the affine static model."""
    used = estimate.details.get("noise_std_used", estimate.noise_std)
    levels = (float(used[0]), float(used[1]))  # type: ignore[index]
    return levels if static is None else (levels[0], abs(static[0]) * levels[1])
