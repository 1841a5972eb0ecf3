"""The common part of two second stages (sheaths) as an uncertainty of the gas.

A lag common to both sensors cancels from the pair's cross-relation, so the part their second
stages share is fixed only loosely; with the time constants following the flow, only the flow
law's shape fixes it. Two near-equal stages nearly cancel: a law right to 0.3 % in log sized
0.42 / 0.45 s sheaths as 1.78 / 1.86 s while the model explained both signals (misfit 1.13,
the flow halves 2.9 standard deviations apart) and the gas came out 8.3x the oracle's error
with ``T_g_std`` covering a sixth of it. Stages that are not alike take up such a part too
where the sheaths follow the flow otherwise than the elements (0.54 / 0.61 s sheaths with
exponents 0.44 / 0.52 on 1.54 / 3.88 s elements with 0.47, 2 Hz, the flow: stages of 4.0 +
1.4 s and 5.0 + 3.1 s, a common lag of 3.7 s where the pair's is 0.6 s, misfit 0.98, the gas
21.8 K off where the raw fast sensor is 13 K, called adequate). Their standard uncertainties
(the jackknife's, 22 % and 18-24 % there; 3-7 % where sheaths are resolved) say how far the
data let that part move: :func:`common_part_doubt` reconstructs with both stages one standard
uncertainty shorter (towards the lag the pair cannot see, never into a faster inverse) and
takes the gas's move as part of its uncertainty (:mod:`dualprobe.workflows.undetermined`).
Measured (separate generator, 10 Hz, 20 min, the mass flow): the move over ``T_g_std`` in the
worst 30 s 5.4 on the first pair, 0.59-0.84 on four resolved near-equal pairs; no doubt on six
resolved unlike pairs at 5-25 Hz (0.94-1.32x the oracle), whose ``T_g_std`` grew by 0-8 %.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from dualprobe.estimation import PairEstimate
from dualprobe.io import EstimationError
from dualprobe.workflows.undetermined import WINDOW, Undetermined, undetermined

__all__ = ["common_part_doubt", "fallback_reason"]


def common_part_doubt(estimate: PairEstimate, gas: np.ndarray, gas_std: np.ndarray, ts: float,
                      reconstruct: Callable[[PairEstimate], np.ndarray]) -> Undetermined | None:
    """The gas's move with both second stages one standard uncertainty shorter, judged
    against ``gas_std``; None where the estimate has no second stage on each sensor, no
    uncertainties, or the moved model gives no gas."""
    taus = estimate.time_constants
    conf = estimate.confidence
    if not estimate.stage_on_each or conf is None:
        return None
    stds = [conf.std.get(f"tau{i + 1}_1", np.nan) for i in (0, 1)]
    if not all(np.isfinite(std) and std > 0.0 for std in stds):
        return None
    # a stage moved below zero is no stage: kept at a tenth of itself (an order-2 model still)
    shorter = tuple((t[0], max(t[1] - std, 0.1 * t[1])) for t, std in zip(taus, stds,
                                                                           strict=True))
    try:
        moved = reconstruct(replace(estimate, time_constants=shorter))
    except EstimationError:
        return None
    return undetermined(gas, moved, gas_std, ts, cause="common part")


def fallback_reason(doubt: Undetermined) -> str:
    """Why a second-order fit whose common part is doubted (``doubt``) gives way to first order
    where the order is chosen by evidence. Measured (the doubted pairs above, the flow given):
    the gas 9.95 -> 3.76 K RMS off (0.42 / 0.45 s sheaths sized 1.78 / 1.86 s; the oracle 1.2
    K) and 21.8 -> 5.4 K (sheaths that follow the flow otherwise than the elements; the raw fast
    sensor 13 K); a resolved pair is not doubted (the move 0.59-0.84 of ``T_g_std``)."""
    return (f"the second stages' common part is not determined: one standard uncertainty of "
            f"it moved the gas by {doubt.kelvin:.3g} K RMS over {WINDOW:g} s from t = "
            f"{doubt.start:.0f} s, {doubt.ratio:.2g} times its stated uncertainty (a lag "
            "common to both sensors cancels from their cross-relation; alike sheaths, or "
            "sheaths that follow the flow otherwise than the elements)")
