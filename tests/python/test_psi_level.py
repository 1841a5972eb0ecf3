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
from field_oracle import oracle, worst_factor
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


def test_where_the_readings_cross_the_tracked_time_constants_stay_near_the_truth() -> None:
    """A sheathed pair of the field sweep (``field_sweep.py 7 12 noflow``, case 810: m 0.68,
    ratio 3.81, a 0.5 s sheath on the fast element). Where the two readings cross while the gas
    holds, psi is unobservable for a few seconds; with the level prior at sd 1 the MAP's psi
    went 17x above the truth and back there (the 3.3 s element read as 56 s, the per-row time
    constants 74 % RMS off; the gas unaffected), written so into the ``--output`` CSV; and
    with the knot steps' Cauchy tail unbounded psi overshot at load steps (down to 0.04x)."""
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    from test_field_conditions import Case, _record

    rec = _record(Case(0.68, 3.81, (0.5, 0.0), (1.0, 1.0), 810))
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.sheathed_path
    tau1, tau2 = result.time_constants_per_row()
    ratio = np.concatenate([tau1 / rec.tau1, tau2 / rec.tau2])
    # measured 0.098 (level sd 1: 0.74; sd 0.5 with the knot steps' tail uncapped: 0.13)
    rms = float(np.sqrt(np.mean((ratio - 1.0) ** 2)))
    assert rms < 0.25, rms
    # Every row: measured 0.47-2.02x the truth. With the tail uncapped (psi_map._STEP_CAP)
    # psi overshot at load steps, down to 0.04x for under a second; with sd 1, 16.8x.
    worst = worst_factor(ratio)
    assert worst < 4.0, worst
    # Rows whose true time constant holds within 10 % for 2 s either side (71 % of them),
    # where the readings cross while the gas holds: measured 0.57-1.47x (sd 1: up to 16.8x).
    log_tau = np.log(rec.tau1)
    width = 2 * round(2.0 / rec.ts) + 1
    steady = maximum_filter1d(log_tau, width) - minimum_filter1d(log_tau, width) < np.log(1.1)
    held = tau1[steady] / rec.tau1[steady]
    assert 1.0 / 3.0 < held.min() and held.max() < 3.0, (held.min(), held.max())
