"""Field conditions (issue 11): time constants that follow the gas flow, load-following gas,
sheathed RTDs, against the oracle that knows the true time-varying sensors.

Recordings come from the drive-cycle simulator (dualprobe.simulate.drive_cycle: engine load ->
exhaust gas temperature and velocity; sensors whose element and sheath follow the velocity as
paper eq. 1 says, ADC quantisation, noise), which is richer than the estimator's model (the
sheath may follow its own exponent, the fine-step integration is exact, the gas carries a 1 Hz
fluctuation no 10 Hz pair can follow). The oracle (tests/python/field_oracle.py, written apart
from the product) is the best linear smoother given the TRUE time-varying dynamics and gains.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.estimation import field
from dualprobe.estimation.settings import GAP_THRESHOLD
from dualprobe.io import EstimationError, InputError
from dualprobe.report.dcm import dcm_text
from dualprobe.workflows import order_choice
from dualprobe.workflows.characterise import characterise_arrays
from field_oracle import oracle

DURATION = 1200.0  # s: 20 minutes of driving, 12 000 rows at 10 Hz
RATE = 10.0
NOISE = 0.05
ADC = 0.02


@dataclass(frozen=True)
class Case:
    exponent: float
    ratio: float
    sheaths: tuple[float, float]
    gains: tuple[float, float]
    seed: int


CASES = [
    Case(0.3, 2.0, (0.0, 0.0), (0.97, 1.03), 1),
    Case(0.5, 3.0, (0.3, 0.8), (1.0, 1.0), 2),
    Case(0.7, 4.0, (0.5, 0.2), (1.03, 0.98), 3),
    Case(0.45, 2.5, (0.0, 0.0), (1.0, 1.0), 4),
]


def _record(case: Case, flow_law: bool = True) -> sim.FieldRecording:
    rng = np.random.default_rng(case.seed)
    conditions = sim.drive_cycle(DURATION, rng)
    m = case.exponent if flow_law else 0.0
    s1 = sim.FieldSensor(4.0, m, case.sheaths[0], gain=case.gains[0], noise_std=NOISE)
    s2 = sim.FieldSensor(4.0 * case.ratio, m, case.sheaths[1], gain=case.gains[1],
                         noise_std=NOISE)
    return sim.simulate_field_pair(conditions, s1, s2, sample_rate=RATE, quantisation=ADC,
                                   rng=rng)


def _oracle_rmse(rec: sim.FieldRecording, case: Case) -> float:
    sheath = [s if np.any(s > 0) else None for s in (rec.sheath1, rec.sheath2)]
    return oracle(rec.t, rec.t1, rec.t2, rec.tg, rec.tau1, rec.tau2, (NOISE, NOISE),
                  sheath1=sheath[0], sheath2=sheath[1], static1=(case.gains[0], 0.0),
                  static2=(case.gains[1], 0.0), gases=("rw",)).rmse


def _rmse(x: np.ndarray, y: np.ndarray) -> float:
    ok = np.isfinite(x) & np.isfinite(y)
    return float(np.sqrt(np.mean((x[ok] - y[ok]) ** 2)))


@pytest.mark.parametrize("case", CASES, ids=lambda c: f"m{c.exponent}-r{c.ratio}-s{c.sheaths}")
def test_flow_law_recovers_time_constants_and_reaches_the_oracle(case: Case) -> None:
    rec = _record(case)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind in ("power_law", "curve")
    # m within 0.05 (issue 11)
    assert abs(model.exponent - case.exponent) < 0.05
    # per-row dominant (element) time constants within 5 % RMS of the truth
    tau1, tau2 = result.time_constants_per_row()
    for est, truth in ((tau1, rec.tau1), (tau2, rec.tau2)):
        assert float(np.sqrt(np.mean((est / truth - 1.0) ** 2))) < 0.05
    # sheaths: identified when present (order 2 where a sheath is)
    for i, sheath in enumerate(case.sheaths):
        taus = result.estimate.time_constants[i]
        if sheath > 0.0:
            assert len(taus) == 2, f"sensor {i + 1}'s sheath stage not identified: {taus}"
    # reconstruction: the gas as sensor 1 reads it (two sensors cannot tell their common
    # calibration), within 1.5x the oracle's RMSE and 15 % of the raw fast sensor's
    gas = result.gas_estimate
    assert gas is not None
    target = case.gains[0] * rec.tg
    ours = _rmse(gas, target)
    raw = _rmse(rec.t1, target)
    best = _oracle_rmse(rec, case)
    assert ours <= 1.5 * best, (ours, best)
    assert ours <= 0.15 * raw, (ours, raw)
    assert result.model_check is not None and result.model_check.adequate
    assert model.level_reference is None  # a pure power law gets no gas-level term


def test_mass_flow_gets_a_gas_level_term(monkeypatch: pytest.MonkeyPatch) -> None:
    """With the exhaust MASS flow as the column the time constants also follow the gas
    temperature (velocity ~ mass flow x T; the simulator's sensors follow the velocity): the
    power law in mass flow alone misfits, the joint flow and level law explains more of it and
    tracks the per-row time constants better (truth and oracle, not the old version)."""
    case = Case(0.5, 3.0, (0.0, 0.0), (1.0, 1.0), 401)
    rec = _record(case)
    best = _oracle_rmse(rec, case)

    def run() -> tuple[Any, float, float]:
        result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                                     flow_column="mdot", reconstruction="smoother")
        tau1, tau2 = result.time_constants_per_row()
        error = max(float(np.sqrt(np.mean((est / truth - 1.0) ** 2)))
                    for est, truth in ((tau1, rec.tau1), (tau2, rec.tau2)))
        assert result.gas_estimate is not None
        return result, error, _rmse(result.gas_estimate, rec.tg)

    result, error, gas = run()
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    assert model.level_reference is not None
    assert model.level_sensitivity < 0.0  # hotter gas, faster sensors
    assert math.isnan(model.psi_noise)  # a fitted flow law is not tracked: no even/odd split
    assert model.evidence["level_statistic"] > GAP_THRESHOLD
    doc = result.to_json_dict()
    assert doc["flow_model"]["level_sensitivity"] == model.level_sensitivity
    assert doc["flow_model"]["level_curvature"] == model.level_curvature
    assert "_LEVEL_REF" in dcm_text(doc) and "_LEVEL2" in dcm_text(doc)
    # issue 11's bounds hold (measured: 1.3 % and 1.20x; without the term 2.3 % and 1.31x)
    assert error < 0.05 and gas <= 1.5 * best
    monkeypatch.setattr(field, "_level", lambda *args, **kwargs: None)
    _, error_without, gas_without = run()
    # better than the power law alone on both counts (1.3 % vs 2.3 %; 1.20x vs 1.31x)
    assert error < 0.8 * error_without and gas < gas_without


def test_without_flow_tracking_stays_within_2_5x_the_oracle() -> None:
    case = CASES[3]
    rec = _record(case)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, rec.tg)
    best = _oracle_rmse(rec, case)
    assert ours <= 2.5 * best, (ours, best)


@pytest.mark.parametrize("case", [CASES[0], Case(0.51, 2.23, (0.0, 0.0), (1.002, 0.998), 204)],
                         ids=["gains-0.97-1.03", "gains-1.002-0.998"])
def test_without_flow_unequal_gains_are_tracked(case: Case) -> None:
    """Unequal gains (no sheath), no flow: unit-gain tracking cannot explain the pair, the
    whole record's affine map is biased by the very variation being tracked; the searched map
    is what lets the tracker follow the flow. Gains 0.97 / 1.03 stayed at constant time
    constants (3.8x the oracle) before the search, now 0.91 K against the oracle's 0.77 K
    (1.18x). Gains 1.002 / 0.998 (2.4 K at 600 K): the constant model chose unit gains, so the
    search was not tried (9.6x the oracle); now 1.07 K against 0.77 K (1.38x)."""
    rec = _record(case)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert result.model_check is not None and result.model_check.adequate
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, case.gains[0] * rec.tg)  # the gas as sensor 1 reads it
    best = _oracle_rmse(rec, case)
    assert ours <= 2.5 * best, (ours, best)  # the bound without flow


def _refused_or_honest(case: Case) -> None:
    """Refused (exit 3, with what would help), or a gas within the issue's 2.5x of the oracle,
    or one flagged ``adequate: false``; and never worse than a fifth of the raw fast sensor's
    error (the sheathed no-flow path gives 0.06-0.18 of it; the absurd numbers these cases once
    gave with exit 0 were 5-100 times the raw error)."""
    rec = _record(case)
    try:
        result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t,
                                     reconstruction="smoother")
    except EstimationError as exc:
        assert re.search(r"give --flow|longer than a third of the record", str(exc)), exc
        return
    assert result.gas_estimate is not None and result.model_check is not None
    target = case.gains[0] * rec.tg  # the gas as sensor 1 reads it
    ours = _rmse(result.gas_estimate, target)
    assert ours <= 0.2 * _rmse(rec.t1, target), ours
    if ours > 2.5 * _oracle_rmse(rec, case):
        assert not result.model_check.adequate, ours


def test_without_flow_an_unexplained_pair_is_refused_not_absurd() -> None:
    """Gain-mismatched sheathed sensors that follow the flow, characterised without it. This
    was 207 +/- 332 s and a reconstruction 2,500 K off the gas with exit 0, then refused; the
    sheathed path (crossfit + psi_map) now reconstructs it at 3.0x the oracle, 0.18 of the raw
    sensor's error, with ``adequate: false``."""
    _refused_or_honest(CASES[2])


def test_flow_without_flow_dependence_reports_constant() -> None:
    rec = _record(CASES[0], flow_law=False)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", reconstruction=None)
    model = result.estimate.flow_model
    assert model is not None
    assert model.kind == "constant" or abs(model.exponent) < 0.05
    np.testing.assert_allclose(result.estimate.time_constants[0][0], 4.0, rtol=0.03)
    np.testing.assert_allclose(result.estimate.time_constants[1][0], 8.0, rtol=0.03)


def test_a_flow_column_that_explains_nothing_is_named_in_the_warning() -> None:
    """A flow channel frozen after the first tenth of a drive cycle: no law fits, the model is
    constant and misfits, and the warning says the column showed no dependence instead of
    suggesting that the time constants follow the flow."""
    rec = _record(CASES[3])
    tenth = rec.t.size // 10
    flow = np.where(np.arange(rec.t.size) < tenth, rec.flow, rec.flow[tenth])
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=flow,
                                 flow_column="mdot", reconstruction=None)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "constant"
    check = result.model_check
    assert check is not None and not check.adequate
    assert any("no measurable dependence on the flow column 'mdot'" in reason
               for reason in check.reasons), check.reasons


