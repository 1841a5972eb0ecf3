"""The rungs of the ladder (:class:`~dualprobe.diagnose.result.Step`): what a step records
(parameters, evidence, the candidates it beat, where it helped), and the look two effects ahead
when no single effect is significant."""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from dualprobe.diagnose.catalogue import effect_params
from dualprobe.diagnose.evidence import Judge
from dualprobe.diagnose.fit import ModelFit, Problem, fit_model
from dualprobe.diagnose.localise import window_regime
from dualprobe.diagnose.residuals import direction_masks, disagreement_windows
from dualprobe.diagnose.result import Step

__all__ = [
    "PAIR_PARTNERS",
    "PAIR_SEARCH_GAP",
    "PAIR_STATIC",
    "candidate_summary",
    "make_step",
    "pair_search",
    "where",
]

# Look two effects ahead only while the mean square residual exceeds the floor by this many
# floors (RMSE > 1.4 x the floor's): below, there is nothing left that two effects could hide.
PAIR_SEARCH_GAP = 1.0
# The pairs that can cancel each other's level error: a static map effect with any effect of
# the level-sensitive families (the time-varying and logger effects cannot hide a level error).
PAIR_STATIC = ("gain", "offset", "nonlinearity")
PAIR_PARTNERS = ("extra_pole", "hysteresis", "dead_time", "gain", "offset", "nonlinearity")


def candidate_summary(evidence: Mapping[str, Any]) -> dict[str, Any]:
    keys = (
        "rmse",
        "gap_closed",
        "likelihood_ratio",
        "delta_bic",
        "effect_size_over_minimum",
        "significant",
    )
    return {k: evidence.get(k) for k in keys}


def where(
    before: ModelFit, after: ModelFit, u: np.ndarray, t: np.ndarray, ts: float, sigma: float
) -> list[dict[str, Any]]:
    """Disagreement windows of the model before the step, with the RMS after it."""
    out = []
    masks = direction_masks(before.prediction, u, ts, sigma)
    for start, end in disagreement_windows(before.residual, t, ts, before.tau, sigma):
        seg = slice(start, end)
        out.append(
            {
                "start": float(t[start]),
                "end": float(t[end - 1]),
                "rms_before": float(np.sqrt(np.mean(before.residual[seg] ** 2))),
                "rms_after": float(np.sqrt(np.mean(after.residual[seg] ** 2))),
                "regime": window_regime(masks, seg),
            }
        )
    return out


def make_step(
    effect: str,
    current: ModelFit,
    fit: ModelFit,
    evidence: Mapping[str, Any],
    candidates: Mapping[str, tuple[ModelFit, dict[str, Any]]],
    data: tuple[np.ndarray, np.ndarray, float, float],
    params_from: ModelFit | None = None,
) -> Step:
    """A rung of the ladder (`data`: reference, time, sample interval, noise RMS); the
    effect's parameters from `params_from` (the joint fit of a pair) when given, else from
    `fit`."""
    u, t, ts, sigma = data
    table = {e: candidate_summary(c[1]) for e, c in candidates.items()}
    evidence = {k: v for k, v in evidence.items() if k != "rmse"}
    ranked = sorted(candidates, key=lambda e: -candidates[e][1]["gap_closed"])
    runner_up = next((e for e in ranked if e != effect), None)
    if runner_up is not None:
        evidence["runner_up"] = runner_up
        evidence["runner_up_gap_closed"] = candidates[runner_up][1]["gap_closed"]
    evidence["candidates"] = table
    return Step(
        effect=effect,
        params=effect_params(effect, (params_from or fit).params),
        rmse_before=current.rmse,
        rmse_after=fit.rmse,
        evidence=evidence,
        where=where(current, fit, u, t, ts, sigma),
        model=fit,
        candidates=table,
    )


def pair_search(
    problem: Problem,
    judge: Judge,
    current: ModelFit,
    candidates: Mapping[str, tuple[ModelFit, dict[str, Any]]],
    available: Sequence[str],
) -> list[tuple[str, ModelFit, dict[str, Any]]] | None:
    """Look two steps ahead when no single effect is significant but a large gap remains.

    Two effects can cancel each other's level error so that neither helps alone: a gain error
    against the curvature of a Pt-100 read with linear alpha, or against the mean-level bias a
    direction-dependent time constant builds up under fluctuating gas. Pairs of a static map
    effect (PAIR_STATIC) and a partner (PAIR_PARTNERS) are fitted and tested jointly (2
    degrees of freedom); the best significant pair is returned as two steps, the one that
    closes more alone first. None if no pair is significant or the gap left is within the
    noise floor (nothing to look for)."""
    if current.mse - judge.floor < PAIR_SEARCH_GAP * judge.floor:
        return None
    missing = [e for e in available if e not in current.effects and e in PAIR_PARTNERS]
    best: tuple[float, list[tuple[str, ModelFit, dict[str, Any]]]] | None = None
    for first, second in itertools.combinations(missing, 2):
        if first not in PAIR_STATIC and second not in PAIR_STATIC:
            continue
        a, b = sorted((first, second), key=lambda e: -candidates[e][1]["gap_closed"])
        effects = (*current.effects, a, b)
        fit_a, fit_b = candidates[a][0], candidates[b][0]
        # each alone has already been fitted from its scan; the static one is solved exactly
        # for any dynamics: the two single fits are the starts
        both = fit_model(problem, effects, [fit_a.params, fit_b.params])
        joint = judge.evidence((a, b), current, both)
        if not joint["significant"] or (best is not None and joint["gap_closed"] <= best[0]):
            continue
        single_ev = candidates[a][1]
        joint_fields: dict[str, Any] = {f"joint_{k}": v for k, v in joint.items() if k != "rmse"}
        first_ev = {**single_ev, **joint_fields, "joint_with": b}
        second_ev = {**judge.evidence(b, fit_a, both), **joint_fields, "joint_with": a}
        best = (joint["gap_closed"], [(a, fit_a, first_ev), (b, both, second_ev)])
    return None if best is None else best[1]
