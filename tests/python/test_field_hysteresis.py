"""Direction-dependent time constants on drive cycles (issue 11: "direction dependence must work
with [the flow]"), on the project's drive-cycle simulator, whose direction switches at the fine
step where the gas crosses each stage (the estimator classifies 10 Hz rows by their slopes).

A 1 Hz gas fluctuation turns the fast sensor about once a second, so the split columns'
noise model needs the switch term (design.md 1.4): without it the misfit of these pairs read
1.48-1.77 times the noise and the check said "does not explain the data" beside correct time
constants."""

from __future__ import annotations

import numpy as np

from dualprobe import simulate as sim
from dualprobe.workflows.characterise import characterise_arrays


def _pair(seed: int, m: float, cooling: float, tau: float = 5.0,
          duration: float = 1800.0) -> sim.FieldRecording:
    rng = np.random.default_rng(seed)
    conditions = sim.drive_cycle(duration, rng)
    sensors = [sim.FieldSensor(t, m, cooling_factor=cooling, noise_std=0.05)
               for t in (tau, 3.0 * tau)]
    return sim.simulate_field_pair(conditions, *sensors, sample_rate=10.0, quantisation=0.02,
                                   rng=rng)


def test_flow_law_and_direction_split_together() -> None:
    """m 0.5, cooling 1.2 times slower: with --flow and --hysteresis the power law and the split
    are both identified (measured: m 0.501, cooling / heating 1.195 and 1.197, the gas 0.95 K
    RMS against 18 K for the raw fast sensor)."""
    rec = _pair(14, 0.5, 1.2)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", hysteresis=True, order=1,
                                 reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    assert abs(model.exponent - 0.5) < 0.02  # the 0.05, measured 0.001
    heat, cool = result.estimate.time_constants_heat, result.estimate.time_constants_cool
    assert heat is not None and cool is not None
    for i in range(2):
        # the direction ratio at 2 % (measured 0.4 %); the ratio of eq. 5 at 2 %
        assert abs(cool[i][0] / heat[i][0] / 1.2 - 1.0) < 0.02
    assert abs(heat[1][0] / heat[0][0] / 3.0 - 1.0) < 0.02
    assert result.gas_estimate is not None
    raw = float(np.sqrt(np.mean((rec.t1 - rec.tg) ** 2)))
    ours = float(np.sqrt(np.mean((result.gas_estimate - rec.tg) ** 2)))
    assert ours < 0.1 * raw  # measured 0.05


def test_a_split_misfit_names_the_split_not_hysteresis() -> None:
    """At constant flow a 30 min hysteretic pair still carries a misfit beyond the noise (1.5:
    intervals misclassified where the fast sensor turns); the warning names that limit and
    does not propose hysteresis, which the model already has."""
    rec = _pair(11, 0.0, 1.3, tau=4.0)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, hysteresis=True, order=1,
                                 reconstruction=None)
    check = result.model_check
    assert check is not None
    heat, cool = result.estimate.time_constants_heat, result.estimate.time_constants_cool
    assert heat is not None and cool is not None
    assert abs(heat[0][0] / 4.0 - 1.0) < 0.01 and abs(cool[0][0] / 5.2 - 1.0) < 0.01
    # measured 14 standard deviations (the threshold 10): the classification's limit, which a
    # better split would lower; until then the warning must say what it is
    assert not check.adequate
    reason = next(r for r in check.reasons if "does not explain the data" in r)
    assert "heating/cooling split, decided from each sensor's slope" in reason
    assert "hysteretic" not in reason


def test_a_sheathed_pair_is_not_explained_by_the_split() -> None:
    """Sheaths of 0.5 / 0.75 s on a hysteretic pair: the split is first order, so its model
    cannot explain them (measured misfit 126 with the flow); the warning says to leave the
    split out to identify the sheath stage."""
    rng = np.random.default_rng(3)
    conditions = sim.drive_cycle(1200.0, rng)
    sensors = [sim.FieldSensor(tau, 0.5, sheath_tau_ref=sheath, cooling_factor=1.3,
                               noise_std=0.05) for tau, sheath in ((4.0, 0.5), (12.0, 0.75))]
    rec = sim.simulate_field_pair(conditions, *sensors, sample_rate=10.0, quantisation=0.02,
                                  rng=rng)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", hysteresis=True, reconstruction=None)
    check = result.model_check
    assert check is not None and not check.adequate and not check.fits
    reason = next(r for r in check.reasons if "does not explain the data" in r)
    assert "leave --hysteresis out to identify a sheath stage" in reason
