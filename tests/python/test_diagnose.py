"""The discrepancy workflow (issue 5) on recordings with hidden effects.

The data come from `hidden_effects.py`, a generator written independently of the workflow and
richer than its catalogue (multi-node heat conduction, direction-dependent convection, continuous
transport delay, Callendar-Van Dusen read through linear alpha, off-grid gas changes, a lagging
noisy reference). The workflow is never told what was hidden.
"""

from __future__ import annotations

import itertools
import json
import math
import time
from pathlib import Path

import numpy as np
import pytest

from dualprobe import diagnose as dg
from dualprobe.io import EstimationError
from dualprobe.models import noise
from hidden_effects import (
    CATALOGUE,
    GasSegments,
    HiddenCase,
    conduction_chain,
    make_case,
    simulate_chain,
)

# 20-40 minute records: each holds 8-30 gas changes, enough for every effect at realistic size.
DURATIONS = (1200.0, 1800.0, 2400.0)


def _run(
    effects: tuple[str, ...], seed: int, duration: float | None = None
) -> tuple[dg.Diagnosis, HiddenCase]:
    case = make_case(effects, seed, duration=duration or DURATIONS[seed % 3])
    return dg.diagnose(case.reference, case.measured, case.ts), case


def _explain(d: dg.Diagnosis, case: HiddenCase) -> str:
    rounds = [s.candidates for s in d.steps] + [d.last_round]
    return f"truth {case.truth}; found {d.effects}; rounds {rounds}"


# --- building blocks ----------------------------------------------------------------------


def test_generator_integrator_is_exact_for_an_off_grid_step() -> None:
    gas = GasSegments(
        np.array([0.0, 1.234]),
        np.array([1.234, 1e6]),
        np.array([100.0, 150.0]),
        np.array([100.0, 150.0]),
    )
    t = np.arange(0.0, 30.0, 0.1)
    out = simulate_chain(conduction_chain([1.0], [], 1.0 / 5.0), gas, t, 100.0)
    exact = np.where(t < 1.234, 100.0, 150.0 - 50.0 * np.exp(-(t - 1.234) / 5.0))
    # closed-form transition matrices: only rounding error remains
    np.testing.assert_allclose(out, exact, atol=1e-9)


def test_hysteretic_python_loop_is_the_zoh_recursion() -> None:
    ts, tau_heat, tau_cool = 0.1, 4.0, 6.0
    gas = np.concatenate((np.full(300, 200.0), np.full(300, 100.0)))
    out = dg.hysteretic_first_order(gas, ts, tau_heat, tau_cool, 100.0)
    k = np.arange(300)
    heat = 200.0 - 100.0 * np.exp(-k * ts / tau_heat)
    top = 200.0 - 100.0 * math.exp(-300 * ts / tau_heat)
    cool = 100.0 + (top - 100.0) * np.exp(-k * ts / tau_cool)
    # constant direction within each half: the recursion is the exact ZOH exponential
    np.testing.assert_allclose(out, np.concatenate((heat, cool)), rtol=0, atol=1e-9)


def test_hysteretic_core_matches_python_loop(rng: np.random.Generator) -> None:
    gas = np.cumsum(rng.normal(0.0, 1.0, 5000)) + 200.0
    python = dg.hysteretic_first_order(gas, 0.1, 3.0, 4.5, 190.0)
    core = dg.simulate_hysteretic(gas, 0.1, 3.0, 4.5, 190.0)
    # same recursion in double precision: agreement to rounding
    np.testing.assert_allclose(core, python, rtol=0, atol=1e-9)


