"""Where the data do not determine the gas: a tracked schedule and its rival
(:mod:`dualprobe.estimation.rival`) explain both signals as well, yet their gases differ.

Any estimate of the gas then lies at least half their distance from one of them, whichever is
true, so that half-difference is part of the gas's uncertainty (added to ``T_g_std`` in
quadrature), and where it exceeds the uncertainty stated without it over a stretch of the
record (its RMS over the posterior's RMS in a ``WINDOW``-long stretch above ``LIMIT``: the rival's
gas beyond three of the posterior's standard deviations there) the model check doubts the
result. The same judges the common part of two second stages
(:mod:`dualprobe.workflows.common_part`), whose rival is the gas with that part one standard
uncertainty shorter: a one-sigma move, so all of its distance is uncertainty.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

__all__ = ["LIMIT", "WINDOW", "Cause", "Undetermined", "undetermined"]

# "schedule": a rival schedule's gas (spread: half the distance); "common part": the gas with
# both second stages one standard uncertainty shorter (spread: all of it); "order": the
# second-order gas that first order replaced for its undetermined common part (half)
Cause = Literal["schedule", "common part", "order"]

# s: a manoeuvre's length on a drive cycle (accelerations and cruises of 4-80 s), so that one
# stretch the data do not determine is not averaged away over a 20-min record, while the rows'
# noise in the two reconstructions averages out within it
WINDOW = 30.0
# the half-difference's RMS over the posterior's: above 1.5 the rival's gas lies beyond three
# of the posterior's standard deviations there. Measured (README): 0.34-1.02 on 13 tracked
# first-order pairs at 1.16-1.53x the oracle (and on three near-equal sheaths, whose common
# lag both schedules share), 1.2 on one at 1.90x; 2.4 and 2.7 where the schedule was 15-25 %
# off (3.0x, 5.3x). At 1 (two deviations) an unsheathed pair at 1.23x was doubted (1.02): a
# second estimator with other priors scatters to the posterior's two-sigma edge even where
# the data determine psi.
LIMIT = 1.5


@dataclass(frozen=True)
class Undetermined:
    """``spread`` (N,) half the distance between the two gases per row (K); ``ratio`` the
    worst window's RMS spread over its RMS posterior standard deviation, ``kelvin`` its RMS
    spread, ``start`` its first row's time from the record's start (s)."""

    spread: np.ndarray
    ratio: float
    kelvin: float
    start: float
    cause: Cause = "schedule"

    @property
    def doubtful(self) -> bool:
        return self.ratio > LIMIT

    def reason(self) -> str:
        if self.cause == "common part":
            return (
                "the second stages' common part is not determined well enough for this gas: "
                "a lag common to both sensors cancels from their cross-relation, so the data "
                "fix the part their second stages share only loosely, and one standard "
                f"uncertainty of it moves the gas by {self.kelvin:.3g} K RMS over {WINDOW:g} s "
                f"from t = {self.start:.0f} s, {self.ratio:.2g} times the uncertainty stated "
                "without it (T_g_std includes it); the stages may be sized several times too "
                "long (alike sheaths, or sheaths that follow the flow otherwise than the "
                "elements): compare with --order 1")
        if self.cause == "order":
            return (
                "first order was taken where the second-order fit's common part is not "
                f"determined (note: order chosen by evidence): that fit's gas lies "
                f"{2.0 * self.kelvin:.3g} K RMS from this one over {WINDOW:g} s from t = "
                f"{self.start:.0f} s, {self.ratio:.2g} times the uncertainty stated without "
                "it, and the data do not say which is nearer (T_g_std includes half that "
                "distance); the sheaths' datasheet tells how long a lag both sensors share")
        return (
            f"the tracked time constants are not determined by these data: another schedule "
            f"explains both signals as well and gives a gas {2.0 * self.kelvin:.3g} K RMS away "
            f"from this one over {WINDOW:g} s from t = {self.start:.0f} s, {self.ratio:.2g} "
            "times the uncertainty stated without it (the two readings nearly coincide while "
            "the gas moves, so a change of the time constants and a change of the gas explain "
            "them alike); T_g_std includes half that distance. Give the exhaust flow (--flow) "
            "to determine them")


def undetermined(gas: np.ndarray, rival: np.ndarray, std: np.ndarray, ts: float,
                 cause: Cause = "schedule") -> Undetermined | None:
    """The spread between ``gas`` and the ``rival``'s gas, judged against ``std`` (the
    posterior's standard deviation without it), in windows of ``WINDOW`` (the whole record
    when shorter); None where either gas has no finite row. For a ``cause`` of "common part"
    the rival is the gas one standard uncertainty away, so the spread is all of the distance."""
    share = 1.0 if cause == "common part" else 0.5
    spread = share * np.abs(np.asarray(gas, float) - np.asarray(rival, float))
    valid = np.isfinite(spread) & np.isfinite(std) & (std > 0.0)
    if not np.any(valid):
        return None
    rows = max(1, min(spread.size, round(WINDOW / ts)))
    worst = (-1.0, 0.0, 0)
    for start in range(0, spread.size - rows + 1, max(1, rows // 2)):
        part = valid[start:start + rows]
        if np.count_nonzero(part) < rows // 2:
            continue
        kelvin = float(np.sqrt(np.mean(spread[start:start + rows][part] ** 2)))
        scale = float(np.sqrt(np.mean(std[start:start + rows][part] ** 2)))
        if kelvin / scale > worst[0]:
            worst = (kelvin / scale, kelvin, start)
    if worst[0] < 0.0:
        return None
    return Undetermined(np.where(np.isfinite(spread), spread, 0.0), worst[0], worst[1],
                        worst[2] * ts, cause)
