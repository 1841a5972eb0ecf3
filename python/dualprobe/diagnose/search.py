"""The diagnosis (:func:`diagnose`): the first-order baseline, the greedy nested search over the
catalogue with statistical and practical significance, the look two effects ahead, and the
backward check that drops an effect made redundant."""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from scipy import stats

from dualprobe.diagnose.catalogue import (
    EFFECTS,
    MIN_GAP_CLOSED,
    MIN_IMPROVEMENT_OF_NOISE,
    NEARLY_AS_GOOD,
    SIGNIFICANCE_LEVEL,
    SIMPLICITY,
    STATIC_EFFECTS,
    candidate_starts,
    effect_params,
    effect_size,
)
from dualprobe.diagnose.fit import ModelFit, Problem, best_of, dot, fit_model
from dualprobe.diagnose.residuals import (
    REGIME_THRESHOLD_NOISE,
    disagreement_windows,
    effective_size,
    localise,
    moving_mean,
    regime_masks,
    residual_tests,
    sampling_floor,
)
from dualprobe.diagnose.result import Diagnosis, Step
from dualprobe.io import EstimationError
from dualprobe.models.noise import ORDER_DIAGNOSE, estimate_noise_std

__all__ = [
    "MIN_SAMPLES",
    "diagnose",
]




MIN_SAMPLES = 50


# A static effect (offset, gain, nonlinearity) must reduce the mean square residual of the
# settled samples by a quarter of the noise variance (its correction there has an RMS of at least
# half the noise; a realistic one, 0.5 K or 2 % gain, is ~25-100x that), checked when at least
# MIN_STEADY_SAMPLES (and 5 % of the record) are settled.
MIN_STEADY_IMPROVEMENT = 0.25
MIN_STEADY_SAMPLES = 200
# Look two effects ahead only while the mean square residual exceeds the floor by this many
# floors (RMSE > 1.4 x the floor's): below, there is nothing left that two effects could hide.
PAIR_SEARCH_GAP = 1.0


class _Judge:
    """Evidence for extending a model, shared by the forward search and the backward check."""

    def __init__(
        self,
        problem: Problem,
        floor: float,
        white_floor: float,
        x_range: tuple[float, float],
    ) -> None:
        self.problem = problem
        self.floor = floor  # white noise plus the sampling floor of off-grid jumps
        self.white_floor = white_floor
        self.x_range = x_range
        self.chi2_threshold = float(stats.chi2.isf(SIGNIFICANCE_LEVEL, 1))
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
        size = min(effect_size(e, after, self.x_range, self.problem.ts) for e in added)
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


