"""Issue 11 on recordings from a generator written apart from the product
(tests/python/field_independent.py: own drive trace, gas and exhaust, RK4 sensors that follow
the gas VELOCITY while the recording offers the MASS flow), against the oracle that knows the
true time-varying sensors (tests/python/field_oracle.py)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from dualprobe.estimation.confidence import SETTING_SHARE
from dualprobe.estimation.engine import Fit
from dualprobe.io import EstimationError
from dualprobe.models.held import held_share
from dualprobe.workflows import characterise as characterise_module
from dualprobe.workflows import order_choice
from dualprobe.workflows import readings as readings_module
from dualprobe.workflows.characterisation import (
    TRACKED_NOISE_STD_NOTE,
    TRACKED_STD_NOTE,
    Characterisation,
)
from dualprobe.workflows.characterise import characterise_arrays
from field_independent import Recording, record
from field_oracle import oracle


def _oracle_rmse(rec: Recording, gains: tuple[float, float] = (1.0, 1.0)) -> float:
    sheaths = [s if np.any(s > 0) else None for s in (rec.sheath1, rec.sheath2)]
    return oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  sheath1=sheaths[0], sheath2=sheaths[1], static2=(gains[1] / gains[0], 0.0),
                  gases=("rw",)).rmse


def _rmse(x: np.ndarray, y: np.ndarray) -> float:
    return float(np.sqrt(np.mean((x - y) ** 2)))


def _tau_errors(result: Characterisation, rec: Recording) -> list[float]:
    tau1, tau2 = result.time_constants_per_row()
    return [float(np.sqrt(np.mean((est / truth - 1.0) ** 2)))
            for est, truth in ((tau1, rec.tau1), (tau2, rec.tau2))]


def _with_mass_flow(rec: Recording) -> Characterisation:
    """``characterise`` with the mass flow as the flow column, the smoother's gas."""
    return characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                               flow_column="mdot", reconstruction="smoother")


def _assert_issue_bounds(result: Characterisation, rec: Recording,
                         gains: tuple[float, float] = (1.0, 1.0)) -> None:
    """Issue 11's bounds with the flow: per-row time constants within 5 % RMS, the gas within
    1.5x the oracle and 15 % of the raw fast sensor."""
    assert max(_tau_errors(result, rec)) < 0.05
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, rec.gas)
    assert ours <= 1.5 * _oracle_rmse(rec, gains)
    assert ours <= 0.15 * _rmse(rec.t1, rec.gas)


def test_mass_flow_column_meets_the_issue_bounds() -> None:
    """10 Hz, tau 4 / 12 s, m 0.5 on the velocity: with the mass flow the power law alone left
    21.7 times the noise; the level term takes it to 1.2 (per-row tau 2.2 -> 0.5 %, m 0.527;
    with sensor 1's raw reading as the level: 1.6, 0.7 %, 0.548). Any remaining misfit is
    reported, not hidden."""
    rec = record(1)
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    assert model.level_reference is not None and model.level_sensitivity < 0.0
    # the exponent in the mass flow is the velocity's once the level term carries T (issue 11:
    # m within 0.05; measured 0.027)
    assert abs(model.exponent - 0.5) < 0.05
    # issue 11: per-row time constants within 5 % RMS, the gas within 1.5x the oracle and 15 %
    # of the raw fast sensor (measured 0.7 %, 1.05x, 6 %)
    _assert_issue_bounds(result, rec)
    assert result.model_check is not None
    if not result.model_check.adequate:
        assert result.model_check.reasons  # a misfit is said, with why
    assert not any("holds its readings" in r for r in result.model_check.reasons)
    summary = result.summary()
    assert TRACKED_STD_NOTE not in summary and TRACKED_NOISE_STD_NOTE not in summary


@pytest.mark.parametrize("gains,offset", [((1.0, 1.0), 3.0), ((1.0, 1.03), 0.0)])
def test_a_gain_or_offset_between_the_sensors_keeps_the_verdict(
        gains: tuple[float, float], offset: float) -> None:
    """10 Hz, tau 4 / 12 s, m 0.5, the mass flow. The pair alone is explained (1.13 times the
    noise, 1.01x the oracle); with 3 K added to sensor 2, or its gain 1.03, the affine map's
    level term stopped at the usual level's 1.52 ("does not explain the data") although the
    sharper level gave 1.14: an offset the map removes exactly must not change the verdict.
    Measured now: 1.14 / 1.16, adequate, m 0.516, the gas 1.01x the oracle."""
    rec = record(7, gains=gains)
    result = characterise_arrays(rec.t1, rec.t2 + offset, rec.ts, time=rec.t,
                                 flow=rec.mass_flow, flow_column="mdot",
                                 reconstruction="smoother")
    assert result.estimate.details.get("static_model") == "affine"
    assert result.model_check is not None and result.model_check.adequate, (
        result.model_check.reasons)
    model = result.estimate.flow_model
    assert model is not None and abs(model.exponent - 0.5) < 0.05  # issue 11: m within 0.05
    assert max(_tau_errors(result, rec)) < 0.05  # issue 11: per-row within 5 % RMS
    assert result.gas_estimate is not None
    best = oracle(rec.t, rec.t1, rec.t2 + offset, rec.gas, rec.tau1, rec.tau2,
                  (rec.noise, rec.noise), static2=(gains[1] / gains[0], offset),
                  gases=("rw",)).rmse
    # issue 11: within 1.5x the oracle (measured 1.01x)
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * best