def test_flow_dependence_is_not_reported_as_hysteresis() -> None:
    """The gas heats at high load (high flow: short time constants) and cools at low load;
    without the flow that looks like hysteresis, with it it must not."""
    rec = _record(CASES[3])
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", hysteresis=True, reconstruction=None)
    assert result.estimate.time_constants_heat is None


def test_a_hysteretic_pair_at_constant_flow_is_still_hysteretic() -> None:
    rng = np.random.default_rng(9)
    conditions = sim.drive_cycle(DURATION, rng)
    s1 = sim.FieldSensor(4.0, 0.0, cooling_factor=1.3, noise_std=NOISE)
    s2 = sim.FieldSensor(12.0, 0.0, cooling_factor=1.3, noise_std=NOISE)
    rec = sim.simulate_field_pair(conditions, s1, s2, sample_rate=RATE, rng=rng)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", hysteresis=True, order=1,
                                 reconstruction=None)
    heat, cool = result.estimate.time_constants_heat, result.estimate.time_constants_cool
    assert heat is not None and cool is not None
    for i, tau in enumerate((4.0, 12.0)):
        assert heat[i][0] == pytest.approx(tau, rel=0.05)
        assert cool[i][0] == pytest.approx(1.3 * tau, rel=0.05)


@pytest.mark.parametrize("bad", ["zero", "negative", "nan", "constant", "short"])
def test_bad_flow_is_a_one_line_input_error(bad: str) -> None:
    rec = _record(CASES[0])
    flow = rec.flow.copy()
    if bad == "zero":
        flow[100] = 0.0
    elif bad == "negative":
        flow[5] = -1.0
    elif bad == "nan":
        flow[7] = math.nan
    elif bad == "constant":
        flow[:] = 12.0
    else:
        flow = flow[:-1]
    with pytest.raises(InputError) as info:
        characterise_arrays(rec.t1, rec.t2, rec.ts, flow=flow, flow_column="flow",
                            reconstruction=None)
    assert "\n" not in str(info.value) and "flow" in str(info.value)


