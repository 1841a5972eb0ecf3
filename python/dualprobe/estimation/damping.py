"""The Levenberg step search shared by the field estimators' damped Gauss-Newton loops
(:mod:`dualprobe.estimation.crossfit`, :mod:`dualprobe.estimation.psi_map`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import TypeVar

__all__ = ["damped_search"]

State = TypeVar("State")


def damped_search(attempt: Callable[[float], tuple[State, float] | None], cost: float,
                  damping: float, tries: int) -> tuple[State | None, float, float]:
    """Try ``attempt(damping)`` (a trial state and its cost, or None when the damped system
    could not be solved) with the damping growing tenfold until the cost falls below ``cost``.
    Returns (the accepted state or None, its cost or ``cost``, the damping last tried)."""
    for _ in range(tries):
        trial = attempt(damping)
        if trial is not None and math.isfinite(trial[1]) and trial[1] < cost:
            return trial[0], trial[1], damping
        damping *= 10.0
    return None, cost, damping
