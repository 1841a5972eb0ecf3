"""Where the fit of each candidate extension starts: its null value (which reproduces the
current model, so a nested fit can only improve on it) and the best few points of a scan where
the fit is multimodal."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from dualprobe.diagnose.catalogue.dynamics import main_tau, null_extension
from dualprobe.diagnose.fit import ModelFit, Problem, best_of

__all__ = ["candidate_starts"]

_TAU_KEYS = ("tau", "tau_heat", "tau_cool")


def _scaled(p: Mapping[str, float], factor: float) -> dict[str, float]:
    q = dict(p)
    for key in _TAU_KEYS:
        if key in q:
            q[key] = q[key] * factor
    return q


def candidate_starts(
    problem: Problem, current: ModelFit, effect: str, effects: Sequence[str]
) -> list[Mapping[str, float]]:
    """Starting points for extending `current` by `effect`."""
    p = dict(current.params)
    tau = current.tau
    ts = problem.ts
    if effect == "extra_pole":
        trials = []
        for ratio in np.geomspace(0.01, 0.6, 12):
            # keep the sum of the time constants (the mean delay of the step response)
            q = _scaled(p, 1.0 / (1.0 + ratio))
            q["tau2"] = ratio * main_tau(q)
            trials.append(q)
        return [null_extension(p, effect), *best_of(problem, effects, trials, 2)]
    if effect == "dead_time":
        trials = []
        max_delay = min(0.6 * tau, 0.25 * problem.duration)
        grid = np.unique(np.concatenate((np.arange(0.0, 10.5) * ts, np.linspace(0, max_delay, 16))))
        for delay in grid:
            q = _scaled(p, max(1.0 - delay / tau, 0.3))
            q["delay"] = float(delay)
            trials.append(q)
        return [null_extension(p, effect), *best_of(problem, effects, trials, 2)]
    if effect == "hysteresis":
        trials = []
        for ratio in (0.6, 0.8, 1.25, 1.6):
            q = dict(p)
            base = q.pop("tau")
            q["tau_heat"] = base / math.sqrt(ratio)
            q["tau_cool"] = base * math.sqrt(ratio)
            trials.append(q)
        return [null_extension(p, effect), *best_of(problem, effects, trials, 2)]
    if effect in ("flow_dependence", "level_dependence"):
        name = "flow_exponent" if effect == "flow_dependence" else "level_exponent"
        trials = [{**p, name: float(e)} for e in (-0.4, 0.3, 0.6, 1.0)]
        return [{**p, name: 0.0}, *best_of(problem, effects, trials, 1)]
    return [p]  # static effects are solved exactly for any dynamics; the hold is detected
