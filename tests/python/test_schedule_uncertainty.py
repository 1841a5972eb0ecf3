"""``reconstruct(..., schedule_log_std=s)``: the time constants' relative error per row carried
into ``gas_std`` by the delta method (half the change of the gas between the schedule moved by
exp(+s) and exp(-s), in quadrature with the posterior). Its coverage of the true gas, with the
product's own tracked schedule, is tested in test_field_independent.py; here its mechanics on
a drive cycle from the project's simulator with the true time constants."""

from __future__ import annotations

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.reconstruction import Reconstruction, reconstruct


@pytest.fixture(scope="module")
def drive() -> tuple[sim.FieldRecording, np.ndarray]:
    rng = np.random.default_rng(8)
    conditions = sim.drive_cycle(300.0, rng)
    rec = sim.simulate_field_pair(conditions, sim.FieldSensor(4.0, 0.5),
                                  sim.FieldSensor(12.0, 0.5), sample_rate=10.0,
                                  quantisation=0.02, rng=rng)
    return rec, rec.tau1 / 4.0  # the true schedule (time constants 4 / 12 s times it)


def _run(drive: tuple[sim.FieldRecording, np.ndarray], mode: str, log_std: float
         ) -> Reconstruction:
    rec, schedule = drive
    return reconstruct(rec.t1, rec.t2, rec.ts, [4.0], [12.0], mode=mode, noise_std=0.05,
                       schedule=schedule, schedule_log_std=log_std)


@pytest.mark.parametrize("mode", ["smoother", "filter"])
def test_the_schedule_error_adds_to_gas_std_and_leaves_the_gas(
        drive: tuple[sim.FieldRecording, np.ndarray], mode: str) -> None:
    base = _run(drive, mode, 0.0)
    added = {s: np.sqrt(np.maximum(_run(drive, mode, s).gas_std ** 2 - base.gas_std ** 2, 0.0))
             for s in (0.01, 0.02)}
    moved = _run(drive, mode, 0.02)
    np.testing.assert_array_equal(moved.gas, base.gas)  # only the uncertainty changes
    assert np.all(moved.gas_std >= base.gas_std)
    # a first-order sensor's reading moves with log tau by its lag, tau T' = T_g - T: the added
    # part per unit s is of the size of the fast sensor's lag (measured 1.2x its median for
    # the smoother, 1.1x for the filter; a factor 3 either way allows the weighting of the
    # two sensors, whose lags differ by 3x)
    lag = float(np.median(np.abs(drive[0].tg - drive[0].t1)))
    assert lag / 3.0 < float(np.median(added[0.02])) / 0.02 < 3.0 * lag
    # the delta method is linear in s: doubling s doubles the added part (measured 2.0001;
    # 1 % allows the gas's curvature in log tau over +-2 %)
    busy = added[0.02] > np.quantile(added[0.02], 0.5)
    ratio = np.median(added[0.02][busy] / added[0.01][busy])
    assert abs(ratio - 2.0) < 0.02, ratio


@pytest.mark.parametrize("bad", [-0.01, float("nan"), float("inf")])
def test_a_bad_schedule_error_is_refused(drive: tuple[sim.FieldRecording, np.ndarray],
                                         bad: float) -> None:
    with pytest.raises(ValueError, match="schedule_log_std"):
        _run(drive, "smoother", bad)


def test_without_a_schedule_the_error_has_nothing_to_move(
        drive: tuple[sim.FieldRecording, np.ndarray]) -> None:
    rec, _ = drive
    plain = reconstruct(rec.t1, rec.t2, rec.ts, [4.0], [12.0], noise_std=0.05)
    same = reconstruct(rec.t1, rec.t2, rec.ts, [4.0], [12.0], noise_std=0.05,
                       schedule_log_std=0.05)
    np.testing.assert_array_equal(plain.gas_std, same.gas_std)
