"""A first-order tracked psi that follows the noise gives way to the sheathed path when that
explains the data with a determined psi and the sheaths the first-order psi absorbed
(dualprobe.estimation.without_flow._sheathed), on the SEPARATE generator
(tests/python/field_independent.py) against the oracle that knows the true sensors. Its own
file: at 85 s it balances the xdist workers (--dist loadfile)."""

from __future__ import annotations

import numpy as np

from dualprobe.workflows.characterise import characterise_arrays
from field_independent import record as independent_record
from field_oracle import oracle
from test_field_independent import _rmse


def test_a_first_order_psi_that_follows_the_noise_gives_way_to_found_sheaths() -> None:
    """Sheaths 0.4 / 0.6 s on 5 / 12.5 s elements (20 min, 10 Hz): first-order tracking
    absorbs the sheaths, its psi 14 % of noise (psi_noise 0.136) at a misfit of 1.08, which
    the sheathed path (0.91) cannot beat by the misfit's evidence; kept, the gas was 4.8x the
    oracle. Both explain the data, only the MAP's psi is determined (1.8 %), and the engine
    finds both sheaths on it, so the sheathed path is taken: 1.28x measured."""
    rec = independent_record(7, tau=5.0, ratio=2.5, m=0.5, rate=10.0, sheaths=(0.4, 0.6))
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.evidence.get("sheathed_path") == 1.0
    assert 0.0 < model.psi_noise < 0.05
    assert [len(taus) for taus in result.estimate.time_constants] == [2, 2]
    # the sheaths found: 0.34 / 0.55 s measured (15 % and 8 % low); 25 % is what the sheathed
    # path's stages of 0.3 s and over were within on the separate generator (0.25 / 0.40 s for
    # 0.31 / 0.45 s on another pair): sheaths, not any second stage
    found = [taus[1] for taus in result.estimate.time_constants]
    np.testing.assert_allclose(found, [0.4, 0.6], rtol=0.25)
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  sheath1=rec.sheath1, sheath2=rec.sheath2, gases=("rw",)).rmse
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 2.5 * best  # the bound without flow
    check = result.model_check
    assert check is not None and not check.adequate  # the sheathed path's schedule: warned