def test_a_fast_pair_at_a_high_rate_is_not_called_undetermined(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """100 Hz, 10 min, tau 0.3 / 0.9 s (fast thermocouples), the mass flow. Over 60 000 rows
    the time constants moved with the filter setting by 0.1 % (significant against their
    0.1 % jackknife uncertainty), and that alone called them "not identifiable" and the
    reconstruction "not reliable: the lag correction may swing by as much" at the oracle's
    accuracy (0.408 K against 0.408 K). A move is now material beyond 5 % (SETTING_SHARE).
    The case is the law of the first search (its level sensor 1's smoothed inverse); with the
    level found again on the reconstructed gas (estimation/relevel.py) the move is not even
    significant (measured: no systematic part), and the same must hold."""
    rec = record(7, tau=0.3, rate=100.0, duration=600.0)
    with monkeypatch.context() as patched:
        patched.setattr(characterise_module, "relevelled", lambda *args, **kwargs: None)
        first = _with_mass_flow(rec)
    conf = first.estimate.confidence
    assert conf is not None
    for name in ("tau1_0", "tau2_0"):
        # the case: a move that is significant (nonzero) but immaterial
        assert 0.0 < conf.settings_std[name] < SETTING_SHARE * conf.values[name]
        assert conf.identifiable[name], conf.reasons[name]
    assert first.reconstruction_doubts() == []
    result = _with_mass_flow(rec)
    conf = result.estimate.confidence
    assert conf is not None
    for name in ("tau1_0", "tau2_0"):
        assert conf.settings_std[name] < SETTING_SHARE * conf.values[name]
        assert conf.identifiable[name], conf.reasons[name]
    assert result.reconstruction_doubts() == []
    # issue 11's bounds but the 15 % of the raw sensor, which a 0.3 s sensor beside a 0.15 s
    # gas fluctuation of 1.5 K leaves out of reach (the oracle itself: 18 %)
    assert max(_tau_errors(result, rec)) < 0.05
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec)


@pytest.mark.parametrize("seed,options", [(1, {}), (7, {"rate": 2.0, "tau": 8.0})])
def test_t_g_std_covers_the_gas_to_the_reported_bandwidth(seed: int,
                                                          options: dict[str, Any]) -> None:
    """T_g_std is the smoother's posterior given its gas prior; the gas's 0.15 s fluctuation
    lies beyond what the sensors resolve, where no data can tell its size. So the summary
    states the bandwidth, and T_g_std must cover the gas's error below it (the error low-passed
    at the bandwidth, zero phase). Measured (10 Hz and 2 Hz here; also 50 Hz with sheaths and
    0.15 K noise with 0.1 K steps): the error below over T_g_std had an RMS of 0.65-1.04 and
    stayed within 2 T_g_std on 95-99 % of the rows, while the whole error was 1.7-2.6 times
    T_g_std (the part above the bandwidth, 0.97-1.13 K, against 0.35-0.88 K below)."""
    rec = record(seed, **options)
    result = _with_mass_flow(rec)
    resolved = result.bandwidth
    assert resolved is not None and not resolved.limited
    assert 0.0 < resolved.low_hz <= resolved.hz <= resolved.high_hz < 0.5 / rec.ts
    assert f"resolves the gas up to {resolved.hz:.3g} Hz" in result.summary()
    document = result.to_json_dict()["reconstruction"]
    assert document["bandwidth_hz"] == resolved.hz
    _assert_covered_below_bandwidth(result, rec)


def _assert_covered_below_bandwidth(result: Characterisation, rec: Recording) -> None:
    assert result.gas_estimate is not None and result.gas_std is not None
    assert result.bandwidth is not None
    error = result.gas_estimate - rec.gas
    below = sosfiltfilt(butter(4, result.bandwidth.hz, fs=1.0 / rec.ts, output="sos"), error)
    z = below / result.gas_std
    # an honest posterior gives z an RMS of 1 (95 % within 2). Its intensity comes from the
    # marginal likelihood on a gas that is not the prior's random walk, so 1.5 times too
    # confident at most, and not so cautious that the band says nothing (0.4: T_g_std 2.5 times
    # the error); the 2-sigma band must hold on 90 % of the rows
    rms = float(np.sqrt(np.mean(z * z)))
    assert 0.4 <= rms <= 1.5, rms
    assert float(np.mean(np.abs(z) < 2.0)) >= 0.90


def test_the_causal_filter_reports_its_own_uncertainty() -> None:
    """`--reconstruction filter` (what the ECU runs) gives T_g_std from the core Kalman
    filter's own variance (it was NaN). Measured on this generator with the mass flow (10, 2
    and 50 Hz, 0.05-0.15 K): the error over it had an RMS of 1.04-1.28, 89-97 % within 2
    T_g_std (rows after the first minute: the filter's start)."""
    rec = record(1)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                                 flow_column="mdot", reconstruction="filter")
    assert result.gas_estimate is not None and result.gas_std is not None
    assert result.bandwidth is None  # the smoother's; a causal filter has none of its kind
    rows = slice(int(60.0 / rec.ts), None)
    z = ((result.gas_estimate - rec.gas) / result.gas_std)[rows]
    # the filter's variance is the model's given its tuned gas intensity (the smoother's
    # marginal likelihood): at most 1.5 times too confident in RMS, the 2-sigma band on 85 %
    # of the rows (a Gaussian's 95 %, less what the load steps' tails take)
    assert float(np.sqrt(np.mean(z * z))) <= 1.5
    assert float(np.mean(np.abs(z) < 2.0)) >= 0.85


