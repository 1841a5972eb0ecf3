"""A lag common to both sensors (equal sheaths) cancels from a pair's cross-relation: the pair
explains both signals without it, and the gas it reconstructs is the gas as seen through that
lag. The summary must say so beside the bandwidth it states, since ``T_g_std`` cannot cover it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import scipy.signal

from common_lag_study import worlds
from dualprobe import simulate as sim
from dualprobe.cli import main
from dualprobe.estimation.settings import GAP_THRESHOLD
from dualprobe.io import EstimationError, write_columns
from dualprobe.workflows.characterisation import Characterisation
from dualprobe.workflows.characterise import characterise_arrays
from field_independent import record
from field_oracle import at_level, common_part_error, oracle, schedule_blame, through_stage
from test_field_conditions import ADC, DURATION, NOISE, RATE


def test_the_stage_helper_is_scipy_s_first_order_hold_response() -> None:
    """The studies' stage (field_oracle.through_stage) against scipy.signal.lsim, which
    interpolates the input linearly between samples too, at a constant time constant."""
    rng = np.random.default_rng(7)
    t = np.arange(0.0, 30.0, 0.05)
    u = np.cumsum(rng.normal(0.0, 1.0, t.size))
    tau = 0.4
    stage = scipy.signal.StateSpace(-1.0 / tau, 1.0 / tau, 1.0, 0.0)  # its state the output
    _, expected, _ = scipy.signal.lsim(stage, u, t, X0=[u[0]])
    # both exact for an input linear between rows: agreement to rounding, scaled to the input
    assert np.max(np.abs(through_stage(t, u, np.full(t.size, tau)) - expected)) < 1e-9 * np.ptp(u)


def test_the_shared_sheath_part_is_the_smaller_sheath_on_every_row() -> None:
    rng = np.random.default_rng(8)
    t = np.arange(0.0, 60.0, 0.1)
    gas = np.cumsum(rng.normal(0.0, 0.3, t.size))
    s1 = 0.3 + 0.2 * np.sin(t / 5.0)
    s2 = np.full(t.size, 0.35)
    seen = through_stage(t, gas, np.minimum(s1, s2))
    assert common_part_error(t, gas, s1, s2) == pytest.approx(
        float(np.sqrt(np.mean((seen - gas) ** 2))), rel=1e-12)
    assert common_part_error(t, gas, s1, None) == 0.0  # nothing shared without a second sheath


def test_the_blame_falls_on_the_part_of_the_estimate_that_is_off() -> None:
    """field_oracle.schedule_blame: the oracle given the estimate's stages on the true schedule,
    and the true stages on the estimate's schedule. Where one part is the truth, its half of
    the decomposition is the oracle itself and the other half carries the error."""
    rec = record(9, duration=300.0, tau=4.0, ratio=3.0, m=0.5, sheaths=(0.4, 0.6))
    truth = (rec.tau1, rec.tau2, rec.sheath1, rec.sheath2)
    sigma = (rec.noise, rec.noise)
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, sigma,
                  sheath1=rec.sheath1, sheath2=rec.sheath2, gases=("rw",)).rmse
    psi = at_level(rec.tau1) / rec.tau1  # the true schedule, mean log 0

    stages = ((at_level(rec.tau1), at_level(rec.sheath1)),
              (at_level(rec.tau2), at_level(rec.sheath2)))
    unit = (1.0, 0.0)
    # The per-row constants rebuilt from levels and psi equal the truth's to rounding (2e-16),
    # but the oracle's search for its intensity q compares RMSEs that are flat at the optimum:
    # a 1e-15 change of one sensor's constants moved its RMSE by 6e-5 (measured). So 1e-3.
    same = 1e-3
    # the truth as the estimate: both halves the oracle
    for half in schedule_blame(rec.t, rec.t1, rec.t2, rec.gas, truth, sigma, unit, stages,
                               psi, unit):
        assert half == pytest.approx(best, rel=same)
    # a schedule with half the truth's swing in log (a smeared MAP psi does that where the load
    # changes fast): the stages' half unmoved
    wrong = np.sqrt(psi)
    ours_on_true, true_on_ours = schedule_blame(rec.t, rec.t1, rec.t2, rec.gas, truth, sigma,
                                                unit, stages, wrong, unit)
    assert ours_on_true == pytest.approx(best, rel=same)
    # measured 4.66x; 2x keeps it far from the untouched half's 1 (the record's first 5 min:
    # psi 0.92-2.77 over an idle start and a pull-away, the gas over 244 K)
    assert true_on_ours > 2.0 * best, true_on_ours / best
    # the sheaths left out (a first-order estimate) on the true schedule: the schedule's half
    # unmoved
    short = ((stages[0][0],), (stages[1][0],))
    ours_on_true, true_on_ours = schedule_blame(rec.t, rec.t1, rec.t2, rec.gas, truth, sigma,
                                                unit, short, psi, unit)
    assert true_on_ours == pytest.approx(best, rel=same)
    # measured 1.67x: the 0.4 s both share is not undone (beside the 1e-3 of an untouched half)
    assert ours_on_true > 1.3 * best, ours_on_true / best


def test_a_common_sheath_is_not_undone_and_the_summary_says_so() -> None:
    sheath = 0.5  # s at the reference velocity, on both sensors (0.8 Hz)
    rng = np.random.default_rng(4242)
    conditions = sim.drive_cycle(DURATION / 2, rng)
    s1 = sim.FieldSensor(4.0, 0.5, sheath, noise_std=NOISE)
    s2 = sim.FieldSensor(12.0, 0.5, sheath, noise_std=NOISE)
    rec = sim.simulate_field_pair(conditions, s1, s2, sample_rate=RATE, quantisation=ADC,
                                  rng=rng)
    assert np.allclose(rec.sheath1, rec.sheath2)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother",
                                 flow=rec.flow, flow_column="flow")
    assert result.gas_estimate is not None and result.model_check is not None
    seen = through_stage(rec.t, rec.tg, rec.sheath1)
    to_gas = float(np.sqrt(np.mean((result.gas_estimate - rec.tg) ** 2)))
    to_seen = float(np.sqrt(np.mean((result.gas_estimate - seen) ** 2)))
    # the pair sees the gas through the common sheath: measured 0.29 K from that, 4.82 K from
    # the gas (the oracle, given the sheaths: 1.02 K), the model check content (misfit 0.93);
    # a fifth leaves room for other draws while no estimate of the gas itself could pass
    assert to_seen < 0.2 * to_gas, (to_seen, to_gas)
    assert result.model_check.adequate
    assert "a lag common to both sensors" in result.summary()


def test_equal_sheaths_put_the_no_flow_bound_out_of_reach() -> None:
    """Issue 11 asks, without a flow signal, for a gas within 2.5x the oracle's error on pairs
    with and without sheaths. Two worlds of the separate generator (field_independent.py):
    A, a pair with equal sheaths of 0.55 s; B, the same drive cycle and noise with both sheaths
    moved into the gas (an unsheathed pair seeing a smoother gas). Their readings are the same,
    so any estimator returns one gas for both, its errors in A and B add up to at least the
    distance D between the worlds' gases, and it can be within 2.5x both oracles only if
    D <= 2.5 (o_A + o_B). Here D exceeds that: the bound is unattainable for equal sheaths
    (tests/python/common_lag_study.py, case 9003)."""
    found = worlds(9003)
    # the noise-free readings of the two worlds differ by the integrator's rounding only: a
    # chi-square far below 1 against the noise, so no test on the data can tell them apart
    assert found.chi2 < 0.01, found.chi2
    distance, oracles = found.distance, found.oracles
    # measured D 5.17 K, oracles 1.16 and 0.24 K: D / (o_A + o_B) 3.67; 2.5 is the issue's
    # factor itself, no margin is taken from it
    assert distance > 2.5 * sum(oracles), (distance, oracles)


def test_equal_sheaths_put_the_flow_bound_out_of_reach() -> None:
    """With the flow, issue 11 asks for a gas within 1.5x the oracle's error, sheathed pairs
    included. The two worlds of the test above have the same mass flow as well as the same
    readings (the flow follows the engine's load, not the sheaths), so the flow column does
    not tell them apart either: the bound holds in both only if D <= 1.5 (o_A + o_B). Case
    9002 is at the issue's nominal conditions (10 Hz, 0.05 K, 0.02 K steps) with equal
    sheaths of 0.3 s, the smallest D / (o_A + o_B) of the equal-sheath cases studied (README,
    "The common-lag limit, tested")."""
    found = worlds(9002)
    assert found.chi2 < 0.01, found.chi2  # readings identical but for the rounding
    np.testing.assert_array_equal(found.a.mass_flow, found.b.mass_flow)
    distance, oracles = found.distance, found.oracles
    # measured D 3.22 K, oracles 1.18 and 0.41 K: D / (o_A + o_B) 2.03; 1.5 is the issue's
    # factor itself, no margin is taken from it
    assert distance > 1.5 * sum(oracles), (distance, oracles)


def _with_mass_flow(case: int, **kw: Any) -> Characterisation:
    rec = record(case, rate=10.0, **kw)
    return characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                               flow_column="mdot", reconstruction="smoother")


_CASE_8301 = {"tau": 5.45, "ratio": 3.13, "m": 0.58, "sheaths": (0.44, 0.52)}


def test_near_equal_sheaths_the_law_mis_sizes_fall_back_to_first_order() -> None:
    """Near-equal sheaths (0.44 / 0.52 s, 10 Hz, 20 min, the mass flow as the column; sweep
    case 8301 of field_sweep_independent.py) on the separate generator. The law is within
    0.34 % RMS of the true schedule in log, yet order 2 sized the sheaths 1.72 / 1.84 s
    (given the true schedule: 0.44 / 0.53 s) at a misfit of 1.15 times the noise, within the
    band, and the gas came out 4.77x the oracle with the model called adequate. Split by flow
    that model misfits the high-flow half (1.56, the low-flow half 0.83: 12.3 standard
    deviations apart): its stages' common part took up the law's error, so the order chosen
    by evidence is first order (checks.regime_shared_stage), still warned."""
    rec = record(8301, rate=10.0, **_CASE_8301)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                                 flow_column="mdot", reconstruction="smoother")
    assert [len(taus) for taus in result.estimate.time_constants] == [1, 1]
    assert "high-flow halves unalike" in result.estimate.identifiability["order_fallback"]
    assert result.model_check is not None and not result.model_check.adequate
    assert result.gas_estimate is not None
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  sheath1=rec.sheath1, sheath2=rec.sheath2, gases=("rw",)).rmse
    error = float(np.sqrt(np.mean((result.gas_estimate - rec.gas) ** 2)))
    # measured 2.49x (order 2: 4.77x); 3.5x fails if order 2 or anything like it comes back,
    # and near-equal sheaths put the 1.5x out of reach (the tests above)
    assert error < 3.5 * best, (error, best)


def test_asked_for_order_2_with_near_equal_stages_the_law_mis_sizes_is_refused() -> None:
    """With --order 2 the same pair gets no number (exit 3): its sheaths are not identified
    (issue 11: the sheath stage identified when present, or a clean exit 3)."""
    rec = record(8301, rate=10.0, **_CASE_8301)
    with pytest.raises(EstimationError, match="high-flow halves unalike"):
        characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                            flow_column="mdot", order=2)


def test_near_equal_sheaths_sized_long_where_the_split_cannot_see_it_fall_back() -> None:
    """0.42 / 0.45 s sheaths (near_equal_sweep.py 201, case 20107; 10 Hz, 20 min, the mass flow
    as the column): order 2 sized them 1.78 / 1.86 s (jackknife 22 %), the misfit 1.13, the flow
    halves 2.9 standard deviations apart, and the gas 8.3x the oracle's error was called
    adequate with T_g_std a sixth of it. Moving the common part by its standard uncertainty
    moves the gas by 5.4 times T_g_std (resolved near-equal pairs: 0.59-0.84). That was
    doubted (9.95 K off, warned); now the order chosen by evidence is first order there
    (3.76 K), warned, with half the distance to the order-2 gas in T_g_std."""
    rec = record(20107, rate=10.0, tau=4.03, ratio=3.09, m=0.37, sheaths=(0.42, 0.45))
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                                 flow_column="mdot", reconstruction="smoother")
    assert [len(taus) for taus in result.estimate.time_constants] == [1, 1]
    fallback = str(result.estimate.identifiability["order_fallback"])
    assert "common part is not determined" in fallback
    check = result.model_check
    assert check is not None and not check.adequate
    assert any(r.startswith("first order was taken where the second-order fit's common part")
               for r in check.reasons)
    assert result.gas_estimate is not None and result.gas_std is not None
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  sheath1=rec.sheath1, sheath2=rec.sheath2, gases=("rw",)).rmse
    error = result.gas_estimate - rec.gas
    # measured 3.1x (order 2: 8.3x); as for case 8301 above, near-equal sheaths put the
    # issue's 1.5x out of reach and 3.5x fails if order 2 comes back
    assert float(np.sqrt(np.mean(error ** 2))) < 3.5 * best
    z = float(np.sqrt(np.mean((error / result.gas_std) ** 2)))
    # measured 1.5 (first order's own T_g_std: 12.1); 3 is the sweeps' mark of an
    # overconfident result (logger_sweep.py: 1.8-2.2 where the gas beyond the bandwidth is the
    # only thing uncovered)
    assert z < 3.0, z


def test_the_command_line_judges_the_common_part_without_being_asked_for_the_gas(
        tmp_path: Path) -> None:
    """The same pair through the command line with --json only: one verdict per record, not
    "adequate" without --output and doubted with it (the model check needs the gas)."""
    rec = record(20107, rate=10.0, tau=4.03, ratio=3.09, m=0.37, sheaths=(0.42, 0.45))
    data, doc = tmp_path / "pair.csv", tmp_path / "out.json"
    write_columns(data, {"t": rec.t, "T1": rec.t1, "T2": rec.t2, "mdot": rec.mass_flow})
    assert main(["characterise", str(data), "--sensor1", "T1", "--sensor2", "T2", "--flow",
                 "mdot", "--json", str(doc)]) == 0
    check = json.loads(doc.read_text())["model_check"]
    assert not check["adequate"]
    assert any("common part is not determined" in r for r in check["reasons"])


@pytest.mark.parametrize("case,kw", [
    (8300, {"tau": 4.58, "ratio": 2.09, "m": 0.55, "sheaths": (0.41, 0.35),
            "gains": (0.992, 1.006)}),
    (62000, {"duration": 900.0, "tau": 5.46, "ratio": 3.5, "m": 0.61, "sheaths": (0.69, 0.85)}),
])
def test_resolved_sheaths_fit_both_flow_halves_alike(case: int, kw: dict[str, Any]) -> None:
    """Sheaths the law sizes right (1.02x the oracle): measured 2.7 and 0.5 standard
    deviations between the halves (62000 before the level term was found again on the
    reconstruction: 6.5, which is why the split is judged on the final law)."""
    result = _with_mass_flow(case, **kw)
    model = result.estimate.flow_model
    assert model is not None and model.evidence["flow_split_statistic"] < GAP_THRESHOLD
    assert result.model_check is not None and result.model_check.adequate


@pytest.mark.parametrize("case,kw", [
    (10405, {"tau": 5.37, "ratio": 2.24, "m": 0.5, "sheaths": (0.65, 0.66),
             "gains": (1.02, 1.009)}),
    (10403, {"rate": 20.0, "tau": 7.12, "ratio": 3.74, "m": 0.61, "sheaths": (0.43, 0.38),
             "gains": (1.002, 1.022)}),
])
def test_a_lone_faint_stage_is_read_as_near_equal_sheaths(case: int, kw: dict[str, Any]) -> None:
    """Near-equal sheaths with the gas velocity as the column (field_sweep_independent.py 104
    velocity; no gas-level term to hint at a common stage): the pair came out with one second
    stage of 0.009 s (10 Hz) or 0.056 s (20 Hz) on one sensor, the sheaths' difference, the
    signals explained and the gas 5.03x / 2.08x the oracle, called adequate. A lone stage that
    short is no sheath (checks.FAINT_STAGE): the result is doubted, the signals still fit."""
    gains = kw["gains"]
    rec = record(case, **{"rate": 10.0, **kw})
    velocity = rec.mass_flow * rec.gas / gains[0]  # rec.gas is in sensor 1's calibration
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=velocity,
                                 flow_column="velocity", reconstruction="smoother")
    assert sorted(len(taus) for taus in result.estimate.time_constants) == [1, 2]
    check = result.model_check
    assert check is not None and not check.adequate and check.fits
    assert any("nearly equal sheaths on both sensors" in r for r in check.reasons)
    # the header names a doubt, not a misfit (and never "ok")
    assert result.summary().splitlines()[1].endswith(": signals fit, result doubtful")


_IDLE = {"duration": 120.0, "rate": 50.0, "tau": 0.71, "ratio": 2.84, "m": 0.61,
         "gains": (1.012, 1.016), "noise": 0.05, "adc": 0.1}


@pytest.mark.parametrize("sheaths", [(0.23, 0.5), (0.0, 0.0)])
def test_a_first_order_pair_says_its_time_constants_leave_a_common_lag_open(
        sheaths: tuple[float, float]) -> None:
    """logger_sweep.py 121 short, case 121007: 120 s at idle (the flow within 2 %), 50 Hz.
    With 0.23 / 0.5 s sheaths the data are explained at first order (misfit 1.19 x the noise,
    0.98 without the ADC steps) by 0.335 / 1.874 s, where the elements are 0.71 / 2.0 s: both
    sensors' total lags (0.94 / 2.5 s) short by one amount, 0.61 / 0.63 s, as the second-order
    expansion of a sheathed pair's cross-relation has it (order_choice.common_lag_note). The
    summary must say what these time constants are beside their small +-; unsheathed, the
    same record gives the elements."""
    rec = record(121007, sheaths=sheaths, **_IDLE)  # type: ignore[arg-type]
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction=None)
    assert result.estimate.order == 1
    fast, slow = (taus[0] for taus in result.estimate.time_constants)
    totals = [float(np.median(tau + sheath)) for tau, sheath in
              ((rec.tau1, rec.sheath1), (rec.tau2, rec.sheath2))]
    short = [totals[0] - fast, totals[1] - slow]
    # the shortfall is common: its difference is the expansion's third-order rest (measured
    # 0.02 s on 0.6 s; 0.1 s is a sixth of it), and it is the sheaths' size, not noise
    assert abs(short[0] - short[1]) < 0.1, short
    if any(sheaths):
        assert min(short) > 0.4, short
    else:
        # unsheathed: the elements themselves (measured within 0.5 %; the jackknife's +- is 2 %)
        assert max(abs(s) / t for s, t in zip(short, totals, strict=True)) < 0.05, short
    note = result.estimate.identifiability["common_lag"]
    assert f"({abs(slow - fast):.3g} s), never a lag common to both sensors" in note
    summary = result.summary()
    assert "note: first order: two signals determine at most the time constants'" in summary


def test_with_the_velocity_a_first_order_pair_is_short_by_one_common_lag() -> None:
    """logger_sweep.py's short draws, seed 131, case 2 (120 s at 50 Hz, 2.13 / 10.7 s
    elements behind 0.35 / 0.36 s sheaths, m 0.63, sensor 2 held for 3 rows, 10 ms jitter):
    with the gas velocity, a first-order power law whose per-row time constants are 0.39 /
    0.42 s short of the totals (common to 0.03 s, as the note says); without it, tracked, the
    totals over the estimates were 1.28 / 1.13 and the note names the schedule's error."""
    kw = {"duration": 120.0, "rate": 50.0, "tau": 2.13, "ratio": 5.0, "m": 0.63,
          "sheaths": (0.35, 0.36), "gains": (1.01, 1.022), "noise": 0.05, "adc": 0.0,
          "jitter": 0.01, "hold": 3}
    rec = record(131002, **kw)  # type: ignore[arg-type]
    velocity = rec.mass_flow * rec.gas / 1.01  # rec.gas is in sensor 1's calibration
    for flow in (velocity, None):
        result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction=None,
                                     flow=flow, flow_column="velocity" if flow is not None
                                     else None)
        model = result.estimate.flow_model
        assert result.estimate.order == 1 and model is not None
        note = result.estimate.identifiability["common_lag"]
        assert ("tracked without the flow" in note) == (flow is None)
        if flow is None:
            assert model.kind == "tracked"
            continue
        assert model.kind == "power_law"
        short = [float(np.median(tau + sheath - taus[0] * model.psi)) for tau, sheath, taus in
                 ((rec.tau1, rec.sheath1, result.estimate.time_constants[0]),
                  (rec.tau2, rec.sheath2, result.estimate.time_constants[1]))]
        # the sheaths' size (delta = 0.36 s by the expansion) common to both; the difference
        # is the expansion's rest and the law's error (measured 0.03 s; 0.1 s, a quarter)
        assert min(short) > 0.25 and abs(short[0] - short[1]) < 0.1, short


