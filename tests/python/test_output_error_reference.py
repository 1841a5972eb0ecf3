"""The independent check of the flow-scheduled estimator (issue 11, item 6):
dualprobe.reference.output_error fits both sensors' outputs to one common gas by maximum
likelihood (a Kalman filter's prediction error decomposition), a different method from the
product's cross-relation (the gas eliminated, generalised total least squares on filtered
derivatives). Both run on the same simulated drive cycles and must agree with each other and
with the truth within their own standard uncertainties."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from dualprobe import simulate as sim
from dualprobe.reference import output_error
from dualprobe.workflows.characterise import characterise_arrays


def test_stacked_expm_matches_scipy() -> None:
    rng = np.random.default_rng(1)
    a = rng.normal(size=(300, 6, 6)) * rng.uniform(0.01, 3.0, (300, 1, 1))
    ours = output_error._expm(a)
    # rounding only: squarings of a norm-0.5 Taylor sum lose ~1e-11 relative at norm ~20
    assert np.max(np.abs(ours - scipy.linalg.expm(a)) / np.maximum(1.0, np.abs(ours))) < 1e-9


def test_likelihood_is_highest_near_the_truth() -> None:
    """The likelihood of the true model beats time constants 5 % off (either way) by far
    more than sampling allows (a log-likelihood difference of 2 is already significant)."""
    rec = _drive_cycle((0.0, 0.0), (1.0, 1.0))
    psi = (rec.flow / float(np.median(rec.flow))) ** 0.5
    i = int(np.argmin(np.abs(rec.flow - np.median(rec.flow))))
    taus = (rec.tau1[i], rec.tau2[i])

    def nll(f1: float, f2: float) -> float:
        return output_error.negative_log_likelihood(rec.t, rec.t1, rec.t2, psi, (f1 * taus[0],),
                                                    (f2 * taus[1],), 100.0, (0.05, 0.05))

    best = nll(1.0, 1.0)
    for f1, f2 in ((1.05, 1.0), (0.95, 1.0), (1.0, 1.05), (1.0, 0.95)):
        assert nll(f1, f2) > best + 20.0


def _drive_cycle(sheaths: tuple[float, float], gains: tuple[float, float]) -> sim.FieldRecording:
    # 150 s at 10 Hz: the reference's Python loop over the rows costs ~10-20 s per fit here
    rng = np.random.default_rng(11)
    conditions = sim.drive_cycle(150.0, rng)
    s1 = sim.FieldSensor(4.0, 0.5, sheaths[0], gain=gains[0], noise_std=0.05)
    s2 = sim.FieldSensor(12.0, 0.5, sheaths[1], gain=gains[1], noise_std=0.05)
    return sim.simulate_field_pair(conditions, s1, s2, sample_rate=10.0, quantisation=0.02,
                                   rng=rng)


@pytest.mark.parametrize("sheaths", [(0.0, 0.0), (0.3, 0.0)], ids=["first-order", "sheathed"])
def test_product_and_output_error_reference_agree(sheaths: tuple[float, float]) -> None:
    rec = _drive_cycle(sheaths, (1.0, 1.0))
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.flow,
                                 flow_column="flow", reconstruction="smoother")
    doc = result.to_json_dict()
    model = doc["flow_model"]
    assert model["kind"] == "power_law"
    # the reference starts from round numbers, not from the product's answer
    start1 = (0.5, 2.0) if sheaths[0] else (2.0,)
    ref = output_error.fit_output_error(rec.t, rec.t1, rec.t2, rec.flow, start1, (8.0,))
    assert ref.success
    i = int(np.argmin(np.abs(rec.flow - model["reference_flow"])))
    truth = [(rec.tau1[i], rec.sheath1[i]), (rec.tau2[i], rec.sheath2[i])]
    for k, sensor in enumerate(doc["sensors"]):
        ours, ours_std = sensor["time_constants"], sensor["time_constants_std"]
        theirs, theirs_std = ref.taus[k][::-1], ref.taus_std[k][::-1]  # element first
        assert len(ours) == len(theirs) == (2 if sheaths[k] else 1)
        for j in range(len(ours)):
            # Two estimates from the same data: their difference has at most the sum of the
            # variances (less when correlated); 4 standard deviations leave room for the
            # methods' different small-sample biases (measured 0.4-1.2 of the combined std).
            combined = math.hypot(ours_std[j], theirs_std[j])
            assert abs(ours[j] - theirs[j]) < 4.0 * combined, (k, j, ours, theirs)
            # and the reference, the efficient estimator, agrees with the truth
            assert abs(theirs[j] - truth[k][j]) < 4.0 * theirs_std[j], (k, j, theirs, truth)
    combined = math.hypot(model["exponent_std"], ref.exponent_std)
    assert abs(model["exponent"] - ref.exponent) < 4.0 * combined
    assert abs(ref.exponent - 0.5) < 4.0 * ref.exponent_std
    # the noise it finds is the simulated one (0.05 K, quantised by 0.02 K steps: +0.006 K)
    assert all(0.04 < s < 0.06 for s in ref.sigma)
