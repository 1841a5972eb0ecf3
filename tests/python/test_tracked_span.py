"""A tracked schedule that spans more than any exhaust's flow can make it is doubted (issue 11:
never "explains the data" beside a wrong answer).

Without a flow column the tracked common factor psi can absorb what the model lacks while the
misfit stays at the noise. On a pair beyond the issue's grid (50 Hz, 400 s, elements 2.75 /
4.0 s: a ratio of 1.46, 0.12 / 0.23 s sheaths, the slow sensor's logger holding 2 rows, 10 ms
clock jitter; ``logger_sweep.py 98 8 short``, case 98003) the tracked psi spanned 35-fold where
the truth spans 3.2-fold, its per-row time constants off by factors of 0.3-2.5 and the gas 4.8x
the oracle's error, and the model check said the model explains both signals (misfit 1.12).
Recordings from the separately written generator (``field_independent.py``).
"""

from __future__ import annotations

import numpy as np
import pytest

from dualprobe.estimation.field import FlowModel
from dualprobe.workflows.characterise import characterise_arrays
from dualprobe.workflows.checks import SPAN_LIMIT, schedule_span
from field_independent import record
from field_oracle import oracle

_SPAN_REASON = "the tracked time constants span"


def test_the_span_is_that_of_a_tracked_schedule_only() -> None:
    psi = np.geomspace(0.2, 6.0, 50)  # 30-fold
    assert schedule_span(FlowModel("tracked", psi)) == pytest.approx(30.0)
    # rows with no schedule (NaN) or a non-positive one do not make the span infinite
    assert schedule_span(FlowModel("tracked", np.r_[psi, np.nan, 0.0])) == pytest.approx(30.0)
    # a flow law spans what the flow column spans: the data vouch for it
    assert schedule_span(FlowModel("power_law", psi, column="mdot", exponent=0.5)) == 1.0
    assert schedule_span(None) == 1.0


@pytest.mark.slow
def test_a_tracked_schedule_beyond_any_exhaust_is_not_called_adequate() -> None:
    rec = record(98003, tau=2.75, ratio=1.46, m=0.52, rate=50.0, sheaths=(0.12, 0.23),
                 gains=(0.967, 0.97), noise=0.05, adc=0.02, jitter=0.01, hold=2,
                 duration=400.0)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t)
    check, model = result.model_check, result.estimate.flow_model
    assert check is not None and model is not None and result.gas_estimate is not None
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  sheath1=rec.sheath1, sheath2=rec.sheath2, static2=(0.97 / 0.967, 0.0),
                  gases=("rw",)).rmse
    ours = float(np.sqrt(np.mean((result.gas_estimate - rec.gas) ** 2)))
    tau1, _ = result.time_constants_per_row()
    tau_error = float(np.sqrt(np.mean((tau1 / rec.tau1 - 1.0) ** 2)))
    # the honesty property, whatever the tracker: a gas beyond the no-flow bound (2.5x
    # the oracle) or per-row time constants more than 15 % RMS off (three times the 5 % a
    # field characterisation is held to) never beside "adequate" (measured: 4.8x and 39 %, the
    # schedule 35-fold; a tracker that got them right would pass too)
    assert (ours <= 2.5 * best and tau_error <= 0.15) or not check.adequate, (ours / best,
                                                                             tau_error)
    # the truth spans 3.2-fold here: a span past the limit is what the check names
    span = schedule_span(model)
    assert (span > SPAN_LIMIT) == any(_SPAN_REASON in r for r in check.reasons), span
    assert float(np.max(rec.tau1) / np.min(rec.tau1)) < SPAN_LIMIT / 5.0
