"""Issue 14: the new catalogue effects on recordings with hidden effects (hidden_field.py).

The generator is written independently of ``dualprobe.diagnose``: sensors simulated exactly by
``dualprobe.simulate.drive_cycle`` under drive-cycle or laboratory gas, a fine thermocouple as
the reference. Each new effect is hidden in 10 recordings (seeds 1-10, parameters drawn at
random over a realistic range) and must be named alone in at least 9 of them; the parameters
of the named effect must be close to the hidden ones. The rates are printed (``-s``).
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from dualprobe import diagnose as dg
from hidden_field import FIELD_EFFECTS, FieldCase, make_field_case

SEEDS = tuple(range(1, 11))
MIN_RATE = 0.9


def _diagnose(case: FieldCase, *, flow: bool) -> dg.Diagnosis:
    return dg.diagnose(case.reference, case.measured, case.ts, flow=case.flow if flow else None)


def _parameter_error(effect: str, d: dg.Diagnosis, case: FieldCase) -> float:
    """How far the named effect's parameter is from the hidden one, in units of what is close
    enough (<= 1 passes)."""
    p, truth = d.final.params, case.truth
    if effect == "flow_dependence":
        # the reference lags 2-6 ms and follows the flow itself: 0.05 on the exponent
        return abs(p["flow_exponent"] - truth["flow_exponent"]) / 0.05
    if effect == "level_dependence":
        # over a 1.8x range of absolute temperature the exponent is found to ~0.05; the lagging
        # reference (10-30 ms) and the off-grid steps bias it: 0.1
        return abs(p["level_exponent"] - truth["level_exponent"]) / 0.1
    if effect == "drift":
        hours = (case.t[-1] - case.t[0]) / 3600.0
        # the drift over the record within 0.2 K (the smallest hidden one is 0.5 K)
        return abs(p["drift_rate"] * hours - truth["drift_total"]) / 0.2
    if effect == "sample_and_hold":
        exact = (
            p["hold_samples"] == truth["hold_samples"] and p["hold_phase"] == truth["hold_phase"]
        )
        return 0.0 if exact else np.inf
    step = next(s for s in d.steps if s.effect == "quantisation").params["quantisation_step"]
    return abs(step - truth["quantisation_step"]) / 1e-9


@pytest.mark.parametrize("effect", FIELD_EFFECTS)
def test_each_new_effect_is_named_in_at_least_9_of_10_recordings(effect: str) -> None:
    outcomes = {}
    for seed in SEEDS:
        case = make_field_case((effect,), seed)
        d = _diagnose(case, flow=effect == "flow_dependence")
        named = d.effects == [effect]
        error = _parameter_error(effect, d, case) if named else np.inf
        outcomes[seed] = (d.effects, d.verdict.verdict if d.verdict else None, round(error, 2))
    hits = [s for s, (effects, _, error) in outcomes.items() if effects == [effect] and error <= 1]
    rate = len(hits) / len(SEEDS)
    print(f"\n{effect}: named alone with close parameters in {len(hits)}/{len(SEEDS)}: {outcomes}")
    assert rate >= MIN_RATE, outcomes


def test_flow_dependence_without_the_flow_column_is_not_called_explained_by_nothing() -> None:
    """Without --flow the time constant's variation is only partly captured (the gas level
    follows the load too): never 'nothing_missing', and a misfit of several times the noise is
    reported when the best catalogue stand-in leaves one."""
    for seed in (1, 2):
        case = make_field_case(("flow_dependence",), seed)
        d = _diagnose(case, flow=False)
        assert d.verdict is not None
        assert d.verdict.verdict != "nothing_missing", d.verdict.sentence
        if d.verdict.misfit_to_noise > dg.MISFIT_LIMIT:
            assert d.verdict.verdict in ("partly_explained", "unexplained"), d.verdict.sentence


def test_flow_dependence_reproduces_the_final_simulation() -> None:
    case = make_field_case(("flow_dependence",), 3)
    d = _diagnose(case, flow=True)
    params = d.final.params
    assert {"flow_exponent", "flow_reference"} <= set(params)
    simulated = dg.simulate_effects(case.reference, case.ts, params, flow=case.flow)
    # the reported parameters (with the flow reference, the median velocity) are the model
    np.testing.assert_allclose(simulated, d.final.prediction, atol=1e-9)
    assert params["flow_reference"] == pytest.approx(float(np.median(case.flow)))


@pytest.mark.parametrize("late", [0.5, -0.3])
def test_a_flow_column_logged_late_or_early_is_located(late: float) -> None:
    """An ECU's mass flow reaches the sensor later than it is logged (intake to exhaust, its
    filters). Given as logged, a flow 0.3 s late left 2.8 times the noise floor, "partly
    explained"; 1 s late was read as a level dependence with an exponent of 3 (drive cycle,
    10 Hz, tau 4 s, m 0.5). The delay is now located as characterise does (either sign):
    measured on seeds 1-10 with the flow 0.5 s late, -0.498 to -0.514 s, every exponent as
    hidden to 3 decimals, all explained; with the flow as logged, 0 or under 0.014 s."""
    for seed in (1, 2, 3):
        case = make_field_case(("flow_dependence",), seed)
        rows = np.arange(case.flow.size, dtype=float)
        logged = np.interp(rows - late / case.ts, rows, case.flow)  # the column `late` s late
        d = dg.diagnose(case.reference, case.measured, case.ts, flow=logged)
        assert d.effects == ["flow_dependence"], d.effects
        assert d.verdict is not None and d.verdict.verdict == "explained", d.verdict.sentence
        params = d.final.params
        # the sensor follows the column -late s later; one-row interpolation and the 2-6 ms
        # reference lag: within 0.03 s (a third of a row at 10 Hz)
        assert params["flow_delay"] == pytest.approx(-late, abs=0.03)
        assert abs(params["flow_exponent"] - case.truth["flow_exponent"]) < 0.05
        # the reported parameters, with the delay, are the model
        simulated = dg.simulate_effects(case.reference, case.ts, params, flow=logged)
        np.testing.assert_allclose(simulated, d.final.prediction, atol=1e-9)


def test_drift_and_hold_reproduce_the_final_simulation() -> None:
    for effect in ("drift", "sample_and_hold"):
        case = make_field_case((effect,), 4)
        d = _diagnose(case, flow=False)
        simulated = dg.simulate_effects(case.reference, case.ts, d.final.params)
        np.testing.assert_allclose(simulated, d.final.prediction, atol=1e-9)


@pytest.mark.slow
def test_one_hour_drive_cycle_recording_performance() -> None:
    case = make_field_case(("flow_dependence",), 3, duration=3600.0)
    start, cpu = time.perf_counter(), time.process_time()
    d = _diagnose(case, flow=True)
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    # printed, not asserted (the 2-core machine is shared)
    print(
        f"\none-hour 10 Hz drive-cycle recording with its flow ({case.measured.size} samples) "
        f"diagnosed in {elapsed:.2f} s ({cpu:.2f} s CPU); found {d.effects}"
    )
    assert d.effects == ["flow_dependence"]
