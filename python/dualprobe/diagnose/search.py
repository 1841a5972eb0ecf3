"""The diagnosis (:func:`diagnose`): the noise of both signals and what a perfect model would
leave, the first-order baseline, the greedy nested search over the catalogue with statistical
and practical significance, the look two effects ahead, the backward check that drops an effect
made redundant, and the verdict."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np

from dualprobe.diagnose.catalogue import FITTED_EFFECTS, Scale, effect_params
from dualprobe.diagnose.catalogue.logger import MIN_FLOOR_SHARE, MIN_STEP
from dualprobe.diagnose.evidence import CHI2_THRESHOLD, SIGNIFICANCE_LEVEL, Judge, choose
from dualprobe.diagnose.fit import ModelFit, Problem, best_of, fit_model
from dualprobe.diagnose.floors import (
    ChannelNoise,
    channel_noise,
    perfect_model_floor,
    refine_noise,
    roughness_floor,
    sampling_floor,
    sensor_noise_gain,
)
from dualprobe.diagnose.flow_delay import locate_flow_delay
from dualprobe.diagnose.ladder import candidate_summary, make_step, pair_search, where
from dualprobe.diagnose.localise import localise
from dualprobe.diagnose.model import context_for
from dualprobe.diagnose.residuals import effective_size, residual_tests
from dualprobe.diagnose.result import Diagnosis, Step
from dualprobe.diagnose.starts import candidate_starts
from dualprobe.diagnose.verdict import decide
from dualprobe.io import EstimationError
from dualprobe.models.gain import GAIN_RANGE, static_gain
from dualprobe.models.shift import later

__all__ = [
    "MIN_SAMPLES",
    "diagnose",
]

MIN_SAMPLES = 50
# |correlation| of output and input above which a tiny output follows the input (other units)
# rather than nothing (disconnected: noise, ~0). Measured: a 12 s sensor behind a 4 s one on a
# 15 min drive cycle correlates 0.97 with it; a half-correlated output is no disconnection.
FOLLOWS = 0.5

Candidates = dict[str, tuple[ModelFit, dict[str, Any]]]


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


def _given_noise(
    noise_std: float | tuple[float, float] | None,
) -> tuple[float | None, float | None]:
    """(reference, measured) noise levels given by the caller: one value for both or a pair."""
    if noise_std is None:
        return None, None
    pair = (noise_std, noise_std) if isinstance(noise_std, (int, float)) else tuple(noise_std)
    if len(pair) != 2 or not all(math.isfinite(float(s)) and float(s) > 0 for s in pair):
        raise ValueError(f"diagnose: noise_std must be finite and > 0, got {noise_std!r}")
    return float(pair[0]), float(pair[1])


def _quantisation_step(noise: ChannelNoise, model: ModelFit) -> Step | None:
    """The logger's grid as a step of the ladder (it changes the floor, not the model), when
    it is a visible part of the output's noise."""
    grid = noise.grid
    if grid is None:
        return None
    share = grid.floor**2 / max(noise.std, 1e-300) ** 2
    statistical = grid.chance_log10 < math.log10(SIGNIFICANCE_LEVEL)
    practical = grid.step >= MIN_STEP and share >= MIN_FLOOR_SHARE
    if not (statistical and practical):
        return None
    evidence: dict[str, Any] = {
        "kind": "grid",
        "grid_step": grid.step,
        "grid_origin": grid.origin,
        "differences_on_grid": grid.differences,
        "chance_log10": grid.chance_log10,
        "floor_share_of_noise_variance": share,
        "effect_size_over_minimum": grid.step / MIN_STEP,
        "statistically_significant": statistical,
        "practically_significant": practical,
        "significant": True,
        "gap_closed": None,
        "likelihood_ratio": None,
        "delta_bic": None,
    }
    return Step(
        effect="quantisation",
        params={"quantisation_step": grid.step, "quantisation_floor": grid.floor},
        rmse_before=model.rmse,
        rmse_after=model.rmse,
        evidence=evidence,
        where=[],
        model=model,
    )


