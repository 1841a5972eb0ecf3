"""Standard uncertainties of the dual-sensor estimates: a block jackknife over the record.

The cross-relation's moments are sums over rows, so the record is cut into B consecutive blocks
(each much longer than the filter's memory, so that the blocks' errors are nearly independent)
and the estimate is repeated B times without one block (delete-one-block jackknife on the
moments: no data pass is repeated). The jackknife variance ``(B - 1)/B sum (p_b - mean)^2``
carries everything that varies between stretches of the record: the errors-in-variables
structure of both noisy signals, coloured noise, quantisation, and model error that is not the
same everywhere. Parameters that are re-optimised inside the estimate (the flow exponent) are
re-optimised in every replicate.

The method's own setting, the filter time constant tf, is tested the same way: the estimate at
tf/2 and 2 tf minus the estimate at tf has a jackknife standard deviation too; a difference
beyond ``SETTINGS_SIGNIFICANCE`` of them is a systematic dependence on the setting (model error
that the filter weights differently), and half of it enters the uncertainty in quadrature (and
the value is flagged as moving with the settings). A difference within the noise adds nothing:
it is the same noise the jackknife already counted.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualprobe.estimation.orders import sensor_order_fits

__all__ = [
    "BLOCKS",
    "MIN_BLOCKS",
    "SETTINGS_SIGNIFICANCE",
    "Jackknife",
    "block_length",
    "filter_memory",
    "jackknife",
    "settings_sensitivity",
]

BLOCKS = 32  # target number of blocks: variance estimate with ~31 degrees of freedom
MIN_BLOCKS = 6  # below this the variance estimate is too uncertain to report
MEMORY_MULTIPLE = 2.0  # a block spans at least this many filter memories
SETTINGS_SIGNIFICANCE = 3.0  # |difference| / its standard deviation that counts as systematic


def block_length(samples: int, memory_samples: float) -> int:
    """Rows per block: ``samples / BLOCKS`` but at least ``MEMORY_MULTIPLE`` filter memories
    (so that neighbouring blocks' errors hardly correlate)."""
    floor = math.ceil(MEMORY_MULTIPLE * memory_samples)
    return max(math.ceil(samples / BLOCKS), floor, 1)


@dataclass(frozen=True)
class Jackknife:
    """Jackknife of a parameter vector: the full estimate, the standard deviations, the
    replicates (B, P) (NaN rows: failed replicates) and the number of blocks."""

    estimate: np.ndarray
    std: np.ndarray
    replicates: np.ndarray

    @property
    def blocks(self) -> int:
        return int(self.replicates.shape[0])

    @property
    def failed(self) -> int:
        return int(np.count_nonzero(~np.all(np.isfinite(self.replicates), axis=1)))


def jackknife(
    blocks: np.ndarray, estimate: Callable[[np.ndarray], np.ndarray],
    full: np.ndarray | None = None,
) -> Jackknife:
    """Delete-one-block jackknife of ``estimate(moments) -> parameters`` over block moment
    vectors ``blocks`` (B, L). Failed replicates (non-finite parameters) are left out of the
    variance and counted; when half or more fail the standard deviations are infinite."""
    total = np.sum(blocks, axis=0)
    value = estimate(total) if full is None else full
    reps = np.array([estimate(total - block) for block in blocks], dtype=float)
    ok = np.all(np.isfinite(reps), axis=1)
    count = int(np.count_nonzero(ok))
    if count < max(MIN_BLOCKS, blocks.shape[0] // 2):
        std = np.full(np.shape(value), math.inf)
    else:
        good = reps[ok]
        std = np.sqrt((count - 1) / count * np.sum((good - good.mean(axis=0)) ** 2, axis=0))
    return Jackknife(np.asarray(value, dtype=float), std, reps)


@dataclass(frozen=True)
class Sensitivity:
    """Dependence of the estimate on a setting: the largest significant difference per
    parameter (0 where within the noise) and the significance of each variant."""

    systematic: np.ndarray
    significance: np.ndarray  # (variants, P): |difference| / its jackknife std


def settings_sensitivity(
    base: Jackknife, variants: Sequence[Jackknife]
) -> Sensitivity:
    """Systematic differences between the base estimate and variants computed on the same
    blocks (their replicates pair up block by block)."""
    systematic = np.zeros_like(base.estimate)
    significance = []
    for variant in variants:
        diff = variant.estimate - base.estimate
        reps = variant.replicates - base.replicates
        ok = np.all(np.isfinite(reps), axis=1)
        count = int(np.count_nonzero(ok))
        if count >= MIN_BLOCKS:
            good = reps[ok]
            sd = np.sqrt((count - 1) / count * np.sum((good - good.mean(axis=0)) ** 2, axis=0))
        else:
            sd = np.full(diff.shape, math.inf)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where(sd > 0.0, np.abs(diff) / sd, np.where(diff != 0.0, math.inf, 0.0))
        significance.append(z)
        systematic = np.where(z > SETTINGS_SIGNIFICANCE,
                              np.maximum(systematic, 0.5 * np.abs(diff)), systematic)
    return Sensitivity(systematic, np.array(significance))


# --------------------------------------------------------------------------------------------
# The SVF estimate's parameters and their jackknife
# --------------------------------------------------------------------------------------------

def filter_memory(order: int, tf: float) -> float:
    """Seconds holding 99 % of the SVF filter's impulse response energy,
    ~(m + 3 sqrt(m)) tf for the m = order + 1 fold lag t^(m-1) exp(-t/tf)."""
    m = order + 1
    return (m + 3.0 * math.sqrt(m)) * tf


@dataclass(frozen=True)
class Layout:
    """Which parameters a fit reports, in the order of :func:`parameters`: each sensor's
    time constants (its order), heating/cooling (hysteresis), gain ratio and offset (affine)."""

    orders: tuple[int, int]
    hysteresis: bool
    affine: bool

    def names(self) -> list[str]:
        out = [f"tau{i + 1}_{j}" for i in range(2) for j in range(self.orders[i])]
        if self.hysteresis:
            out += ["tau1_heat", "tau1_cool", "tau2_heat", "tau2_cool"]
        if self.affine:
            out += ["gain_ratio", "offset"]
        return out


def parameters(fit: Any, layout: Layout) -> np.ndarray:
    """The parameter vector of a fit (NaN where it is infeasible), using the sub-model of the
    layout's sensor orders when they are not both the fit's own order."""
    taus = fit.time_constants
    feasible = fit.status == "ok"
    if fit.order == 2 and layout.orders != (2, 2):
        # the sub-model's own feasibility: the full order-2 solution may be infeasible (a
        # complex pair on the sensor the sub-model fits at order 1) while the sub-model the
        # estimate reports is not (every replicate was NaN so, and the uncertainty infinite)
        try:
            sub = sensor_order_fits(fit)[layout.orders]
            taus = sub.time_constants
            feasible = sub.feasible and fit.status in ("ok", "infeasible")
        except (np.linalg.LinAlgError, ValueError):
            taus = ((math.nan,) * layout.orders[0], (math.nan,) * layout.orders[1])
            feasible = False
    values = [float(t) for i in range(2) for t in taus[i][: layout.orders[i]]]
    if layout.hysteresis:
        heat, cool = fit.heat, fit.cool
        values += [heat[0][0], cool[0][0], heat[1][0], cool[1][0]] if heat and cool else \
            [math.nan] * 4
    if layout.affine:
        values += [fit.gain_ratio, fit.offset]
    out = np.array(values, dtype=float)
    return out if feasible else np.full(out.size, math.nan)