def test_without_flow_a_varying_pair_is_tracked_not_refused() -> None:
    """30 minutes of driving, m = 0.5, order auto, no flow column: the constant order-2 model
    is infeasible and the constant first-order one prefers a spurious 8 K offset; tracking
    with unit gains explains the data (found on this record: it once ended in "no positive
    real time constants ... (check the columns)")."""
    rng = np.random.default_rng(3)
    conditions = sim.drive_cycle(1800.0, rng)
    rec = sim.simulate_field_pair(conditions, sim.FieldSensor(4.0, 0.5),
                                  sim.FieldSensor(12.0, 0.5), sample_rate=RATE,
                                  quantisation=ADC, rng=rng)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert np.all(model.psi > 0.0)
    # the ratio of eq. 5 is held: 3 within the tracking's resolution
    ratio = result.estimate.time_constants[1][0] / result.estimate.time_constants[0][0]
    assert abs(ratio / 3.0 - 1.0) < 0.1, ratio
    assert result.gas_estimate is not None
    raw = _rmse(rec.t1, rec.tg)
    assert _rmse(result.gas_estimate, rec.tg) < 0.25 * raw


@pytest.mark.parametrize("case", [
    # sheath on the fast sensor only, unequal gains: the constant order-2 fit oscillates
    # (complex poles on both sensors, "6.1, 6.1 s"), misfit 850x the noise, and the smoother
    # fits a gas 69 K RMS off the truth with residuals at the noise
    Case(0.35, 2.2, (0.6, 0.0), (0.985, 1.02), 8),
    # sheath on the slow sensor only: the constant order-2 fit puts a shared 47.6 / 50.1 s
    # factor on both sensors (true elements 4.7 / 9.4 s), and the gas comes out 218 K off
    Case(0.4, 2.0, (0.0, 0.6), (1.0, 1.0), 10),
    # sheath on the slow sensor, unequal gains: a gain ratio of 0.876 (truth 0.953), and a gas
    # 104 K RMS from both sensors, 6.7 times their mutual disagreement where lagging sensors
    # allow 1.8 times: 90 K off the truth
    Case(0.41, 2.97, (0.0, 0.77), (0.98, 1.028), 203),
], ids=["complex-poles", "shared-factor", "departing-gas"])
def test_without_flow_a_misfit_constant_order_2_fit_is_refused_not_absurd(case: Case) -> None:
    """Flow-following pairs with one sheathed sensor, characterised without the flow: the
    constant order-2 fit absorbs the variation in poles no physics allows (each once came out
    with exit 0, then was refused). The sheathed path now gives 1.28x, 1.57x and 2.60x the
    oracle (the last with a misfit of 0.70, below the noise: it claimed to explain the data
    until every sheathed-path schedule got the model check's doubt); whatever it gives must
    be honest (``_refused_or_honest``)."""
    _refused_or_honest(case)


