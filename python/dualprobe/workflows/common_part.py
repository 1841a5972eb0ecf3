"""The common part of two near-equal second stages (sheaths) as an uncertainty of the gas.

Two near-equal stages nearly cancel from the pair's cross-relation; with the time constants
following the flow, only the flow law's shape fixes their common part, and a law right to
0.3 % in log can size 0.42 / 0.45 s sheaths as 1.78 / 1.86 s while the model explains both
signals (misfit 1.13, the flow halves 2.9 standard deviations apart) and the gas comes out
8.3x the oracle's error with ``T_g_std`` covering a sixth of it. Their standard uncertainties
(the jackknife's, 22 % there; 3-7 % where such sheaths are resolved) say how far the data let
that part move: :func:`common_part_doubt` reconstructs with both stages one standard
uncertainty shorter (towards the lag the pair cannot see, never into a faster inverse) and
takes the gas's move as part of its uncertainty (:mod:`dualprobe.workflows.undetermined`).
Measured (separate generator, 10 Hz, 20 min, the mass flow): the move over ``T_g_std`` in the
worst 30 s 5.4 on that pair, 0.59-0.84 on four resolved near-equal pairs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from dualprobe.estimation import PairEstimate
from dualprobe.io import EstimationError
from dualprobe.workflows.checks import shared_time_constant
from dualprobe.workflows.undetermined import Undetermined, undetermined

__all__ = ["common_part_doubt"]


def common_part_doubt(estimate: PairEstimate, gas: np.ndarray, gas_std: np.ndarray, ts: float,
                      reconstruct: Callable[[PairEstimate], np.ndarray]) -> Undetermined | None:
    """The gas's move with both near-equal second stages (``SHARED_FACTOR``) one standard
    uncertainty shorter, judged against ``gas_std``; None where the estimate has no such pair,
    no uncertainties, or the moved model gives no gas."""
    taus = estimate.time_constants
    conf = estimate.confidence
    if (estimate.order != 2 or conf is None or any(len(t) != 2 for t in taus)
            or shared_time_constant(taus) is None):
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
