"""The sheathed path's sheaths (issue 11, without a flow signal;
dualprobe.estimation.sheathed.track_at): profiled by the MAP's cost
(sheath_profile.profile_sheaths), and seeded where the cross-relation found none. The MAP's
psi, and the gas with it, are steep in a sheath's value: a sheath 12 % short left psi late and
smeared at every load step and the gas at 2.56x the oracle; sheaths missed altogether, 5.3x.
Its own file: about 160 s (--dist loadfile)."""

from __future__ import annotations

import field_independent as fi
from dualprobe.workflows.characterise import characterise_arrays
from field_oracle import at_level
from test_field_conditions import Case, _oracle_rmse, _record, _rmse
from test_field_independent import _oracle_rmse as independent_oracle_rmse


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
    sheath = at_level(taus[1][1] / model.psi)
    truth = at_level(rec.sheath2)
    assert abs(sheath / truth - 1.0) < 0.08, (sheath, truth)
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, case.gains[0] * rec.tg)
    best = _oracle_rmse(rec, case)
    # measured 1.18x (2.56x before); the bound without the flow is 2.5x, and 1.6x
    # keeps most of what the profile gained
    assert ours <= 1.6 * best, ours / best


def test_sheaths_the_cross_relation_missed_are_seeded() -> None:
    """Pair 5301 of ``field_sweep_independent.py 53 8`` at 10 Hz (the separate generator: fast
    element 7.99 s, ratio 3.54, m 0.42, sheaths 0.38 / 0.56 s, gains 1.017 / 1.024). The
    cross-relation's second-order coefficients come out negative on both sensors (from every
    start: the noise in its regressors biases them low), so the MAP and the engine started
    without sheaths and stayed first order: 5.3x the oracle, misfitting."""
    sheaths, gains = (0.38, 0.56), (1.017, 1.024)
    rec = fi.record(5301, tau=7.99, ratio=3.54, m=0.42, sheaths=sheaths, gains=gains)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.sheathed_path
    taus = result.estimate.time_constants
    assert [len(pair) for pair in taus] == [2, 2]
    # measured 0.25 / 0.42 s (the MAP's pull shortens sheaths, README); ordered as the truth
    found = [at_level(pair[1] / model.psi) for pair in taus]
    assert 0.5 * sheaths[0] < found[0] < found[1] < 1.2 * sheaths[1], found
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, rec.gas)
    best = independent_oracle_rmse(rec, gains)
    # measured 2.25x (5.29x unseeded); the bound without the flow is 2.5x
    assert ours <= 2.5 * best, ours / best


def _fast_sheath_pair(case: int, tau: float, ratio: float, m: float, sheath: float,
                      gains: tuple[float, float]) -> tuple[list[tuple[float, ...]], float, float]:
    """Pair ``case`` of the separate generator at 10 Hz with one sheath on the fast sensor,
    characterised without the flow (asserted: the sheathed path, the orders [2, 1]): the time
    constants at the record's geometric mean of psi (as above), the sheath's relative error
    there, and the gas's RMSE over the oracle's."""
    rec = fi.record(case, tau=tau, ratio=ratio, m=m, rate=10.0, sheaths=(sheath, 0.0),
                    gains=gains)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.sheathed_path
    taus = result.estimate.time_constants
    assert [len(pair) for pair in taus] == [2, 1], taus
    at_mean = [tuple(at_level(stage / model.psi) for stage in pair) for pair in taus]
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, rec.gas)
    return (at_mean, at_mean[0][1] / at_level(rec.sheath1) - 1.0,
            ours / independent_oracle_rmse(rec, gains))


def test_sheath_and_ratio_are_profiled_together() -> None:
    """Pair 30506 of ``field_sweep_independent.py 305 8`` (fast element 7.33 s, ratio 3.46, m
    0.66, 10 Hz, one 0.44 s sheath on the fast sensor, gains 0.981 / 1.029). The MAP's cost
    lies in a narrow valley along the sheath and the ratio together: found at 0.22 s with the
    ratio 3.28, the gas was 2.64x the oracle (misfit 14 times the noise), and neither the
    sheath alone nor the ratio alone lowers the cost from there (sheath_profile._joint_profile).
    Given the true psi the same path reaches 1.02x."""
    taus, sheath_error, factor = _fast_sheath_pair(30506, 7.33, 3.46, 0.66, 0.44,
                                                   (0.981, 1.029))
    assert abs(sheath_error) < 0.15, taus  # measured 5 % short (half the truth before)
    ratio = taus[1][0] / taus[0][0]
    assert abs(ratio / 3.46 - 1.0) < 0.03, ratio  # measured 3.44 (3.28 before)
    # measured 1.25x (2.64x before); the bound without the flow is 2.5x, and 2.0x
    # keeps most of what the joint profile gained
    assert factor <= 2.0, factor


def test_a_sheath_far_off_is_followed_while_the_cost_falls() -> None:
    """Pair 30601 of ``field_sweep_independent.py 306 8`` at 10 Hz (fast element 4.14 s,
    ratio 3.89, m 0.47, one 0.27 s sheath on the fast sensor, gains 0.978 / 0.982). The
    cross-relation started the sheath at 0.087 s, a third of the truth; the MAP's cost still
    fell at the one-at-a-time parabola's edge (0.10 s), the joint profile took it to 0.14 s
    and stopped, and the gas was 3.02x the oracle, misfitting 4.9 times the noise
    (sheath_profile._followed)."""
    taus, sheath_error, factor = _fast_sheath_pair(30601, 4.14, 3.89, 0.47, 0.27,
                                                   (0.978, 0.982))
    # measured 5 % short (0.14 s, about half the truth, before)
    assert abs(sheath_error) < 0.15, taus
    # measured 1.14x (3.02x before); the bound without the flow is 2.5x, and 2.0x
    # keeps most of what following the cost gained
    assert factor <= 2.0, factor