def test_the_level_term_rescues_an_order_2_fit_that_lacks_it() -> None:
    """2 Hz, tau 7.75 / 26.7 s, a 0.21 s sheath on sensor 1, 0.1 K ADC steps, the mass flow as
    the column: the power law alone gave order 2 a complex pair (13.2 / 13.2 s, misfit 4.3).
    The level term must not lean on that fit's stages: with sensor 1's inverse through them
    the search stalled (3.7) and the pair was refused; through its first-order time constant,
    1.65 times the noise, m 0.553 (0.52 on the velocity) and the gas 1.03x the oracle."""
    rec = record(1002, duration=900.0, rate=2.0, tau=7.75, ratio=3.45, m=0.52,
                 sheaths=(0.21, 0.0), noise=0.035, adc=0.1, jitter=0.002)
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.level_reference is not None
    assert abs(model.exponent - 0.52) < 0.05
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec)


@pytest.mark.parametrize("column", ["velocity", "mdot"])
def test_a_sheath_behind_a_fast_element_is_identified_with_the_flow(column: str) -> None:
    """10 Hz, tau 3.29 / 12.7 s, sheaths 0.79 / 0.4 s, m 0.62, gains 0.994 / 0.989. The first
    exponent comes from a first-order fit, which the sheath biases (0.559); the order-2 fit
    at it chose unit gains and its re-search ran to the grid's edge (0.659), where the stages
    came out shared and the pair fell back to first order: 2.30x the oracle with the velocity
    as the column, 2.34x with the mass flow. Now the exponent is searched again with the
    orders and static model chosen at the last one (velocity: m 0.620, 1.01x), and the level
    term is tried on the order-2 law's 3.4 times the noise (mass flow: m 0.656, 1.05x)."""
    gains = (0.994, 0.989)
    rec = record(61012, duration=900.0, tau=3.29, ratio=3.87, m=0.62, sheaths=(0.79, 0.4),
                 gains=gains)
    flow = rec.mass_flow * rec.gas if column == "velocity" else rec.mass_flow
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=flow,
                                 flow_column=column, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    # issue 11: the sheath stage identified when present, m within 0.05 (measured 0.000 and
    # 0.036), per-row time constants within 5 % RMS (0.1 % and 1.3 %), the gas within 1.5x
    # the oracle (1.01x, 1.05x) and 15 % of the raw fast sensor
    assert [len(taus) for taus in result.estimate.time_constants] == [2, 2]
    assert abs(model.exponent - 0.62) < 0.05
    _assert_issue_bounds(result, rec, gains)


@pytest.mark.parametrize("seed,duration,tau,ratio,m,sheaths,gains", [
    (3000, 900.0, 3.04, 3.6, 0.53, (0.4, 0.0), (1.0, 1.0)),
    (3000, 1800.0, 3.04, 3.6, 0.53, (0.4, 0.0), (1.0, 1.0)),
    (81005, 900.0, 7.78, 2.33, 0.35, (0.42, 0.0), (1.0, 1.0)),
    (82002, 900.0, 2.18, 2.99, 0.6, (0.0, 0.3), (1.014, 0.997))])
def test_a_sheath_on_one_sensor_is_identified_with_the_mass_flow(
        seed: int, duration: float, tau: float, ratio: float, m: float,
        sheaths: tuple[float, float], gains: tuple[float, float]) -> None:
    """10 Hz, 0.05 K, ADC steps, a sheath on ONE sensor, the mass flow as the column. The
    first-order decisions could not see past the sheath, which dominates the first-order
    misfit: 3000's level term took it from 264 to 224 times the noise (not significant), and
    the order-2 power law hid the missing level in a shared 149 / 111 s stage: first order,
    1.85x the oracle. 81005's power law itself (312 -> 205 times the noise, 7.5 standard
    deviations): reported "constant", 3.47x. Both are now decided with a second stage on one
    sensor only, where no stage can be common (1.03x, 1.01x). 82002 (gains 1.014 / 0.997): the
    unit order-2 model stood in a shared 269 / 277 s pole pair for the gain mismatch, even at
    the TRUE schedule, and fell back to first order at 2.34x; the affine model is taken
    instead (1.01x). 3000 over 30 min: the re-searched exponent's order-2 run had no positive
    stages, and the law was given up (first order, 1.89x); the last usable exponent now stays
    (1.02x)."""
    rec = record(seed, duration=duration, rate=10.0, tau=tau, ratio=ratio, m=m,
                 sheaths=sheaths, gains=gains)
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    # issue 11: the sheath stage identified when present (on that sensor only), per-row time
    # constants within 5 % RMS (measured 0.2-0.8 %), the gas within 1.5x the oracle (1.01-1.03x)
    # and 15 % of the raw fast sensor (9-13 %); each model explains the data
    sheathed = [i for i, s in enumerate(sheaths) if s > 0.0]
    assert [len(t) for t in result.estimate.time_constants] == [
        2 if i in sheathed else 1 for i in range(2)]
    stage = result.estimate.time_constants[sheathed[0]][1] / model.psi
    truth = (rec.sheath1, rec.sheath2)[sheathed[0]]
    assert float(np.sqrt(np.mean((stage / truth - 1.0) ** 2))) < 0.10  # measured 0.2-2.5 %
    _assert_issue_bounds(result, rec, gains)
    assert result.model_check is not None and result.model_check.adequate


