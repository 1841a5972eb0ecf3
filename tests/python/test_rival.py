"""A tracked schedule the data do not determine is doubted (estimation/rival.py,
workflows/undetermined.py): a rival schedule that explains both signals as well and puts the gas
elsewhere widens T_g_std by half the distance, and the model check says so where that exceeds
the uncertainty stated without it. On the SEPARATE generator (field_independent.py)."""

from __future__ import annotations

import numpy as np

from dualprobe.workflows.characterise import characterise_arrays
from dualprobe.workflows.undetermined import LIMIT, WINDOW, undetermined
from field_independent import record
from field_oracle import oracle


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def test_a_tracked_schedule_the_readings_cannot_pin_is_doubted() -> None:
    # pair 5302 of field_sweep_independent.py 53 8: while a cruise's speed wobble moves the
    # gas by +-25 K and psi by +-30 %, the readings coincide; the tracked time constants were
    # 15 % RMS off, the gas 3.04x the oracle, and the model check called it adequate
    rec = record(5302, tau=6.52, ratio=2.16, m=0.62, rate=10.0, sheaths=(0.25, 0.21))
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked" and model.rival is not None
    assert result.model_check is not None and result.gas_estimate is not None
    assert result.gas_std is not None
    assert not result.model_check.adequate
    assert result.model_check.fits  # a doubt, not a misfit: both schedules explain the data
    assert any("another schedule explains both signals as well" in reason
               for reason in result.model_check.reasons)
    # the premise, against the truth: the per-row time constants are far off (measured 15 %)
    tau1 = result.time_constants_per_row()[0]
    assert _rms(np.log(tau1 / rec.tau1) - np.mean(np.log(tau1 / rec.tau1))) > 0.08
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  sheath1=rec.sheath1, sheath2=rec.sheath2, gases=("rw",)).rmse
    ours = _rms(result.gas_estimate - rec.gas)
    assert ours > 2.5 * best, (ours, best)  # beyond the bound: a doubt is owed


def test_a_well_determined_tracked_schedule_keeps_its_verdict() -> None:
    # an unsheathed pair of 3 / 10.5 s, m 0.4 (1.16x the oracle): the MAP's schedule explains
    # the data too (0.87 times the noise), and its gas stays within the posterior's band
    # (measured: the worst 30 s window at 0.34 of it)
    rec = record(12, tau=3.0, ratio=3.5, m=0.4, rate=10.0)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked" and model.rival is not None
    assert result.model_check is not None and result.model_check.adequate
    assert result.gas_estimate is not None
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  gases=("rw",)).rmse
    assert _rms(result.gas_estimate - rec.gas) <= 1.5 * best  # measured 1.16x


def test_the_worst_window_is_found_and_judged_against_the_stated_uncertainty() -> None:
    ts = 0.1
    rows = round(10 * WINDOW / ts)
    gas = np.zeros(rows)
    rival = np.zeros(rows)
    stretch = slice(round(4 * WINDOW / ts), round(5 * WINDOW / ts))
    rival[stretch] = 3.0  # half-difference 1.5 K over one window
    std = np.full(rows, 0.5)
    found = undetermined(gas, rival, std, ts)
    assert found is not None
    assert found.ratio == 3.0 and found.kelvin == 1.5 and found.start == 4 * WINDOW
    assert found.doubtful and found.ratio > LIMIT
    assert np.all(found.spread[stretch] == 1.5) and found.spread[0] == 0.0
    # the same spread beside an uncertainty that already covers it is no doubt
    assert not undetermined(gas, rival, np.full(rows, 2.0), ts).doubtful  # type: ignore[union-attr]
    # a gas with no finite row has nothing to judge
    assert undetermined(np.full(rows, np.nan), rival, std, ts) is None


def test_a_one_sigma_move_counts_all_of_its_distance() -> None:
    """The common part of near-equal stages (workflows/common_part.py) is judged by the gas one
    standard uncertainty away: that whole distance is uncertainty, not half of it."""
    ts = 0.1
    rows = round(3 * WINDOW / ts)
    gas, moved, std = np.zeros(rows), np.full(rows, 1.2), np.full(rows, 0.5)
    found = undetermined(gas, moved, std, ts, cause="common part")
    assert found is not None and found.kelvin == 1.2 and found.ratio == 1.2 / 0.5
    assert found.doubtful and "common part" in found.reason()
    assert undetermined(gas, moved, std, ts).kelvin == 0.6  # type: ignore[union-attr]
