"""The flow column's delay (diagnose): where the sensor's time constant follows the flow, an
ECU's mass flow (measured at the intake, or filtered) reaches the sensor a few tenths of a
second later. Given as logged, the flow law misfits at every load change: measured (drive
cycle, 10 Hz, tau 4 s, m 0.5, a fast reference) 0.3 s late left 2.8 times the noise floor,
"partly explained"; 1 s late was read as a level dependence with an exponent of 3 plus a flow
exponent of 0.14, 7.3 times the floor. :func:`locate_flow_delay` finds the delay d (either
sign) that the first-order flow law fits best (:func:`dualprobe.models.shift.delay_profile`, as
characterise searches it), and keeps it when it beats no delay by a likelihood ratio (the
evidence rule of every other effect)."""

from __future__ import annotations

import functools
import math

import numpy as np

from dualprobe.diagnose.fit import ModelFit, Problem, fit_model
from dualprobe.diagnose.model import context_for
from dualprobe.diagnose.residuals import effective_size
from dualprobe.diagnose.starts import candidate_starts
from dualprobe.models.shift import delay_profile, later

__all__ = ["locate_flow_delay"]

_EFFECTS = ("flow_dependence",)


def locate_flow_delay(problem: Problem, baseline: ModelFit, flow: np.ndarray,
                      threshold: float) -> float:
    """The flow's delay in s (0 when no delay fits significantly better than none):
    ``problem`` the diagnosis (its context's flow reference is kept), ``baseline`` the
    first-order fit the flow law starts from, ``threshold`` the chi2(1) level a likelihood
    ratio must pass."""
    ts = problem.ts
    reference = problem.context.conditions.flow_reference

    @functools.cache
    def fit_at(delay: float) -> ModelFit:
        trial = Problem(problem.u, problem.y, ts,
                        context_for(problem.u, ts, later(flow, delay, ts),
                                    flow_reference=reference),
                        problem.constants)
        trial.fixed = dict(problem.fixed)
        return fit_model(trial, _EFFECTS, candidate_starts(trial, baseline, _EFFECTS[0],
                                                           _EFFECTS))

    delay, _ = delay_profile(lambda d: fit_at(float(d)).mse, ts)
    if not math.isfinite(delay):
        return 0.0
    located, none = fit_at(delay), fit_at(0.0)
    if not (math.isfinite(located.mse) and math.isfinite(none.mse)) or located.mse <= 0.0:
        return 0.0
    horizon = round(3.0 * located.tau / ts)
    ratio = effective_size(located.residual, horizon) * math.log(none.mse / located.mse)
    return delay if ratio > threshold else 0.0