def test_an_order_2_power_law_that_fails_without_its_level_is_run_with_it() -> None:
    """50 Hz, sheaths 0.38 / 0.28 s on 6.6 / 17 s elements, a jittered clock, the mass flow as
    the column: the level term was decided at first order, but the order-2 characterisation
    at the power law alone was not usable, so the pair was answered at first order, 2.72x the
    oracle (294 times the noise). It is now run with the level decided (measured: order 2,
    1.17x, per-row time constants 1.3 %, the residual misfit of 2.0 times the noise
    reported)."""
    rec = record(1001, duration=900.0, rate=50.0, tau=6.62, ratio=2.61, m=0.48,
                 sheaths=(0.38, 0.28), noise=0.056, adc=0.0, jitter=0.002)
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.level_reference is not None
    assert [len(t) for t in result.estimate.time_constants] == [2, 2]
    # issue 11's bounds: per-row time constants within 5 %, the gas within 1.5x the oracle
    # and 15 % of the raw fast sensor (measured 6 %)
    _assert_issue_bounds(result, rec)
    assert result.model_check is not None
    if not result.model_check.adequate:
        assert result.model_check.reasons


def test_without_flow_meets_the_issue_bound() -> None:
    """The same recording without the flow column: tracked, within 2.5x the oracle (1.30x)."""
    rec = record(1)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 2.5 * _oracle_rmse(rec)
    _assert_tracked_std_covers(result, rec)


def test_without_flow_t_g_std_carries_the_tracked_noise() -> None:
    """A second pair (seed 3) tracked without the flow: T_g_std covers the gas below the
    bandwidth only with the tracked time constants' noise part in it."""
    rec = record(3)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    _assert_tracked_std_covers(result, rec)


def _assert_tracked_std_covers(result: Characterisation, rec: Recording) -> None:
    """T_g_std of a tracked schedule includes the part of the per-row time constants' error
    that follows the noise (``psi_noise`` by the delta method): the gas error below the
    bandwidth over T_g_std had an RMS of 1.90 and 2.31 without it (seeds 1 and 3; the 2-sigma
    band held on 92 % and 85 % of the rows), 0.77 and 1.19 with it (98 %, 91 %). The summary
    says that a bias of the tracked time constants is still not in it."""
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert 0.0 < model.evidence["psi_noise"] < 0.05  # a lower bound on psi's error (2.7-4.5 %)
    _assert_covered_below_bandwidth(result, rec)
    summary = result.summary()
    assert TRACKED_NOISE_STD_NOTE in summary and TRACKED_STD_NOTE not in summary
    assert f"noise moves them by {model.evidence['psi_noise']:.1%} RMS (psi_noise)" in summary


@pytest.mark.parametrize("seed,duration,fallback", [
    (12, 1200.0, None), (6, 600.0, "gave both sensors a time constant"), (10, 600.0, None)])
def test_a_stage_shared_by_both_sensors_falls_back_to_first_order(
        seed: int, duration: float, fallback: str | None) -> None:
    """50 Hz, tau 2 / 8 s, m 0.35, 0.1 K noise, the mass flow as the column: order 2 gave both
    sensors a common slow "stage" that absorbed the missing level term. Seed 12: 276 / 275 s,
    the model "adequate" and the gas 2,081 K RMS off with exit 0; seed 6 (600 s): 52.6 / 44 s,
    misfit, refused. Of seeds 1-12, 7 were refused and 1 absurd; first order, which a pair can
    determine, gave 0.86-0.97 K for all 12 (raw fast sensor about 11 K). Since the level term
    is decided at first order, seed 12's order-2 fit with the level no longer takes a shared
    stage and the order choice itself gives first order (1.03x the oracle); seed 6 still
    falls back from a 52.6 / 44 s pair (1.02x). Seed 10 fell back from stages the data did
    not determine (61.6 s +- 168 %), then (its flow column taken 0.049 s later, the misfit
    1.82 -> 1.72) from a shared 107 / 107 s pair; with the level term tried whenever the
    power law misfits significantly, the order choice itself gives first order, as for seed
    12."""
    rec = record(seed, duration=duration, rate=50.0, tau=2.0, ratio=4.0, m=0.35, noise=0.1)
    result = _with_mass_flow(rec)
    assert [len(t) for t in result.estimate.time_constants] == [1, 1]
    why = result.estimate.identifiability.get("order_fallback")
    assert (why is None) if fallback is None else (fallback in str(why))
    assert max(_tau_errors(result, rec)) < 0.05
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec)