def test_unlike_stages_that_share_a_common_part_fall_back_to_first_order() -> None:
    """Sheaths that follow the flow otherwise than the elements (0.54 / 0.61 s with exponents
    0.44 / 0.52 on 1.54 / 3.88 s elements with 0.47; test_field_conditions.py's 5107 at 2 Hz
    instead of 10): the order-2 fit sized stages of 4.0 + 1.4 s and 5.0 + 3.1 s, not alike
    enough for the near-equal checks (20.3 % apart, ``SHARED_FACTOR`` 20 %), a common lag of
    3.7 s where the pair's is 0.6 s; misfit 0.98 and the flow halves alike, the gas 21.8 K off
    where the raw fast sensor is 13 K, called adequate (its error 8.2 times T_g_std). One
    standard uncertainty of the stages' common part moves the gas beyond what T_g_std stated:
    that was doubted (the gas still 21.8 K off); now first order (5.4 K), warned."""
    rng = np.random.default_rng(5107)
    conditions = sim.drive_cycle(DURATION, rng)
    s1 = sim.FieldSensor(1.54, 0.47, 0.54, sheath_exponent=0.44, noise_std=0.072)
    s2 = sim.FieldSensor(3.88, 0.47, 0.61, sheath_exponent=0.52, noise_std=0.072)
    rec = sim.simulate_field_pair(conditions, s1, s2, sample_rate=2.0, rng=rng)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow")
    assert [len(taus) for taus in result.estimate.time_constants] == [1, 1]
    check = result.model_check
    assert check is not None and not check.adequate
    assert any("common part is not determined" in r for r in check.reasons)
    assert result.gas_estimate is not None and result.gas_std is not None
    error = result.gas_estimate - rec.tg
    raw = float(np.sqrt(np.mean((rec.t1 - rec.tg) ** 2)))
    # measured 5.4 K against the raw fast sensor's 13.0 K (order 2: 21.8 K, worse than raw)
    assert float(np.sqrt(np.mean(error ** 2))) < 0.5 * raw
    # measured 1.4 (8.2 with order 2 undoubted, 3.6 doubted)
    assert float(np.sqrt(np.mean((error / result.gas_std) ** 2))) < 3.0


