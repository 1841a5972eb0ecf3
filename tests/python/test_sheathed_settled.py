"""Sheaths that the first-order tracking absorbs below twice the psi-noise limit are found by
the sheathed path, and its order-2 result is kept although its short sheath moves with the
filter setting (dualprobe.estimation.sheathed.SUSPECT, dualprobe.workflows.checks
.unsettled_stages), on the SEPARATE generator (tests/python/field_independent.py) against the
oracle that knows the true sensors. Its own file: at about 60 s it balances the xdist workers
(--dist loadfile)."""

from __future__ import annotations

import numpy as np

from dualprobe.estimation.confidence import SETTING_SHARE
from dualprobe.workflows.characterise import characterise_arrays
from field_independent import record as independent_record
from field_oracle import oracle
from test_field_independent import _rmse


def test_sheaths_absorbed_below_the_old_trigger_are_found_and_kept() -> None:
    """Sheaths 0.26 / 0.42 s on 5.1 / 19.1 s elements, gains 1.01 / 0.99 (20 min, 20 Hz; the
    sweep's pair 5307): the first-order psi follows the noise at 0.080, under the old trigger
    (0.10), so the sheathed path was not tried and the gas was 6.02x the oracle. Tried from the
    limit (0.05), it explains the data (0.89 times the noise, against 1.51 for the first-order
    tracking), and its short sheath moves 9 % with the filter setting, so the order-2 check
    used to drop it for first order (6.02x again). Kept: 2.03x measured."""
    rec = independent_record(5307, tau=5.1, ratio=3.74, m=0.47, rate=20.0, sheaths=(0.26, 0.42),
                             gains=(1.01, 0.99))
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.evidence.get("sheathed_path") == 1.0
    assert [len(taus) for taus in result.estimate.time_constants] == [2, 2]
    # the rule this pair is exempt from would have fired: the exemption is what is tested
    conf = result.estimate.confidence
    assert conf is not None
    assert conf.settings_std["tau1_1"] > SETTING_SHARE * conf.values["tau1_1"]
    # sheaths, not any second stage: measured 0.187 / 0.341 s (28 % and 19 % low; a sheath
    # under 0.3 s behind a 5 s element is seen weakly, crossfit's docstring: 0.115 for 0.19),
    # so a third off either way is the bound, where the 0.3 s and longer ones held 25 %
    found = [taus[1] for taus in result.estimate.time_constants]
    np.testing.assert_allclose(found, [0.26, 0.42], rtol=0.35)
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  sheath1=rec.sheath1, sheath2=rec.sheath2, static2=(0.99 / 1.01, 0.0),
                  gases=("rw",)).rmse
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 2.5 * best  # the bound without flow
    check = result.model_check
    assert check is not None and not check.adequate  # the sheathed path's schedule: warned