def test_undetermined_stages_fall_back_to_first_order_with_their_reason(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The fallback's branch for order-2 stages the data do not determine (seed 10 reached it
    until its flow delay was found; the detection itself: the asked-for order-2 refusal below),
    on seed 6, whose order-2 fit falls back (above): first order, and the message names the
    stage and its uncertainty."""
    monkeypatch.setattr(order_choice, "spurious_shared_stage", lambda estimate: None)
    monkeypatch.setattr(order_choice, "undetermined_stages",
                        lambda estimate: [(0, 61.6, 1.68)] if estimate.order == 2 else [])
    rec = record(6, duration=600.0, rate=50.0, tau=2.0, ratio=4.0, m=0.35, noise=0.1)
    result = _with_mass_flow(rec)
    assert [len(t) for t in result.estimate.time_constants] == [1, 1]
    why = str(result.estimate.identifiability.get("order_fallback"))
    assert "are not determined by the data" in why and "61.6" in why, why
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec)


def test_an_undetermined_gain_falls_back_to_first_order(monkeypatch: pytest.MonkeyPatch,
                                                        ) -> None:
    """5 Hz, gains 0.97 / 1.009, the slow sensor's logger holding each reading for two rows,
    taken as readings (as a hold with no regular pattern would be: its interpolation is off
    here): order 2 gave a gain ratio of 1.92 +- 22.9 and an offset of -535 K, the model
    "adequate" and the gas 27.1 K RMS off where the raw fast sensor is 16.3 K off (exit 0).
    First order determines the gain (0.957): 2.1 K. (Interpolated, the same record gives
    first order directly at 1.02x the oracle.)"""
    rec = record(1005, duration=900.0, rate=5.0, tau=2.03, ratio=3.71, m=0.64,
                 gains=(0.97, 1.009), noise=0.114, adc=0.0, jitter=0.002, hold=2)
    monkeypatch.setattr(readings_module, "unhold",
                        lambda x, ts, smooth=False, longest=0.0: (np.asarray(x, dtype=float), 1))
    result = _with_mass_flow(rec)
    assert "order_fallback" in result.estimate.identifiability
    assert result.gas_estimate is not None
    # the held readings are beyond the model, so not the issue's 1.5x: far better than the
    # raw fast sensor (measured 13 %), and the static map a temperature sensor pair can have
    assert _rmse(result.gas_estimate, rec.gas) <= 0.25 * _rmse(rec.t1, rec.gas)
    fit = result.estimate.details["fit"]
    assert isinstance(fit, Fit) and abs(fit.gain_ratio - 1.009 / 0.97) < 0.1


@pytest.mark.parametrize("seed,tau,ratio,m,sheaths", [
    (61006, 4.8, 3.79, 0.41, (0.64, 0.79)), (62000, 5.46, 3.5, 0.61, (0.69, 0.85))])
def test_near_equal_sheaths_are_resolved_with_an_order_2_level(
        seed: int, tau: float, ratio: float, m: float, sheaths: tuple[float, float]) -> None:
    """10 Hz, near-equal sheaths, the mass flow as the column. The sheaths nearly cancel from
    the cross-relation, so the stages hang on psi being right to a fraction of a per cent: with
    the level from sensor 1's first-order inverse, order 2 traded stages the data did not fix
    (61006: 7.1 +- 32 %, 3.8 +- 30 % s; the gas 22.1 K RMS off, worse than the raw fast sensor,
    exit 0), then fell back to first order at 3.6x and 4.0x the oracle. With the level decided
    at first order, the quadratic term and sensor 1's order-2 inverse as the level (measured:
    per-row time constants 0.3-0.5 % RMS, the gas 1.02x the oracle for both, adequate)."""
    rec = record(seed, duration=900.0, rate=10.0, tau=tau, ratio=ratio, m=m, sheaths=sheaths)
    result = _with_mass_flow(rec)
    assert [len(t) for t in result.estimate.time_constants] == [2, 2]
    # the issue's bounds: per-row time constants within 5 %, the gas within 1.5x the oracle
    # and 15 % of the raw fast sensor
    _assert_issue_bounds(result, rec)
    model = result.estimate.flow_model
    assert model is not None and abs(model.exponent - m) < 0.05  # measured 0.401, 0.603
    # the sheaths per row within 10 % RMS (measured 1.7-4.5 %), though nearly common
    for i, truth in enumerate((rec.sheath1, rec.sheath2)):
        stage = result.estimate.time_constants[i][1] / model.psi
        assert float(np.sqrt(np.mean((stage / truth - 1.0) ** 2))) < 0.10
    # the generator's sensors follow (mass flow x T)^-m: log tau is convex in T, c ~ m / 2T^2
    # (6e-7 and 9e-7 per K^2 at 580 K; measured 8.4e-7 and 1.05e-6)
    assert model.level_curvature > 0.0
    assert result.model_check is not None and result.model_check.adequate


def test_near_equal_sheaths_are_not_taken_for_a_common_factor() -> None:
    """The 62000 pair over 30 min: order 2 found 0.89 / 1.09 s for sheaths of 0.82 / 1.01 s
    (at the reference flow), but over 18 000 rows its small misfit (1.54 times the noise) was
    significant, and a nearly shared pair of stages in a misfitting model was taken for a
    common factor absorbing model error: first order, 3.86x the oracle. Fast stages under
    half the dominant time constants are sheaths (the common factors were 24-4033 s): order 2
    is kept (1.14x, the misfit reported). The misfit was the level term's gas level, smoothed
    over tf and missing the fast load changes; with the level candidates of
    ``level.candidates`` (measured: 0.80 / 0.99 s, per-row time constants 0.4 %, m 0.603 for
    0.61, 1.01x, misfit 1.20 at 6.8 standard deviations) the model explains the data."""
    rec = record(62000, duration=1800.0, rate=10.0, tau=5.46, ratio=3.5, m=0.61,
                 sheaths=(0.69, 0.85))
    result = _with_mass_flow(rec)
    assert [len(t) for t in result.estimate.time_constants] == [2, 2]
    assert "order_fallback" not in result.estimate.identifiability
    assert max(_tau_errors(result, rec)) < 0.05  # measured 0.5 %
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec)
    model = result.estimate.flow_model
    assert model is not None and abs(model.exponent - 0.61) < 0.05  # measured 0.603
    # the generator's sensors follow the velocity (mass flow x T)^-m exactly, which the level
    # term approximates to ~0.05 % in psi: nothing left that the noise does not explain
    assert result.model_check is not None and result.model_check.adequate


def test_asked_for_order_2_with_undetermined_stages_is_refused() -> None:
    """2 Hz, tau 2.2 / 6.1 s, a 0.16 s sheath on sensor 2, 0.1 K noise and ADC steps, the mass
    flow as the column, ``--order 2``: 4.15 +- 46 % / 1.35 s and 6.46 / 2.86 +- 77 % s, the
    model "adequate" at 0.9 times the noise and the gas 28.9 K RMS off where the raw fast
    sensor is 13.2 K off, exit 0. No number instead, and what to do."""
    rec = record(4006, duration=900.0, rate=2.0, tau=2.2, ratio=2.78, m=0.65,
                 sheaths=(0.0, 0.16), noise=0.101, adc=0.1, jitter=0.002)
    with pytest.raises(EstimationError, match="do not determine the second-order"):
        characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, order=2, flow=rec.mass_flow,
                            flow_column="mdot", reconstruction="smoother")


@pytest.mark.parametrize("flow", [True, False])
def test_held_readings_are_interpolated_between_refreshes(flow: bool) -> None:
    """2 Hz, the slow sensor's logger refreshing every other row (a 1 s hold): taken as
    readings, the fast sensor's per-row time constant was 31 % off and the gas 2.6x the oracle
    with the flow (4.1x without), flagged. Interpolated between its refreshes by a cubic,
    its noise counted once per refresh (dualprobe.models.held), with a note that says so."""
    rec = record(3005, duration=900.0, rate=2.0, tau=2.78, ratio=2.36, m=0.6, noise=0.047,
                 adc=0.02, hold=2)
    assert held_share(rec.t1) < 0.02 and held_share(rec.t2) == pytest.approx(0.5, abs=0.05)
    result = (_with_mass_flow(rec) if flow else
              characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother"))
    assert any(n.startswith("T_m2 holds its readings for 2 rows") for n in result.notes)
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, rec.gas)
    if flow:  # the issue's bounds with the flow (measured: 1.1 % and 0.7 %, 0.90x)
        _assert_issue_bounds(result, rec)
    else:  # and without (measured 1.40x; per-row time constants 8 % off)
        assert ours <= 2.5 * _oracle_rmse(rec)
    check = result.model_check
    assert check is not None and check.adequate, check and check.reasons


def test_irregularly_held_readings_are_named_not_called_adequate() -> None:
    """A logger refreshing after 2-5 rows at random is no regular pattern, so nothing is
    interpolated (a quantised signal's runs look alike); the hold is beyond the model, and the
    check says so, with which sensor."""
    rec = record(3005, duration=900.0, rate=2.0, tau=2.78, ratio=2.36, m=0.6, noise=0.047,
                 adc=0.02)
    runs = np.random.default_rng(1).integers(2, 6, rec.t2.size)
    starts = np.cumsum(runs)
    starts = np.concatenate([[0], starts[starts < rec.t2.size]])
    held = rec.t2[starts][np.searchsorted(starts, np.arange(rec.t2.size), side="right") - 1]
    assert held_share(held) > 0.5
    result = characterise_arrays(rec.t1, held, rec.ts, time=rec.t, flow=rec.mass_flow,
                                 flow_column="mdot", reconstruction="smoother")
    assert not result.notes
    check = result.model_check
    assert check is not None and not check.adequate
    assert any(r.startswith("T_m2 holds its readings") for r in check.reasons), check.reasons


def test_a_misfit_beside_a_held_flow_column_names_the_refresh() -> None:
    """20 min, 10 Hz, a 0.4 s sheath on the fast sensor, the mass flow refreshed once a second:
    interpolated between its refreshes, the flow misses its tip-ins (the generator's flow
    follows the load within 0.2 s) and the fit keeps a misfit beyond the noise (measured: the
    gas 1.07x the oracle; 1.02x with the flow at the rows' rate). The warning names the
    column's refresh among the causes."""
    rec = record(7001, tau=4.5, ratio=3.0, m=0.5, sheaths=(0.4, 0.0))
    column = np.repeat(rec.mass_flow[::10], 10)[:rec.mass_flow.size]
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=column,
                                 flow_column="mdot", reconstruction="smoother")
    check = result.model_check
    assert check is not None and not check.adequate
    assert any("flow column, refreshed every 10 rows and interpolated" in reason
               for reason in check.reasons), check.reasons


@pytest.mark.parametrize("lead,hold", [(0.0, 1), (0.3, 1), (-0.2, 1), (0.0, 10)])
def test_a_flow_column_that_leads_lags_or_is_held(lead: float, hold: int) -> None:
    """10 Hz, sheaths 0.5 / 0.3 s on 4 / 12 s elements, gains 1.01 / 0.99: the mass flow
    column ``lead`` seconds ahead of the flow at the sensors (an intake air-mass meter; a
    negative lead: a column the ECU filtered), or refreshed once a second (``hold`` rows).
    Before, the flow was taken as given: lagging by 0.1 s the sheath of sensor 2 was lost
    (1.43x the oracle, misfit 2.0), by 0.5 s the pair fell to first order (1.82x, misfit 89),
    held for 1 s, 1.81x. Measured now: the delay 0.274 s for 0.3 s and -0.194 s for -0.2 s,
    1.01-1.02x; held, 1.03x (misfit 1.5, said)."""
    gains = (1.01, 0.99)
    rec = record(5010, duration=900.0, tau=4.0, ratio=3.0, m=0.5, sheaths=(0.5, 0.3),
                 gains=gains)
    column = np.interp(rec.t + lead, rec.t, rec.mass_flow)
    column = np.repeat(column[::hold], hold)[:column.size]
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=column,
                                 flow_column="mdot", reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    assert [len(t) for t in result.estimate.time_constants] == [2, 2]
    # the delay to within half a row (0.05 s; measured 0.026 and 0.006 off), none at all
    # for the column as it is; held, within a row (the interpolation between refreshes
    # bends the flow a little: measured 0.062 s, the misfit 1.63 -> 1.51)
    tolerance = 0.1 if hold > 1 else (0.0 if lead == 0.0 else 0.05)
    assert abs(model.delay - lead) <= tolerance
    assert model.evidence["flow_refresh_rows"] == hold
    _assert_issue_bounds(result, rec, gains)
    assert result.model_check is not None
    summary = result.summary()
    if hold > 1:
        assert "held for 10 rows" in summary
        if not result.model_check.adequate:  # what the interpolation leaves is said
            assert any("flow column, refreshed every 10 rows" in reason
                       for reason in result.model_check.reasons), result.model_check.reasons
    else:
        assert result.model_check.adequate
        assert ("flow column" in summary and "later" in summary) == (lead != 0.0)


@pytest.mark.parametrize("seed,kw", [
    (61000, {"tau": 3.93, "ratio": 3.54, "m": 0.57, "gains": (1.03, 1.03)}),
    (61011, {"tau": 6.32, "ratio": 2.16, "m": 0.58}),
])
def test_the_gas_level_follows_fast_load_changes(seed: int, kw: dict[str, Any]) -> None:
    """10 Hz, no sheath, the mass flow as the column (the sensors follow (mass flow x T)^-m).
    The level term's gas level was sensor 1's inverse smoothed over the filter time constant
    (about 2 s), which misses the gas's fast load changes, where psi is seen: misfit 5.1 and
    6.3 times the noise (flagged beside a gas at 1.03x and 1.07x the oracle) and m 0.056 and
    0.062 too large, beyond issue 11's 0.05. With the candidates of ``level.candidates``
    (smoothed over tf / 4 or tf / 16 as well) measured: m 0.576 and 0.587, misfit 1.10 and
    0.96, 1.05x and 1.02x."""
    rec = record(seed, duration=900.0, **kw)
    gains = kw.get("gains", (1.0, 1.0))
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law" and model.level_reference is not None
    assert abs(model.exponent - kw["m"]) < 0.05  # issue 11's bound
    _assert_issue_bounds(result, rec, gains)
    # the level term approximates the generator's (mass flow x T)^-m to ~0.05 % in psi: with
    # the right gas level nothing is left that the noise does not explain
    assert result.model_check is not None and result.model_check.adequate


def test_a_small_but_significant_misfit_tries_the_level_term() -> None:
    """10 Hz, sheaths 0.77 / 0.29 s on 5.5 / 19 s elements, m 0.56, the mass flow as the
    column. The order-2 power law left 1.90 times the noise over 563 effective rows (15
    standard deviations), below the 2 from which the level term was tried, so it never was:
    m 0.654, flagged. Tried whenever the misfit is significant (measured: m 0.583, sheaths
    0.82 / 0.32 s, misfit 1.07, 1.02x the oracle)."""
    rec = record(61007, duration=900.0, tau=5.47, ratio=3.53, m=0.56, sheaths=(0.77, 0.29))
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law" and model.level_reference is not None
    assert [len(t) for t in result.estimate.time_constants] == [2, 2]
    assert abs(model.exponent - 0.56) < 0.05  # issue 11's bound
    # issue 11's bounds but the 15 % of the raw fast sensor, which even the oracle misses
    # on this record (1.27 K against a raw 8.53 K: 14.9 %)
    assert max(_tau_errors(result, rec)) < 0.05
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec)
    assert result.model_check is not None and result.model_check.adequate