def _choose(
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


def _check_arrays(reference: np.ndarray, measured: np.ndarray, ts: float) -> None:
    if reference.ndim != 1 or measured.ndim != 1:
        raise ValueError("diagnose: reference and measured must be one-dimensional arrays")
    if reference.size != measured.size:
        raise ValueError(
            f"diagnose: reference has {reference.size} samples, measured {measured.size}"
        )
    if reference.size < MIN_SAMPLES:
        raise ValueError(f"diagnose: need at least {MIN_SAMPLES} samples, got {reference.size}")
    if not (math.isfinite(ts) and ts > 0):
        raise ValueError(f"diagnose: sample interval must be finite and > 0, got {ts}")
    for name, x in (("reference", reference), ("measured", measured)):
        bad = np.flatnonzero(~np.isfinite(x))
        if bad.size:
            raise ValueError(f"diagnose: {name} sample {int(bad[0])} is not finite")


def diagnose(
    reference: np.ndarray,
    measured: np.ndarray,
    ts: float,
    *,
    time: np.ndarray | None = None,
    progress: Callable[[str], None] | None = None,
) -> Diagnosis:
    """Run the discrepancy workflow on a reference (input) and a sensor output.

    Raises ValueError for unusable arrays and ``dualprobe.io.EstimationError`` when the input
    does not excite the sensor (no change well above the noise)."""
    u = np.asarray(reference, dtype=float)
    y = np.asarray(measured, dtype=float)
    ts = float(ts)
    _check_arrays(u, y, ts)
    t = np.arange(u.size) * ts if time is None else np.asarray(time, dtype=float)
    if t.shape != u.shape:
        raise ValueError("diagnose: time must have one entry per sample")
    sigma_u, sigma_y = estimate_noise_std(u, ORDER_DIAGNOSE), estimate_noise_std(y, ORDER_DIAGNOSE)
    if np.ptp(u) < max(20.0 * max(sigma_u, sigma_y), 1e-9):
        raise EstimationError(
            f"diagnose: the input changes by {np.ptp(u):.3g} only, within the noise "
            f"({max(sigma_u, sigma_y):.3g}): the sensor dynamics cannot be identified"
        )
    say = progress or (lambda _msg: None)
    problem = Problem(u, y, ts)

    # 1. Baseline: first order, unity gain; log-spaced scan of tau, then least squares.
    initial = float(np.median(y[: max(3, min(20, y.size // 10))]))
    scan = [
        {"tau": float(tau), "initial": initial}
        for tau in np.geomspace(0.3 * ts, 0.2 * problem.duration, 24)
    ]
    baseline = fit_model(problem, (), best_of(problem, (), scan, 2))
    h = ts / baseline.tau
    noise_gain = -math.expm1(-h) / (1.0 + math.exp(-h))  # output variance / white input variance
    white_floor = sigma_y**2 + noise_gain * sigma_u**2
    jitter = sampling_floor(u, ts, baseline.tau, sigma_u)
    x_range = tuple(np.quantile(y, [0.01, 0.99]))
    judge = _Judge(
        problem, white_floor + jitter, white_floor, (float(x_range[0]), float(x_range[1]))
    )
    judge.set_steady(baseline)
    sigma = math.sqrt(white_floor)

    def convention(fit: ModelFit) -> ModelFit:
        """Sampling convention: the reference interpolated between samples (continuous gas) or
        held over each interval (data that follow the paper's eq. 8): same parameters, the better
        fit wins (by a significant likelihood ratio, else the interpolated default stays).
        Re-decided with every model, since a large missing effect can hide the half-sample
        difference. Gas changes between samples leave a residue (the sampling
        floor) only when the reference is interpolated."""
        saved = problem.fixed
        problem.fixed = {} if saved else {"input_hold": 1.0}
        other = fit_model(problem, fit.effects, [fit.params])
        # switch only on evidence: under a poor model the two differ by chance
        horizon = round(3.0 * other.tau / ts)
        lr = effective_size(other.residual, horizon) * math.log(fit.mse / max(other.mse, 1e-300))
        if lr > judge.chi2_threshold:
            fit = other
        else:
            problem.fixed = saved
        judge.floor = white_floor + (0.0 if problem.fixed else jitter)
        return fit

    def settle(steps: list[Step], current: ModelFit) -> ModelFit:
        """Re-decide the convention with the model just reached; update its step if it moved."""
        rechecked = convention(current)
        if rechecked is not current:
            before = steps[-2].model if len(steps) > 1 else baseline
            steps[-1] = replace(
                steps[-1],
                model=rechecked,
                rmse_after=rechecked.rmse,
                params=effect_params(steps[-1].effect, rechecked),
                where=_where(before, rechecked, u, t, ts, sigma),
            )
        return rechecked

    def rebuild(kept: Sequence[str], start: Mapping[str, float]) -> list[Step]:
        """The ladder over the kept effects, ordered greedily again (the one that closes most
        of the gap first); a step that is not significant on its own is marked joint."""
        ladder: list[Step] = []
        model = baseline
        remaining = list(kept)
        while remaining:
            options: dict[str, tuple[ModelFit, dict[str, Any]]] = {}
            for effect in remaining:
                effects = (*model.effects, effect)
                starts = [*candidate_starts(problem, model, effect, effects), start]
                fit = fit_model(problem, effects, starts)
                options[effect] = (fit, judge.evidence(effect, model, fit))
            chosen = max(options, key=lambda e: options[e][1]["gap_closed"])
            fit, evidence = options[chosen]
            remaining.remove(chosen)
            if not evidence["significant"] and remaining:
                evidence = {**evidence, "joint_with": list(remaining)}
            table = {e: _candidate_summary(c[1]) for e, c in options.items()}
            ladder.append(_make_step(chosen, model, fit, evidence, options, table, u, t, ts, sigma))
            model = settle(ladder, fit)
        return ladder

    baseline = convention(baseline)
    judge.set_steady(baseline)
    say(f"baseline: tau {baseline.tau:.4g} s, RMSE {baseline.rmse:.4g} K")

    # 2-4. Greedy forward search.
    current = baseline
    steps: list[Step] = []
    last_round: dict[str, dict[str, Any]] = {}
    while len(current.effects) < len(EFFECTS):
        candidates: dict[str, tuple[ModelFit, dict[str, Any]]] = {}
        for effect in EFFECTS:
            if effect in current.effects:
                continue
            effects = (*current.effects, effect)
            fit = fit_model(problem, effects, candidate_starts(problem, current, effect, effects))
            candidates[effect] = (fit, judge.evidence(effect, current, fit))
        winner = _choose(candidates, judge.chi2_threshold)
        table = {e: _candidate_summary(c[1]) for e, c in candidates.items()}
        if winner is None:
            pair = _pair_search(problem, judge, current, candidates)
            if pair is None:
                last_round = table
                break
            joint = pair[-1][1]
            for effect, fit, evidence in pair:
                steps.append(
                    _make_step(
                        effect, current, fit, evidence, candidates, table, u, t, ts, sigma, joint
                    )
                )
                say(f"+ {effect} (jointly): RMSE {current.rmse:.4g} -> {fit.rmse:.4g} K")
                current = fit
        else:
            fit, evidence = candidates[winner]
            steps.append(
                _make_step(winner, current, fit, evidence, candidates, table, u, t, ts, sigma)
            )
            say(f"+ {winner}: RMSE {current.rmse:.4g} -> {fit.rmse:.4g} K")
            current = fit
        current = settle(steps, current)

    # Backward check: an effect made redundant by a later one is dropped and the ladder rebuilt.
    dropped: list[str] = []
    changed = True
    while changed and len(current.effects) > 1:
        changed = False
        for effect in current.effects:
            reduced_effects = tuple(e for e in current.effects if e != effect)
            reduced = fit_model(problem, reduced_effects, [current.params])
            if not judge.evidence(effect, reduced, current)["significant"]:
                say(f"- {effect}: redundant given the others")
                dropped.append(effect)
                steps = rebuild(reduced_effects, reduced.params)
                current = steps[-1].model
                changed = True
                break

    final = current
    return Diagnosis(
        time=t,
        reference=u,
        measured=y,
        sample_interval=ts,
        noise_std=(sigma_u, sigma_y),
        noise_floor=judge.floor,
        baseline=baseline,
        steps=tuple(steps),
        final=final,
        localisation=localise(baseline, u, t, ts, sigma),
        tests_baseline=residual_tests(baseline.residual, u, ts, baseline.tau),
        tests_final=residual_tests(final.residual, u, ts, final.tau),
        dropped=tuple(dropped),
        last_round=last_round,
    )


def _make_step(
    effect: str,
    current: ModelFit,
    fit: ModelFit,
    evidence: Mapping[str, Any],
    candidates: Mapping[str, tuple[ModelFit, dict[str, Any]]],
    table: dict[str, dict[str, Any]],
    u: np.ndarray,
    t: np.ndarray,
    ts: float,
    sigma: float,
    params_from: ModelFit | None = None,
) -> Step:
    """A rung of the ladder; the effect's parameters from `params_from` (the joint fit of a
    pair) when given, else from `fit`."""
    evidence = dict(evidence)
    ranked = sorted(candidates, key=lambda e: -candidates[e][1]["gap_closed"])
    runner_up = next((e for e in ranked if e != effect), None)
    if runner_up is not None:
        evidence["runner_up"] = runner_up
        evidence["runner_up_gap_closed"] = candidates[runner_up][1]["gap_closed"]
    evidence["candidates"] = table
    return Step(
        effect=effect,
        params=effect_params(effect, params_from or fit),
        rmse_before=current.rmse,
        rmse_after=fit.rmse,
        evidence=_strip(evidence),
        where=_where(current, fit, u, t, ts, sigma),
        model=fit,
        candidates=table,
    )


def _pair_search(
    problem: Problem,
    judge: _Judge,
    current: ModelFit,
    candidates: Mapping[str, tuple[ModelFit, dict[str, Any]]],
) -> list[tuple[str, ModelFit, dict[str, Any]]] | None:
    """Look two steps ahead when no single effect is significant but a large gap remains.

    Two effects can cancel each other's level error so that neither helps alone: a gain error
    against the curvature of a Pt-100 read with linear alpha, or against the mean-level bias a
    direction-dependent time constant builds up under fluctuating gas. Pairs with at least one
    static effect are fitted and tested jointly (2 degrees of freedom); the best significant
    pair is returned as two steps, the one that closes more alone first. None if no pair is
    significant or the gap left is within the noise floor (nothing to look for)."""
    if current.mse - judge.floor < PAIR_SEARCH_GAP * judge.floor:
        return None
    missing = [e for e in EFFECTS if e not in current.effects]
    best: tuple[float, list[tuple[str, ModelFit, dict[str, Any]]]] | None = None
    for first, second in itertools.combinations(missing, 2):
        if first not in STATIC_EFFECTS and second not in STATIC_EFFECTS:
            continue
        a, b = sorted((first, second), key=lambda e: -candidates[e][1]["gap_closed"])
        effects = (*current.effects, a, b)
        fit_a, fit_b = candidates[a][0], candidates[b][0]
        starts = [
            *candidate_starts(problem, fit_b, a, effects),
            *candidate_starts(problem, fit_a, b, effects),
        ]
        both = fit_model(problem, effects, starts)
        joint = judge.evidence((a, b), current, both)
        if not joint["significant"] or (best is not None and joint["gap_closed"] <= best[0]):
            continue
        single_ev = candidates[a][1]
        joint_fields: dict[str, Any] = {f"joint_{k}": v for k, v in joint.items() if k != "rmse"}
        first_ev = {**single_ev, **joint_fields, "joint_with": b}
        second_ev = {**judge.evidence(b, fit_a, both), **joint_fields, "joint_with": a}
        best = (joint["gap_closed"], [(a, fit_a, first_ev), (b, both, second_ev)])
    return None if best is None else best[1]


def _candidate_summary(evidence: Mapping[str, Any]) -> dict[str, Any]:
    keys = (
        "rmse",
        "gap_closed",
        "likelihood_ratio",
        "delta_bic",
        "effect_size_over_minimum",
        "significant",
    )
    return {k: evidence[k] for k in keys}


def _strip(evidence: Mapping[str, Any]) -> dict[str, Any]:
    return {k: v for k, v in evidence.items() if k != "rmse"}


def _where(
    before: ModelFit, after: ModelFit, u: np.ndarray, t: np.ndarray, ts: float, sigma: float
) -> list[dict[str, Any]]:
    """Disagreement windows of the model before the step, with the RMS after it."""
    out = []
    for start, end in disagreement_windows(before.residual, t, ts, before.tau, sigma):
        seg = slice(start, end)
        masks = regime_masks(before, u, ts, sigma)
        heat = float(np.mean(masks["heating"][seg]))
        cool = float(np.mean(masks["cooling"][seg]))
        out.append(
            {
                "start": float(t[start]),
                "end": float(t[end - 1]),
                "rms_before": float(np.sqrt(np.mean(before.residual[seg] ** 2))),
                "rms_after": float(np.sqrt(np.mean(after.residual[seg] ** 2))),
                "regime": "heating"
                if heat > max(cool, 0.3)
                else ("cooling" if cool > 0.3 else "steady"),
            }
        )
    return out
