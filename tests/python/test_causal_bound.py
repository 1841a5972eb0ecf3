"""The genie bound on causal reconstruction (firmware_sim/tools/causal_bound.py, reported by
`make firmware` as robust.drive_cycle.causal_bound): its Riccati-predicted RMSE must be what its
filter actually achieves on data. The data come from the simulator itself (the drive cycle's
fluctuation alone, isolated by running the cycle twice with the same seed, with and without
it, through the simulator's own flow-dependent sheathed sensors), not from the bound's model."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

import numpy as np
import scipy.linalg

from dualprobe import simulate

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "firmware_sim" / "tools"))

import causal_bound

TS = 0.01
NOISE = 0.02


def _fluctuation_record(seconds: float):
    full = simulate.drive_cycle(seconds + 1.0, np.random.default_rng(3))
    flat = simulate.drive_cycle(seconds + 1.0, np.random.default_rng(3), fluctuation_std=0.0)
    conditions = dataclasses.replace(full, gas=500.0 + (full.gas - flat.gas))
    s1 = simulate.FieldSensor(tau_ref=1.2, exponent=0.5, sheath_tau_ref=0.15, noise_std=NOISE)
    s2 = simulate.FieldSensor(tau_ref=3.0, exponent=0.5, sheath_tau_ref=0.3, noise_std=NOISE)
    return simulate.simulate_field_pair(conditions, s1, s2, sample_rate=1.0 / TS, v_ref=20.0,
                                        rng=np.random.default_rng(9))


def test_the_bound_is_what_its_filter_achieves_on_simulated_data() -> None:
    rec = _fluctuation_record(300.0)
    n = round(300.0 / TS)
    truth = {"ts": TS, "sigma1": NOISE, "sigma2": NOISE,
             "true_taus1": np.column_stack([rec.tau1[:n], rec.sheath1[:n]]),
             "true_taus2": np.column_stack([rec.tau2[:n], rec.sheath2[:n]])}
    var_f, var_s = causal_bound.causal_bound(truth, simulate)
    # The same filter run on the data (the genie knows the slow part: here the constant 500 K).
    fa, fb, row, q, dt = causal_bound.fluctuation_model(simulate)
    nb = fa.shape[0]
    size = nb + 5
    gas = np.zeros(size)
    gas[: nb + 1] = row
    h = np.zeros((2, size))
    h[0, nb + 2] = h[1, nb + 4] = 1.0
    r = NOISE**2 * np.eye(2)
    x = np.zeros(size)
    p = np.zeros((size, size))
    p[:nb, :nb] = q * scipy.linalg.solve_discrete_lyapunov(fa, np.outer(fb, fb))
    p[nb, nb] = q
    fresh = np.zeros((size, size))
    fresh[nb, nb] = q
    y = np.column_stack([rec.t1[:n], rec.t2[:n]]) - 500.0
    estimate = np.empty(n)
    for k in range(n):
        if k:
            fine = causal_bound.fine_step(fa, fb, row, dt, truth["true_taus1"][k - 1],
                                           truth["true_taus2"][k - 1])
            x = fine @ fine @ x
            p = fine @ (fine @ p @ fine.T + fresh) @ fine.T + fresh
        gain = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
        x = x + gain @ (y[k] - h @ x)
        p = p - gain @ h @ p
        estimate[k] = gas @ x
    skip = slice(500, n)  # the first 5 s: the filter's start
    achieved = np.sqrt(np.mean((estimate[skip] - (rec.tg[:n][skip] - 500.0)) ** 2))
    predicted = np.sqrt(np.mean(var_f[skip]))
    # ~300 independent seconds of a ~1 Hz error: the RMSE is estimated to ~4 % (1 sigma);
    # 10 % allows 2.5 sigma. Measured: 0.649 K achieved against 0.642 K predicted.
    assert abs(achieved / predicted - 1.0) < 0.10, (achieved, predicted)
    # The smoother's error is far below the filter's: the price of causality on this gas.
    assert np.sqrt(np.mean(var_s[skip])) < 0.5 * predicted
