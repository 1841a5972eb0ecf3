"""The sheathed path's sheaths profiled by the MAP's cost (issue 11, without a flow signal;
dualprobe.estimation.without_flow._profile_sheaths). The MAP's psi, and the gas with it, are
steep in a sheath's value: a sheath 12 % short left psi late and smeared at every load step
and the gas at 2.56x the oracle. Its own file: about 40 s (--dist loadfile)."""

from __future__ import annotations

import numpy as np

from dualprobe.workflows.characterise import characterise_arrays
from test_field_conditions import Case, _oracle_rmse, _record, _rmse


def _geometric_mean(values: np.ndarray) -> float:
    return float(np.exp(np.mean(np.log(values))))


def test_a_single_sheath_is_profiled_to_where_the_gas_is_right() -> None:
    """Pair 203 of ``field_sweep.py 1 8 noflow``: m 0.41, ratio 2.97, one 0.77 s sheath (0.82 s
    on the record's geometric mean) on the slow sensor, gains 0.98 / 1.028. The engine's fit
    on the MAP's psi found the sheath at 0.72 s; with it the gas was 2.04 K against the
    oracle's 0.80 K (2.56x), with the TRUE psi and the same stages 0.93 K."""
    case = Case(0.41, 2.97, (0.0, 0.77), (0.98, 1.028), 203)
    rec = _record(case)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.sheathed_path
    taus = result.estimate.time_constants
    assert [len(pair) for pair in taus] == [1, 2]
    # Both at the schedule's level (the mean of log psi 0): the time constants in effect over
    # the record's geometric mean. Measured: the sheath 0.72 s before the profile (12 % short).
    sheath = _geometric_mean(taus[1][1] / model.psi)
    truth = _geometric_mean(rec.sheath2)
    assert abs(sheath / truth - 1.0) < 0.08, (sheath, truth)
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, case.gains[0] * rec.tg)
    best = _oracle_rmse(rec, case)
    # measured 1.18x (2.56x before); the bound without the flow is 2.5x, and 1.6x
    # keeps most of what the profile gained
    assert ours <= 1.6 * best, ours / best