def test_with_flow_a_second_stage_that_moves_with_the_filter_is_not_kept() -> None:
    """Near-equal sheaths (0.54 / 0.61 s) that follow the flow with their own exponents (0.44,
    0.52; the elements 0.47), a fast element of 1.54 s: the model's common exponent cannot
    describe them, and the order-2 fit absorbed that in a stage nearly common to both sensors
    (3.39, 1.36 s and 4.83, 2.66 s for 1.54, 0.54 and 3.88, 0.61), reported as explaining
    the data, with a gas 17.7 K RMS off the truth where the raw fast sensor is 13 K off. Its
    second time constants move with the filter time constant (11 %), so the order chosen by
    evidence is 1, which says that it misfits (a warning, not "ok") and is 5.4 K off."""
    rng = np.random.default_rng(5107)
    conditions = sim.drive_cycle(DURATION, rng)
    s1 = sim.FieldSensor(1.54, 0.47, 0.54, sheath_exponent=0.44, noise_std=0.072)
    s2 = sim.FieldSensor(3.88, 0.47, 0.61, sheath_exponent=0.52, noise_std=0.072)
    rec = sim.simulate_field_pair(conditions, s1, s2, sample_rate=RATE, rng=rng)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", reconstruction="smoother")
    assert result.estimate.order == 1
    assert "filter time constant" in str(result.estimate.identifiability["order_fallback"])
    assert "filter time constant" in result.summary()
    assert result.model_check is not None and not result.model_check.adequate
    assert "model check: the model explains" not in result.summary()
    # not worse than the raw fast sensor (the discarded order-2 model was 1.37 times worse)
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.tg) < 0.6 * _rmse(rec.t1, rec.tg)