def test_a_located_delay_is_not_traded_for_the_level_term() -> None:
    """10 Hz, near-equal sheaths 0.58 / 0.76 s on 2.7 / 10 s elements, gains 1.026 / 0.993,
    the mass-flow column 0.1 s ahead. The delay located on the first-order power law is 0.174
    s; with the level term, whose sharper gas level follows the load (and so the flow), the
    law at d = 0 fitted as well (misfit 1.089 against 1.101, 0.5 standard deviations) and the
    delay was dropped: 2.38x the oracle, called adequate. The located delay is now kept
    unless d = 0 fits significantly better (measured 1.19x)."""
    gains = (1.026, 0.993)
    rec = record(91001, duration=900.0, tau=2.74, ratio=3.67, m=0.65, sheaths=(0.58, 0.76),
                 gains=gains)
    column = np.interp(rec.t + 0.1, rec.t, rec.mass_flow)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=column,
                                 flow_column="mdot", reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    # located on the first-order law, which the sheaths bias (measured 0.174 s for 0.1 s)
    assert 0.05 < model.delay < 0.2
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec, gains)


def test_unit_gains_chosen_at_a_constant_schedule_do_not_hide_the_power_law() -> None:
    """10 Hz, no sheath, m 0.64, gains 1.018 / 1.005, the mass flow as the column. At a
    constant schedule both static models misfit by the unmodelled flow, so the gain mismatch
    hardly counted and unit gains were chosen (156 577 times the noise); the unit power law
    took that only to 98 000, was not decided, and the pair was reported "constant": its gas
    24 K off where the raw fast sensor is 23 K off (22x the oracle). The power law is now also
    decided with the affine map (9.6 times the noise; measured 1.07x, per-row tau 1.1 %)."""
    gains = (1.018, 1.005)
    rec = record(91008, duration=900.0, tau=5.72, ratio=3.16, m=0.64, gains=gains)
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    assert model.evidence.get("affine_power_law") == 1.0
    _assert_issue_bounds(result, rec, gains)
    assert result.model_check is not None
    if not result.model_check.adequate:
        assert result.model_check.reasons  # the remaining misfit is said