def test_linear_model_is_exact_for_piecewise_linear_input() -> None:
    ts, tau, tau2 = 0.1, 5.0, 0.8
    t = np.arange(0.0, 60.0, ts)
    ramp = np.clip(t - 2.0, 0.0, None) * 3.0 + 100.0  # knot on the grid
    out = dg.simulate_effects(ramp, ts, {"tau": tau, "initial": 100.0})
    s = np.clip(t - 2.0, 0.0, None)
    exact = 100.0 + 3.0 * (s - tau * (1.0 - np.exp(-s / tau)))
    # first-order hold is the exact discretisation for a linearly interpolated input
    np.testing.assert_allclose(out, exact, atol=1e-9)
    two = dg.simulate_effects(ramp, ts, {"tau": tau, "tau2": tau2, "initial": 100.0})
    # two-pole ramp response: 3 (s - tau - tau2 + (tau^2 e^-s/tau - tau2^2 e^-s/tau2)/(tau - tau2))
    exact2 = 100.0 + 3.0 * (
        s - (tau + tau2) + (tau**2 * np.exp(-s / tau) - tau2**2 * np.exp(-s / tau2)) / (tau - tau2)
    )
    # the cascade interpolates the smooth intermediate linearly: O(ts^2 / tau2) error
    np.testing.assert_allclose(two, exact2, atol=3.0 * ts**2 / tau2)


def test_held_input_with_fractional_delay_is_exact() -> None:
    ts, tau, delay = 0.1, 2.0, 0.37
    rng = np.random.default_rng(5)
    held = np.repeat(rng.uniform(100.0, 300.0, 12), 25)  # staircase, changes on the grid
    held[0] = 150.0  # the rest state before the record
    t = np.arange(held.size) * ts
    params = {"tau": tau, "initial": 150.0, "delay": delay, "input_hold": 1.0}
    out = dg.simulate_effects(held, ts, params)
    # the same staircase, delayed, as continuous gas through the generator's exact integrator
    starts = np.concatenate(([0.0], t[1:] + delay))
    ends = np.concatenate((starts[1:], [1e6]))
    gas = GasSegments(starts, ends, held.copy(), held.copy())
    gas.v0[0] = gas.v1[0] = 150.0
    exact = simulate_chain(conduction_chain([1.0], [], 1.0 / tau), gas, t, 150.0)
    # exact discretisation of a held, fractionally delayed input: rounding only
    np.testing.assert_allclose(out, exact, atol=1e-9)


def test_static_map_and_delay() -> None:
    ts = 0.1
    u = np.concatenate((np.full(50, 100.0), np.full(200, 300.0)))
    p = {
        "tau": 1e-3,
        "initial": 100.0,
        "delay": 0.25,
        "gain": 1.02,
        "offset": 0.5,
        "curvature": -1.5e-4,
    }
    out = dg.simulate_effects(u, ts, p)
    x = 300.0
    # static map y = offset + gain x + curvature x (x - 100) after the step has passed
    assert out[-1] == pytest.approx(0.5 + 1.02 * x - 1.5e-4 * x * (x - 100.0), abs=1e-9)
    # the step (between samples 49 and 50) arrives 2.5 samples later: untouched up to sample
    # 51, half-way (interpolated) at 52, complete from 54 (the 1 ms lag is a step itself)
    assert out[51] == pytest.approx(0.5 + 1.02 * 100.0, abs=1e-9)
    assert 0.5 + 1.02 * 100.0 < out[52] < out[53] < out[54]
    assert out[54] == pytest.approx(out[-1], abs=1e-9)


def test_noise_std_of_a_smooth_signal(rng: np.random.Generator) -> None:
    t = np.arange(20000) * 0.1
    smooth = 200.0 + 50.0 * np.sin(2 * np.pi * t / 300.0)
    signal = smooth + rng.normal(0.0, 0.07, t.size)
    estimate = noise.estimate_noise_std(signal, noise.ORDER_DIAGNOSE)
    # MAD of 20000 second differences: ~1 % standard error; 5 % bound
    assert estimate == pytest.approx(0.07, rel=0.05)


# --- the workflow ---------------------------------------------------------------------------


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_first_order_sensor_gets_no_effect(seed: int) -> None:
    d, case = _run((), seed)
    assert d.effects == [], _explain(d, case)
    truth_tau = case.truth["tau"]
    # baseline recovers tau: off-grid steps and reference noise bias it by well under 2 %
    assert d.baseline.params["tau"] == pytest.approx(truth_tau, rel=0.02)


