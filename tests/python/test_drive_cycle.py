"""The drive-cycle simulator (dualprobe.simulate.drive_cycle): exact against an ODE solver and
the laboratory simulator, conditions in range, logger effects as specified."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.integrate

from dualprobe import simulate as sim
from dualprobe.simulate.drive_cycle import (
    DriveCycle,
    FieldSensor,
    drive_cycle,
    simulate_field_pair,
)


@pytest.fixture(scope="module")
def cycle() -> DriveCycle:
    return drive_cycle(600.0, np.random.default_rng(7))


def test_conditions_span_the_requested_ranges(cycle: DriveCycle) -> None:
    assert cycle.gas.min() == pytest.approx(460.0, abs=8.0)  # the fluctuation rides on the map
    assert cycle.gas.max() == pytest.approx(700.0, abs=8.0)
    assert cycle.velocity.min() == pytest.approx(7.0, rel=1e-9)
    assert cycle.velocity.max() == pytest.approx(60.0, rel=1e-9)
    assert np.all(cycle.load >= 0.0) and np.all(cycle.load <= 1.0)
    # the vehicle stops and drives: idle and at least 50 km/h somewhere in 10 minutes
    assert cycle.vehicle_speed.min() < 1.0 and cycle.vehicle_speed.max() > 50.0


def test_integration_matches_an_adaptive_ode_solver() -> None:
    """Sheathed, direction-dependent, flow-following sensor against LSODA at rtol 1e-10 on the
    same piecewise-linear conditions: the closed-form steps are exact for what they resolve."""
    conditions = drive_cycle(120.0, np.random.default_rng(5))
    sensor = FieldSensor(5.0, 0.5, sheath_tau_ref=0.3, cooling_factor=1.2, noise_std=0.0)
    rec = simulate_field_pair(conditions, sensor, sensor, sample_rate=10.0, rng=1)

    def rhs(t: float, x: np.ndarray) -> list[float]:
        v = np.interp(t, conditions.t, conditions.velocity)
        u = np.interp(t, conditions.t, conditions.gas)
        sheath, element = sensor.time_constants(np.array([v]), 20.0)
        a = float(sheath[0]) * (sensor.cooling_factor if u < x[0] else 1.0)
        b = float(element[0]) * (sensor.cooling_factor if x[0] < x[1] else 1.0)
        return [(u - x[0]) / a, (x[0] - x[1]) / b]

    solution = scipy.integrate.solve_ivp(
        rhs, (0.0, float(rec.t[-1])), [conditions.gas[0]] * 2, t_eval=rec.t, rtol=1e-10,
        atol=1e-10, max_step=conditions.dt, method="LSODA")
    # 1e-4 K: the solver's own error at the direction switches (its step straddles them)
    # dominates; far below any sensor noise considered (>= 0.01 K)
    assert np.max(np.abs(solution.y[1] - rec.t1_clean)) < 1e-4


def test_constant_velocity_reduces_to_the_laboratory_simulator() -> None:
    """m = 0 (or a constant velocity): the element and sheath are the LTI sensor
    1/((1 + a s)(1 + b s)), which simulate.simulate_sensor integrates exactly."""
    conditions = drive_cycle(200.0, np.random.default_rng(3), fluctuation_std=0.0)
    sensor = FieldSensor(8.0, 0.0, sheath_tau_ref=0.7, noise_std=0.0)
    rec = simulate_field_pair(conditions, sensor, sensor, sample_rate=5.0, rng=0)
    profile = sim.GasProfile.from_samples(conditions.t, conditions.gas)
    expected = sim.simulate_sensor(profile, sim.SensorModel((8.0, 0.7)), rec.t)
    assert np.max(np.abs(rec.t1_clean - expected)) < 1e-7  # two exact integrations


def test_time_constants_follow_the_flow_with_a_constant_ratio(cycle: DriveCycle) -> None:
    s1 = FieldSensor(4.0, 0.6)
    s2 = FieldSensor(12.0, 0.6)
    rec = simulate_field_pair(cycle, s1, s2, sample_rate=10.0, v_ref=25.0, rng=2)
    np.testing.assert_allclose(rec.tau2 / rec.tau1, 3.0, rtol=1e-12)
    # the reported tau is the fine step's (midpoint velocity), the flow the row instant's: they
    # differ by the velocity change over half a 5-ms step, < 0.5 % in the hardest acceleration
    np.testing.assert_allclose(rec.tau1, 4.0 * (rec.flow / 25.0) ** -0.6, rtol=5e-3)


def test_logger_effects() -> None:
    conditions = drive_cycle(60.0, np.random.default_rng(11))
    sensor = FieldSensor(2.0, 0.5, noise_std=0.1)
    rec = simulate_field_pair(conditions, sensor, sensor, sample_rate=50.0, quantisation=0.25,
                              hold=5, jitter=0.002, rng=4)
    assert np.allclose(rec.t1 / 0.25, np.round(rec.t1 / 0.25), atol=1e-9)
    runs = rec.t1[: (rec.t1.size // 5) * 5].reshape(-1, 5)
    assert np.all(runs == runs[:, :1])  # the reading refreshes every 5 rows
    dt = np.diff(rec.t)
    assert dt.min() >= 0.02 - 2 * 0.002 - 1e-12 and dt.max() <= 0.02 + 2 * 0.002 + 1e-12
    assert np.std(dt) > 1e-4  # the clock does jitter


@pytest.mark.parametrize("bad", [{"tau_ref": 0.0}, {"tau_ref": 1.0, "noise_std": -1.0},
                                 {"tau_ref": 1.0, "cooling_factor": float("nan")}])
def test_bad_sensor_parameters_are_refused(bad: dict[str, float]) -> None:
    with pytest.raises(ValueError):
        FieldSensor(**bad)