def test_a_decided_unit_power_law_does_not_keep_the_gain_mismatch_in_its_exponent() -> None:
    """20 Hz, a 0.73 s sheath on the slow sensor only, m 0.59, gains 0.997 / 1.001, and as
    the column the gas velocity (mass flow x gas: what eq. 1 follows, as a velocity model gives
    it). Unit gains were chosen at the constant schedule and the unit power law was decided,
    but its exponent carried the 0.4 % gain mismatch (0.67 for 0.59): on it the order-2 fits
    found shared stages of 95-157 s, first order was kept and the gas came out 4.64x the
    oracle (warned). The affine law is now tried beside a decided unit law and kept where it
    fits significantly better (first order: 3172 -> 1550 times the noise); the sheath is found
    (measured 1.03x the oracle, m 0.590, adequate)."""
    gains = (0.997, 1.001)
    rec = record(11000, rate=20.0, tau=7.65, ratio=3.02, m=0.59, sheaths=(0.0, 0.73),
                 gains=gains)
    velocity = rec.mass_flow * rec.gas / gains[0]  # rec.gas is in sensor 1's calibration
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=velocity,
                                 flow_column="velocity", reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    assert model.evidence.get("affine_power_law") == 1.0
    assert [len(t) for t in result.estimate.time_constants] == [1, 2]
    assert abs(model.exponent - 0.59) < 0.05  # issue 11's bound
    _assert_issue_bounds(result, rec, gains)
    assert result.model_check is not None and result.model_check.adequate