def test_uncertainty_of_a_sub_model_whose_full_order_2_solution_is_infeasible() -> None:
    """Orders (1, 2) chosen by evidence while the full (2, 2) solution puts a complex pair on
    sensor 1 (5 Hz, 0.1 K ADC steps, a sheath on sensor 2 with its own exponent): the
    uncertainty is the reported sub-model's. It was infinite for every parameter (each
    replicate took the full solution's infeasibility), with a reason blaming the record."""
    rng = np.random.default_rng(5105)
    conditions = sim.drive_cycle(DURATION, rng)
    s1 = sim.FieldSensor(2.9, 0.62, 0.0, noise_std=0.057)
    s2 = sim.FieldSensor(2.9 * 3.28, 0.62, 0.44, sheath_exponent=0.43, noise_std=0.057)
    rec = sim.simulate_field_pair(conditions, s1, s2, sample_rate=5.0, quantisation=0.1,
                                  rng=rng)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", reconstruction=None)
    conf = result.estimate.confidence
    assert conf is not None
    assert [len(taus) for taus in result.estimate.time_constants] == [1, 2]
    for name, std in conf.std.items():
        assert math.isfinite(std) and std < 0.05 * abs(conf.values[name]) + 0.01, name
    # the dominant time constants at the reference flow against the truth (sensor 1 at the
    # median flow: 2.9 s at v_ref = 20, scaled by (v/20)^-0.62)
    model = result.estimate.flow_model
    assert model is not None and model.reference_flow is not None
    truth = 2.9 * (model.reference_flow / 20.0) ** -0.62
    assert abs(result.estimate.time_constants[0][0] / truth - 1.0) < 0.05


def test_a_gain_ratio_without_a_value_is_named_not_printed_as_nan(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """An order-2 fit whose gain ratio had no finite value (a 50 Hz pair with a jittered clock)
    fell back to first order with the message "the second-order fit's gain ratio (nan) is not
    determined". The number a user reads is named, not printed as nan."""
    monkeypatch.setattr(order_choice, "undetermined_gain", lambda estimate: math.nan)
    rec = _record(CASES[1])
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", reconstruction="smoother")
    why = str(result.estimate.identifiability["order_fallback"])
    assert "gain ratio (no finite value)" in why and "nan" not in why.lower().split()
    assert "(nan)" not in result.summary()