def test_held_input_data_are_recognised_and_get_no_effect() -> None:
    # the paper's eq. 8 with the gas samples held: no sub-sample timing to guess; modelled as
    # interpolated it would look like half a sample of dead time
    rng = np.random.default_rng(8)
    ts, tau, n = 0.1, 1.5, 12000
    gas = np.repeat(rng.uniform(60.0, 340.0, n // 100 + 1), 100)[:n]
    a = math.exp(-ts / tau)
    sensor = np.empty(n)
    sensor[0] = gas[0]
    for k in range(1, n):
        sensor[k] = a * sensor[k - 1] + (1.0 - a) * gas[k - 1]
    d = dg.diagnose(gas + rng.normal(0, 0.07, n), sensor + rng.normal(0, 0.07, n), ts)
    assert d.effects == []
    assert d.baseline.params["input_hold"] == 1.0
    # exact model: only noise is left (reference noise through the sensor adds ~4 %)
    assert d.final.rmse == pytest.approx(0.07, rel=0.1)


@pytest.mark.parametrize(("effect", "seed"), list(itertools.product(CATALOGUE, (11, 12))))
def test_single_hidden_effect_is_named(effect: str, seed: int) -> None:
    d, case = _run((effect,), seed)
    assert d.effects == [effect], _explain(d, case)
    assert d.final.rmse <= 0.5 * d.baseline.rmse
    # the ladder is monotone and ends at the final model
    assert d.steps[-1].rmse_after == pytest.approx(d.final.rmse)
    assert all(s.rmse_after < s.rmse_before for s in d.steps)


def test_named_effect_parameters_are_close_to_the_hidden_ones() -> None:
    d, case = _run(("dead_time",), 21)
    truth = case.truth
    # continuous transport delay, reference lags 10-40 ms: within 0.1 s
    assert d.steps[0].params["delay"] == pytest.approx(truth["delay"], abs=0.1)
    d, case = _run(("gain", "offset"), 22)
    truth = case.truth
    params = d.final.params
    # the generator adds the offset to the element before the gain: y = gain (x + offset); gain
    # and offset trade off against each other, the map itself is fixed by the data: compare it
    # over the range of levels, within 0.2 K (the residue of jumps between samples and of the
    # lagging reference biases it by ~0.1 K here; 0.2 K is under half the smallest realistic
    # offset, 1/20 of the 2 % gain error over this range)
    levels = np.quantile(case.measured, [0.05, 0.5, 0.95])
    fitted = params["offset"] + params["gain"] * levels
    np.testing.assert_allclose(fitted, truth["gain"] * (levels + truth["offset"]), atol=0.2)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("effects", "seed"),
    [(pair, 31 + i) for i, pair in enumerate(itertools.combinations(CATALOGUE, 2))],
)
def test_pair_of_hidden_effects_is_named(effects: tuple[str, str], seed: int) -> None:
    d, case = _run(effects, seed, duration=1200.0)  # 20 min: 6-20 gas changes
    assert sorted(d.effects) == sorted(effects), _explain(d, case)
    assert d.final.rmse <= 0.5 * d.baseline.rmse


def test_json_document_has_the_issue_schema() -> None:
    d, _ = _run(("extra_pole",), 41)
    doc = json.loads(json.dumps(d.to_json_dict(), allow_nan=False))
    # issue 5's document; issue 14 added the verdict, the noise, the remaining misfit, the final
    # parameters and the units of every parameter; the loader's notes (empty here) came with
    # jittered and bridged field records
    assert set(doc) == {"baseline", "steps", "effects", "final_rmse", "residual_white"} | {
        "verdict",
        "misfit_to_noise",
        "summary",
        "noise",
        "misfit",
        "final_params",
        "notes",
    }
    assert doc["notes"] == []
    assert set(doc["baseline"]) == {"model", "params", "rmse", "fit_percent", "units"}
    assert doc["baseline"]["model"] == "first_order"
    assert set(doc["baseline"]["params"]) == {"tau", "initial"}  # interpolated input
    assert doc["effects"] == [s["effect"] for s in doc["steps"]] == ["extra_pole"]
    for step in doc["steps"]:
        assert set(step) == {
            *("effect", "params", "rmse_before", "rmse_after", "evidence", "where", "units")
        }
        assert step["effect"] in dg.EFFECTS
        assert step["evidence"]["significant"] is True
        assert step["evidence"]["p_value"] < dg.SIGNIFICANCE_LEVEL
        assert step["evidence"]["gap_closed"] >= dg.MIN_GAP_CLOSED
        assert step["where"], "the disagreement is localised"
        for window in step["where"]:
            assert window["start"] <= window["end"]
            assert window["rms_after"] < window["rms_before"]
    assert set(doc["steps"][0]["params"]) == {"tau", "tau2"}
    assert doc["final_rmse"] == pytest.approx(doc["steps"][-1]["rmse_after"])
    assert isinstance(doc["residual_white"], bool)


def test_final_parameters_reproduce_the_final_simulation() -> None:
    d, case = _run(("hysteresis", "offset"), 42)
    simulated = dg.simulate_effects(case.reference, case.ts, d.final.params)
    np.testing.assert_allclose(simulated, d.final.prediction, atol=1e-9)


def test_localisation_points_at_heating_and_cooling_asymmetry() -> None:
    d, case = _run(("hysteresis",), 43)
    truth = case.truth
    signature = d.localisation["signatures"]
    # the baseline's single tau lies between tau_heat and tau_cool: the sensor is ahead of it
    # in the faster direction and behind in the slower one
    faster_heating = truth["tau_heat"] < truth["tau_cool"]
    assert (signature["lead_heating"] > 0) == faster_heating
    assert (signature["lead_cooling"] > 0) != faster_heating
    assert d.tests_baseline["white"] is False
    assert d.localisation["windows"]


def test_report_files_exist(tmp_path: Path) -> None:
    d, _ = _run(("nonlinearity",), 44)
    report = d.write_report(tmp_path)
    text = report.read_text()
    for name in dg.FIGURES.values():
        path = report.parent / name
        assert path.stat().st_size > 1000, name
        assert f"({name})" in text
    assert "| + nonlinearity |" in text  # the ladder table


def test_bad_arrays_raise_value_error() -> None:
    good = np.linspace(100.0, 200.0, 200)
    with pytest.raises(ValueError, match="samples"):
        dg.diagnose(good, good[:-1], 0.1)
    bad = good.copy()
    bad[17] = np.nan
    with pytest.raises(ValueError, match="sample 17"):
        dg.diagnose(good, bad, 0.1)
    with pytest.raises(ValueError, match="at least"):
        dg.diagnose(good[:10], good[:10], 0.1)
    with pytest.raises(ValueError, match="sample interval"):
        dg.diagnose(good, good, -0.1)


def test_no_excitation_is_an_estimation_error(rng: np.random.Generator) -> None:
    flat = 200.0 + rng.normal(0.0, 0.05, 3000)
    with pytest.raises(EstimationError, match="cannot be identified"):
        dg.diagnose(flat, flat + rng.normal(0.0, 0.05, 3000), 0.1)


@pytest.mark.slow
def test_one_hour_recording_performance() -> None:
    case = make_case(("extra_pole", "hysteresis"), 51, duration=3600.0)
    start, cpu = time.perf_counter(), time.process_time()
    d = dg.diagnose(case.reference, case.measured, case.ts)
    elapsed, cpu = time.perf_counter() - start, time.process_time() - cpu
    # the claim (<= 5 s on the 2-core machine) is printed, not asserted: shared-load dependent
    print(
        f"\none-hour 10 Hz recording ({case.measured.size} samples) diagnosed in "
        f"{elapsed:.2f} s ({cpu:.2f} s CPU); found {d.effects}"
    )
    assert sorted(d.effects) == ["extra_pole", "hysteresis"]