def diagnose(
    reference: np.ndarray,
    measured: np.ndarray,
    ts: float,
    *,
    time: np.ndarray | None = None,
    flow: np.ndarray | None = None,
    noise_std: float | tuple[float, float] | None = None,
    progress: Callable[[str], None] | None = None,
) -> Diagnosis:
    """Run the discrepancy workflow on a reference (input) and a sensor output.

    `flow` (one value per sample, > 0) makes ``flow_dependence`` a candidate; `noise_std` (K)
    replaces the estimated white-noise level of both signals, or (reference, measured).
    Raises ValueError for unusable arrays and ``dualprobe.io.EstimationError`` when the input
    does not excite the sensor (no change well above the noise)."""
    u = np.asarray(reference, dtype=float)
    y = np.asarray(measured, dtype=float)
    ts = float(ts)
    _check_arrays(u, y, ts)
    t = np.arange(u.size) * ts if time is None else np.asarray(time, dtype=float)
    if t.shape != u.shape:
        raise ValueError("diagnose: time must have one entry per sample")
    given_u, given_y = _given_noise(noise_std)
    noise_u, noise_y = channel_noise(u, given_u), channel_noise(y, given_y)
    sigma_u, sigma_y = noise_u.std, noise_y.std
    if np.ptp(u) < max(20.0 * max(sigma_u, sigma_y), 1e-9):
        raise EstimationError(
            f"diagnose: the input changes by {np.ptp(u):.3g} only, within the noise "
            f"({max(sigma_u, sigma_y):.3g}): the sensor dynamics cannot be identified"
        )
    if np.ptp(y) < max(20.0 * sigma_y, 1e-9):
        if np.ptp(y) > 0.0 and abs(float(np.corrcoef(u, y)[0, 1])) > FOLLOWS:
            # it follows, in other units: a type S thermocouple's voltage in V (1e-5 per K)
            # was called disconnected below the 0.1 mK resolution floor (floors.RESOLUTION)
            raise EstimationError(
                f"diagnose: the output follows the input but changes by {np.ptp(y):.3g} "
                f"where the input changes by {np.ptp(u):.3g}: input and output in different "
                "units or scales (e.g. degC against V)? Convert them first")
        # a sensor that does not follow its input (disconnected, stuck, the wrong column) was
        # "explained" by a gain of 3e-9 and an offset
        raise EstimationError(
            f"diagnose: the output changes by {np.ptp(y):.3g} only, within its noise "
            f"({sigma_y:.3g}), while the input changes by {np.ptp(u):.3g}: a sensor that does "
            "not follow its input (disconnected or stuck, or the wrong column?) cannot be "
            "diagnosed"
        )
    gain = static_gain(u, y, ts)
    low, high = GAIN_RANGE
    if not low <= gain <= high:
        # the catalogue's gain is a calibration error of a few per cent; a thermocouple logged
        # in mV was "partly explained" by a gain of -117 and a 3000 s pole
        raise EstimationError(
            f"diagnose: the output follows the input with a static gain of {gain:.3g}, "
            f"implausible for a temperature sensor against its reference (expected "
            f"{low:g}-{high:g}): input and output in different units or scales (e.g. degC "
            "against mV), an inverted channel, or the wrong columns? Convert them first"
        )
    v = None if flow is None else np.asarray(flow, dtype=float)
    context = context_for(u, ts, v)
    constants: dict[str, dict[str, float]] = {
        "level_dependence": {"level_reference": context.conditions.level_reference}
    }
    if v is not None:
        constants["flow_dependence"] = {"flow_reference": context.conditions.flow_reference}
    if noise_y.hold is not None:
        hold = noise_y.hold
        constants["sample_and_hold"] = {
            "hold_samples": float(hold.samples),
            "hold_phase": float(hold.phase),
        }
    available = tuple(
        e
        for e in FITTED_EFFECTS
        if (e != "flow_dependence" or v is not None)
        and (e != "sample_and_hold" or noise_y.hold is not None)
    )
    say = progress or (lambda _msg: None)
    problem = Problem(u, y, ts, context, constants)

    # 1. Baseline: first order, unity gain; log-spaced scan of tau, then least squares.
    initial = float(np.median(y[: max(3, min(20, y.size // 10))]))
    scan = [
        {"tau": float(tau), "initial": initial}
        for tau in np.geomspace(0.3 * ts, 0.2 * problem.duration, 24)
    ]
    baseline = fit_model(problem, (), best_of(problem, (), scan, 2))
    if given_y is None:
        noise_y = refine_noise(noise_y, baseline.residual)
        sigma_y = noise_y.std
    if v is not None:
        # the flow at the sensor may follow the logged flow (intake to exhaust, ECU filters)
        delay = locate_flow_delay(problem, baseline, v, CHI2_THRESHOLD)
        if delay != 0.0:
            say(f"flow delay: the sensor follows the flow column {delay:+.3g} s later "
                "(transport delay; negative: the column lags it)")
            v = later(v, delay, ts)
            context = context_for(u, ts, v, flow_reference=context.conditions.flow_reference)
            problem.context = context
        problem.constants["flow_dependence"]["flow_delay"] = delay
    white_floor = sigma_y**2 + sensor_noise_gain(ts, baseline.tau) * sigma_u**2
    jumps = sampling_floor(u, ts, baseline.tau, sigma_u)
    rough = roughness_floor(u, ts, baseline.tau, sigma_u)
    x_lo, x_hi = (float(q) for q in np.quantile(y, [0.01, 0.99]))
    scale = Scale(ts, problem.duration, (x_lo, x_hi), context.conditions)
    judge = Judge(problem, white_floor + jumps + rough, white_floor, scale)
    judge.set_steady(baseline)
    sigma = math.sqrt(white_floor)
    data = (u, t, ts, sigma)

    def convention(fit: ModelFit) -> ModelFit:
        """Sampling convention: the reference interpolated between samples (continuous gas) or
        held over each interval (data that follow the paper's eq. 8): same parameters, the better
        fit wins (by a significant likelihood ratio, else the fit's own convention stays).
        Re-decided with every model, since a large missing effect can hide the half-sample
        difference. Gas changes between samples leave a residue (the sampling floor) only when
        the reference is interpolated."""
        own = {"input_hold": 1.0} if fit.params.get("input_hold") else {}
        problem.fixed = {} if own else {"input_hold": 1.0}
        other = fit_model(problem, fit.effects, [fit.params])
        # switch only on evidence: under a poor model the two differ by chance
        horizon = round(3.0 * other.tau / ts)
        lr = effective_size(other.residual, horizon) * math.log(fit.mse / max(other.mse, 1e-300))
        if lr > judge.chi2_threshold:
            fit = other
        else:
            problem.fixed = own
        judge.floor = white_floor + (0.0 if problem.fixed else jumps + rough)
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
                params=effect_params(steps[-1].effect, rechecked.params),
                where=where(before, rechecked, u, t, ts, sigma),
            )
        return rechecked

    def extend(model: ModelFit, effect: str, extra: Sequence[Mapping[str, float]] = ()) -> ModelFit:
        effects = (*model.effects, effect)
        starts = [*candidate_starts(problem, model, effect, effects), *extra]
        fit = fit_model(problem, effects, starts)
        if effect == "sample_and_hold":
            # The logger's hold delays the reading by (k - 1)/2 rows on average, which the
            # convention of a held reference partly mimics: try the hold under the other one.
            saved = problem.fixed
            problem.fixed = {} if saved else {"input_hold": 1.0}
            other = fit_model(problem, effects, starts)
            problem.fixed = saved
            fit = other if other.mse < fit.mse else fit
        return fit

    def rebuild(kept: Sequence[str], start: Mapping[str, float]) -> list[Step]:
        """The ladder over the kept effects, ordered greedily again (the one that closes most
        of the gap first); a step that is not significant on its own is marked joint."""
        ladder: list[Step] = []
        model = baseline
        remaining = list(kept)
        while remaining:
            options: Candidates = {}
            for effect in remaining:
                fit = extend(model, effect, [start])
                options[effect] = (fit, judge.evidence(effect, model, fit))
            chosen = max(options, key=lambda e: options[e][1]["gap_closed"])
            fit, evidence = options[chosen]
            remaining.remove(chosen)
            if not evidence["significant"] and remaining:
                evidence = {**evidence, "joint_with": list(remaining)}
            ladder.append(make_step(chosen, model, fit, evidence, options, data))
            model = settle(ladder, fit)
        return ladder

    baseline = convention(baseline)
    judge.set_steady(baseline)
    say(f"baseline: tau {baseline.tau:.4g} s, RMSE {baseline.rmse:.4g} K")

    # 2-4. Greedy forward search.
    current = baseline
    steps: list[Step] = []
    last_round: dict[str, dict[str, Any]] = {}
    while len(current.effects) < len(available):
        candidates: Candidates = {}
        for effect in available:
            if effect not in current.effects:
                fit = extend(current, effect)
                candidates[effect] = (fit, judge.evidence(effect, current, fit))
        winner = choose(candidates, judge.chi2_threshold)
        if winner is None:
            pair = pair_search(problem, judge, current, candidates, available)
            if pair is None:
                last_round = {e: candidate_summary(c[1]) for e, c in candidates.items()}
                break
            joint = pair[-1][1]
            for effect, fit, evidence in pair:
                steps.append(make_step(effect, current, fit, evidence, candidates, data, joint))
                say(f"+ {effect} (jointly): RMSE {current.rmse:.4g} -> {fit.rmse:.4g} K")
                current = fit
        else:
            fit, evidence = candidates[winner]
            steps.append(make_step(winner, current, fit, evidence, candidates, data))
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
                current = steps[-1].model if steps else baseline
                changed = True
                break

    final = current
    grid_step = _quantisation_step(noise_y, baseline)
    if grid_step is not None:
        steps.insert(0, grid_step)
    # Whiteness on the rows the logger refreshed (a held reading repeats its noise).
    rows = slice(None)
    if "hold_samples" in final.params:
        rows = slice(int(final.params["hold_phase"]), None, int(final.params["hold_samples"]))
    step_ts = ts * (rows.step or 1)
    tests_final = residual_tests(final.residual[rows], u[rows], step_ts, final.tau)
    misfit = localise(final, u, t, ts, math.sqrt(judge.floor), v)
    floor = perfect_model_floor(u, ts, baseline.tau, sigma_u, sigma_y,
                                interpolated=not problem.fixed)
    named = [s.effect for s in steps]
    verdict = decide(
        named, baseline.residual, final.residual, floor, tests_final["ljung_box_p"], misfit
    )
    say(verdict.sentence)
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
        localisation=localise(baseline, u, t, ts, sigma, v),
        tests_baseline=residual_tests(baseline.residual, u, ts, baseline.tau),
        tests_final=tests_final,
        dropped=tuple(dropped),
        last_round=last_round,
        flow=v,
        noise={
            "reference_std": sigma_u,
            "measured_std": sigma_y,
            "reference_source": noise_u.source,
            "measured_source": noise_y.source,
            "white_floor": white_floor,
            "jump_floor": 0.0 if problem.fixed else jumps,
            "roughness_floor": 0.0 if problem.fixed else rough,
            "floor": judge.floor,
            "floor_rms": math.sqrt(judge.floor),
        },
        verdict=verdict,
        misfit=misfit,
    )
