"""The sheathed path's MAP psi where the gas stands still (issue 11). psi is unobservable
there, and with heavy-tailed knot steps alone (psi_map.map_psi's reweightings) it drifted
without bound: the bench's sheathed no-flow recording (30 min at 10 Hz, a 0.7 s sheath on a
4 s element, m 0.5, `dualprobe bench --section pipeline`) opens with 22 s of idle, where log
psi went to -5.4; the 4 s element read as 1120 s and the pair was refused as implausible
(exit 3). psi_map's weak prior on every knot's level (``level_std``) holds it."""

from __future__ import annotations

import numpy as np

from dualprobe import simulate as sim
from dualprobe.workflows.characterise import characterise_arrays
from field_oracle import oracle
from test_field_conditions import ADC, NOISE


def test_an_idle_start_leaves_the_sheathed_path_s_psi_where_it_was() -> None:
    rng = np.random.default_rng(7)
    conditions = sim.drive_cycle(600.0, rng)
    rec = sim.simulate_field_pair(conditions, sim.FieldSensor(4.0, 0.5, 0.7, noise_std=NOISE),
                                  sim.FieldSensor(12.0, 0.5, 0.0, noise_std=NOISE),
                                  sample_rate=10.0, quantisation=ADC, rng=rng)
    # the idle start: the gas within 10 K for 20 s (its fluctuation), then 130 K within 10 s
    assert np.ptp(rec.tg[:200]) < 10.0 < 100.0 < np.ptp(rec.tg[200:300])
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert model.evidence.get("sheathed_path") == 1.0
    # the fast element per row over the truth. Measured: up to 5.6x within the idle start,
    # where the gas stands still and nothing tells psi (unanchored: 239x, and refused), 0.45-1.6
    # on 5-95 % of the rows, and within 2x on every row after the first 22 s
    ratio = result.estimate.time_constants[0][0] / model.psi / rec.tau1
    assert np.max(ratio) < 10.0, np.max(ratio)
    assert np.all(ratio[220:] < 2.0) and np.all(ratio > 0.25), (np.min(ratio), ratio[220:].max())
    assert result.gas_estimate is not None
    ours = float(np.sqrt(np.mean((result.gas_estimate - rec.tg) ** 2)))
    best = oracle(rec.t, rec.t1, rec.t2, rec.tg, rec.tau1, rec.tau2, (NOISE, NOISE),
                  sheath1=rec.sheath1, gases=("rw",)).rmse
    assert ours <= 2.5 * best, ours / best  # issue 11's bound without the flow (1.33x measured)
