"""The evidence an extension of the model needs: statistical significance (a likelihood ratio
with an effective sample size, chi-square and BIC) and practical significance (the gap it
closes, the improvement against the noise, its size, and for a static effect an improvement
where the sensor has settled); the choice among significant candidates.

Sign convention, everywhere (JSON, report, summary): ``delta_bic`` > 0 is evidence *for* the
effect (the BIC of the extended model is lower by that much).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy import stats

from dualprobe.diagnose.catalogue import SIMPLICITY, STATIC_EFFECTS, Scale, effect_size
from dualprobe.diagnose.fit import ModelFit, Problem, dot
from dualprobe.diagnose.residuals import REGIME_THRESHOLD_NOISE, effective_size, moving_mean

__all__ = [
    "CHI2_THRESHOLD",
    "MIN_GAP_CLOSED",
    "MIN_IMPROVEMENT_OF_NOISE",
    "MIN_STEADY_IMPROVEMENT",
    "NEARLY_AS_GOOD",
    "SIGNIFICANCE_LEVEL",
    "Judge",
    "choose",
]

SIGNIFICANCE_LEVEL = 1e-3  # chi-square test of the likelihood ratio
CHI2_THRESHOLD = float(stats.chi2.isf(SIGNIFICANCE_LEVEL, 1))  # one added parameter
# A winner must close a quarter of what is left above the floor: a real missing effect alone
# closes > 60 % of it in the hidden-effect sweeps (the first of two hidden ones less: the second
# is still in the gap); the effect-size floors do most of the work against spurious ones.
MIN_GAP_CLOSED = 0.25
# ... and improve the mean square residual by 3 % of the noise variance: below that the
# improvement is invisible against the noise even where it is statistically detectable.
MIN_IMPROVEMENT_OF_NOISE = 0.03
# A simpler candidate replaces the best if it closes within this fraction of the gap of it
# (or the likelihood ratio between the two is insignificant).
NEARLY_AS_GOOD = 0.01
# A static effect (offset, gain, nonlinearity, drift) must reduce the mean square residual of
# the settled samples by a quarter of the noise variance (its correction there has an RMS of at
# least half the noise; a realistic one, 0.5 K or 2 % gain, is ~25-100x that), checked when at
# least MIN_STEADY_SAMPLES (and 5 % of the record) are settled.
MIN_STEADY_IMPROVEMENT = 0.25
MIN_STEADY_SAMPLES = 200


class Judge:
    """Evidence for extending a model, shared by the forward search and the backward check."""

    def __init__(self, problem: Problem, floor: float, white_floor: float, scale: Scale) -> None:
        self.problem = problem
        self.floor = floor  # white noise plus the sampling floor
        self.white_floor = white_floor
        self.scale = scale
        self.chi2_threshold = CHI2_THRESHOLD
        self.steady = np.zeros(problem.u.size, dtype=bool)

    def set_steady(self, baseline: ModelFit) -> None:
        """Samples where the baseline sensor (unity gain: its output is its state) has settled
        on the gas, within REGIME_THRESHOLD_NOISE noise standard deviations."""
        smooth = moving_mean(self.problem.u, max(3, round(0.5 / self.problem.ts)))
        threshold = max(REGIME_THRESHOLD_NOISE * math.sqrt(self.white_floor), 0.2)
        self.steady = np.abs(smooth - baseline.prediction) < threshold

    def evidence(
        self, effect: str | Sequence[str], before: ModelFit, after: ModelFit
    ) -> dict[str, Any]:
        """Evidence for `after` = `before` extended by `effect` (one name or several)."""
        added = (effect,) if isinstance(effect, str) else tuple(effect)
        n = after.residual.size
        horizon = round(3.0 * max(before.tau, after.tau) / self.problem.ts)
        n_eff = effective_size(after.residual, horizon)
        mse0, mse1 = before.mse, after.mse
        lr = n_eff * math.log(max(mse0, 1e-300) / max(mse1, 1e-300))
        dof = after.n_params - before.n_params
        delta_bic = lr - dof * math.log(n_eff)
        gap = max(mse0 - self.floor, 0.05 * self.floor, 1e-300)
        closed = (mse0 - mse1) / gap
        size = min(effect_size(e, after.params, after.tau, self.scale) for e in added)
        statistical = bool(lr > self.chi2_threshold and delta_bic > 0)
        improvement = (mse0 - mse1) / max(self.white_floor, 1e-300)
        practical = bool(
            closed >= MIN_GAP_CLOSED and improvement >= MIN_IMPROVEMENT_OF_NOISE and size >= 1.0
        )
        steady_improvement = float("nan")
        if any(e in STATIC_EFFECTS for e in added):
            # A static effect must show where the sensor has settled: transient artefacts
            # (jumps between samples, a lagging reference) can buy a small level-correlated
            # offset or gain on the whole record, never in steady state.
            steady = self.steady
            if np.sum(steady) >= max(MIN_STEADY_SAMPLES, 0.05 * n):
                r0, r1 = before.residual[steady], after.residual[steady]
                steady_improvement = (dot(r0, r0) - dot(r1, r1)) / r0.size / self.white_floor
                practical = practical and steady_improvement >= MIN_STEADY_IMPROVEMENT
        return {
            "likelihood_ratio": lr,
            "p_value": float(stats.chi2.sf(max(lr, 0.0), dof)),
            "delta_bic": delta_bic,
            "n": n,
            "n_effective": n_eff,
            "gap_closed": closed,
            "improvement_over_noise_variance": improvement,
            "effect_size_over_minimum": size,
            "steady_improvement_over_noise_variance": steady_improvement,
            "statistically_significant": statistical,
            "practically_significant": practical,
            "significant": statistical and practical,
            "rmse": after.rmse,
        }


def choose(
    candidates: Mapping[str, tuple[ModelFit, dict[str, Any]]], n_eff_threshold: float
) -> str | None:
    """Best significant candidate, or a simpler one that does nearly as well."""
    significant = {e: c for e, c in candidates.items() if c[1]["significant"]}
    if not significant:
        return None
    best = max(significant, key=lambda e: significant[e][1]["gap_closed"])
    best_fit, best_ev = significant[best]
    for effect in SIMPLICITY:
        if effect == best:
            break
        if effect not in significant:
            continue
        fit, ev = significant[effect]
        close = ev["gap_closed"] >= best_ev["gap_closed"] - NEARLY_AS_GOOD
        # Equal parameter counts: the likelihood ratio of the two fits with the effective
        # sample size tells whether the data can tell them apart at all.
        lr = best_ev["n_effective"] * math.log(fit.mse / max(best_fit.mse, 1e-300))
        if close or lr < n_eff_threshold:
            return effect
    return best