def test_a_lone_second_stage_says_the_common_lag_is_open() -> None:
    """2 Hz, 300 s, 4.3 / 11.7 s elements behind 0.72 / 0.49 s sheaths (logger_sweep.py 133 8,
    case 133004), the mass flow: one second stage of 0.16 s on one sensor, the sheaths'
    difference; the lag both share is unseen and the gas comes out late by it (0.35 s,
    1.97x the oracle, its error 8.9 times T_g_std), called adequate like any first-order
    pair. Like them it now says what its time constants leave open."""
    rec = record(133004, tau=4.34, ratio=2.7, m=0.39, rate=2.0, sheaths=(0.72, 0.49),
                 gains=(1.039, 0.971), noise=0.02, adc=0.02, hold=3, duration=300.0)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                                 flow_column="mdot")
    assert sorted(len(taus) for taus in result.estimate.time_constants) == [1, 2]
    note = str(result.estimate.identifiability["common_lag"])
    assert note.startswith("one sensor's second stage only") and "datasheet" in note
    assert "one sensor's second stage only" in result.summary()
    assert result.gas_estimate is not None
    slope = np.gradient(rec.gas, rec.ts)
    late = -float(np.dot(result.gas_estimate - rec.gas, slope) / np.dot(slope, slope))
    assert late > 0.2  # what the note says: late by a lag common to both (0.35 s measured)
