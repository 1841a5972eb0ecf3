"""The sheathed path's psi freed where the data repeat a looser one (issue 11, without a flow
signal; MapSchedule.freed in dualprobe.estimation.map_schedule, kept by sheathed.track_at
only where the engine then fits better). On the SEPARATE generator (field_independent.py),
against the oracle given the true sensors."""

from __future__ import annotations

import dataclasses
import types
from typing import cast

import numpy as np

import field_independent as fi
from dualprobe.estimation.engine import Fit
from dualprobe.estimation.map_schedule import MapSchedule
from field_oracle import at_level, oracle

_FIELDS = ("t", "t1", "t2", "mass_flow", "gas", "tau1", "tau2", "sheath1", "sheath2")


def test_a_schedule_held_back_where_the_load_swings_fast_is_freed_there() -> None:
    # Pair 30603 of field_sweep_independent.py (20 Hz, m 0.68, elements 7.8 / 28.9 s, sheaths
    # 0.38 / 0.23 s), its 300 s from 780 s: the load swings 500-580 K every 5.5 s at 840-870 s
    # and the true psi 0.66-2.9 over the stretch. Given the TRUE stages (at the schedule's
    # level) the MAP's tight prior holds psi back there; the freed psi keeps what the even
    # and odd rows repeat of a looser one.
    rec = fi.record(30603, duration=1200.0, rate=20.0, tau=7.8, ratio=3.7, m=0.68,
                    sheaths=(0.38, 0.23))
    rows = slice(780 * 20, 1080 * 20)
    rec = dataclasses.replace(rec, **{k: getattr(rec, k)[rows] for k in _FIELDS})
    sigma = (rec.noise, rec.noise)
    stages = [(at_level(rec.sheath1), at_level(rec.tau1)),
              (at_level(rec.sheath2), at_level(rec.tau2))]
    # MapSchedule reads the constant fit's sample interval, filter setting and noise only
    # (tf: the engine's on this pair's fast element, 4.2 s)
    fit = cast(Fit, types.SimpleNamespace(ts=rec.ts, tf=4.2, sigma=sigma))
    maps = MapSchedule(rec.t1, rec.t2, fit)
    maps.set_model((1.0, 0.0), stages[0][1])
    tight = maps.schedule(stages)
    freed = maps.freed(stages)
    assert tight is not None and freed is not None

    def gas_rmse(psi: np.ndarray | None) -> float:
        """The oracle's gas with the true stages on this schedule (None: the true one)."""
        if psi is None:
            return oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, sigma,
                          sheath1=rec.sheath1, sheath2=rec.sheath2, gases=("rw",)).rmse
        return oracle(rec.t, rec.t1, rec.t2, rec.gas, stages[0][1] / psi, stages[1][1] / psi,
                      sigma, sheath1=stages[0][0] / psi, sheath2=stages[1][0] / psi,
                      gases=("rw",)).rmse

    best, held, kept = gas_rmse(None), gas_rmse(tight), gas_rmse(freed[0])
    # measured 2.08x and 1.55x the oracle (share 0.64); 0.9 asks for a tenth of the error at
    # least, a third of what was measured
    assert kept < 0.9 * held, (held / best, kept / best)
    truth = np.log(rec.tau1)
    def log_error(psi: np.ndarray) -> float:  # log psi against the truth's, both centred
        error = np.log(psi) + truth
        return float(np.sqrt(np.mean((error - np.mean(error)) ** 2)))
    # measured 0.081 -> 0.069
    assert log_error(freed[0]) < log_error(tight)
    assert 0.2 < freed[1] < 1.0  # the share kept: measured 0.64
