"""A first-order tracked psi that follows the noise gives way to the sheathed path when that
explains the data with a determined psi and the sheaths the first-order psi absorbed
(dualprobe.estimation.sheathed.track_at), on the SEPARATE generator
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


def test_an_oscillating_fit_that_misfits_by_its_own_rows_does_not_replace_first_order() -> None:
    """An unsheathed 5 Hz pair, m = 0.7 (elements 4 / 10 s, 20 min): first-order tracking
    explains the data (1.08 times the noise) with a psi 16 % of noise, so the sheathed path is
    tried; its schedule's fit (1.29 times the noise, a complex pole pair on the slow sensor) was
    taken as explaining the data by the constant fit's effective rows (1291: 7.4 deviations)
    where its own (3672) make it 13, and the characterisation was refused (exit 3: the fit
    oscillates; its gas 46 K off). Kept first order instead: 1.46x the oracle measured, warned
    because its psi follows the noise."""
    rec = independent_record(9012, rate=5.0, tau=4.0, ratio=2.5, m=0.7)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert model.evidence.get("sheathed_path", 0.0) == 0.0
    assert result.gas_estimate is not None and result.model_check is not None
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  gases=("rw",)).rmse
    assert _rmse(result.gas_estimate, rec.gas) <= 2.5 * best  # the bound without flow
    # the honesty property: its per-row time constants are 33 % RMS off (measured), beyond the
    # 15 % (three times the 5 %) that may stand beside "adequate"
    tau1, tau2 = result.time_constants_per_row()
    ratios = np.concatenate([tau1 / rec.tau1, tau2 / rec.tau2])
    assert float(np.sqrt(np.mean((ratios - 1.0) ** 2))) <= 0.15 or not result.model_check.adequate