@pytest.mark.parametrize("column", ["velocity", "mdot"])
def test_a_law_the_data_need_is_kept_though_the_flow_rarely_leaves_one_level(column: str,
                                                                             ) -> None:
    """300 s at 2 Hz, 0.15 K noise, m 0.67, gains 0.991 / 0.98 (logger_sweep.py 120 velocity,
    case 120003): the flow stays within 3 % over 90 % of the record, so the power law changes
    the time constants by 2.3 % over the 5-95 % flow range, under the 5 % a law must change them
    by; yet it takes the misfit from 4.71 to 0.98 times the noise (42 standard deviations). It
    was reported "constant", misfitting, with a warning that the column showed no dependence
    (the gas 2.8x the oracle). A law the data need is now kept: measured 1.27x with the
    velocity, 1.31x with the mass flow, adequate."""
    gains = (0.991, 0.98)
    rec = record(120003, rate=2.0, duration=300.0, tau=4.97, ratio=1.93, m=0.67,
                 sheaths=(0.22, 0.31), gains=gains, noise=0.15, adc=0.0)
    flow = rec.mass_flow * rec.gas / gains[0] if column == "velocity" else rec.mass_flow
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=flow,
                                 flow_column=column, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    assert model.evidence["power_law_change"] < 0.05  # the case: below the practical size
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec, gains)
    assert result.model_check is not None and result.model_check.adequate


def test_spikes_are_replaced_and_noted() -> None:
    """Pickup spikes on the leads (three of 30 K on T_m1, a 3-row dropout to 0 K on T_m2) in
    a 10 Hz drive cycle with the flow: left in, they took the gas from 1.07x the oracle to
    10.1x (twenty were refused with no word of why); replaced, the issue's bounds hold, the
    model is adequate and a note names each sensor."""
    rec = record(1)
    t1, t2 = rec.t1.copy(), rec.t2.copy()
    t1[[2000, 5000, 9000]] += (30.0, -30.0, 30.0)
    t2[7000:7003] = 0.0
    result = characterise_arrays(t1, t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                                 flow_column="mdot", reconstruction="smoother")
    notes = [note for note in result.notes if "no lagging sensor can do" in note]
    assert [note.split(":")[0] for note in notes] == ["T_m1", "T_m2"]
    assert notes[0].startswith("T_m1: 3 runs of 1-3 readings")
    assert all(note.endswith("replaced by straight lines between their neighbours")
               for note in notes)
    assert result.model_check is not None and result.model_check.adequate
    _assert_issue_bounds(result, rec)
