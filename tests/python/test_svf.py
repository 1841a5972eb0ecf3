"""Reference SVF cross-relation estimator (dualprobe.reference.svf, design.md 1.4)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg
import scipy.signal

from dualprobe import simulate as sim
from dualprobe.reference import svf, svf_filter

PT1 = sim.SensorModel((12.48,))
PT2 = sim.SensorModel((28.95,))


def _pair(
    s1: sim.SensorModel,
    s2: sim.SensorModel,
    *,
    ts: float,
    duration: float,
    noise: float = 0.0,
    seed: int = 0,
    amplitude: float = 150.0,
    mean: float = 400.0,
) -> sim.PairRecording:
    rng = np.random.default_rng(seed)
    profile = sim.multistep_profile(duration, mean=mean, amplitude=amplitude,
                                    mean_hold=duration / 8, rng=rng)
    return sim.simulate_pair(profile, s1, s2, ts=ts, duration=duration, noise_std=noise, rng=rng)


@pytest.mark.parametrize(("tf", "ts", "m", "hold"), [
    (5.0, 0.01, 3, "foh"), (0.02, 0.001, 2, "foh"), (1.0, 0.5, 3, "zoh"), (1.0, 3.0, 2, "foh"),
])
def test_closed_form_discretisation_matches_matrix_exponential(
    tf: float, ts: float, m: int, hold: str
) -> None:
    disc = svf_filter.discretise_filter(tf, ts, m, hold)
    a = (np.eye(m, k=-1) - np.eye(m)) / tf
    aug = np.zeros((m + 2, m + 2))
    aug[:m, :m] = a * ts
    aug[0, m] = ts / tf
    aug[m, m + 1] = 1.0
    ex = scipy.linalg.expm(aug)
    ga = ex[:m, m] - ex[:m, m + 1] if hold == "foh" else ex[:m, m]
    gb = ex[:m, m + 1] if hold == "foh" else np.zeros(m)
    # expm itself is accurate to ~1e-12 here; the closed form has no cancellation
    np.testing.assert_allclose(disc.phi, ex[:m, :m], rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(disc.ga, ga, rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(disc.gb, gb, rtol=1e-9, atol=1e-15)


def test_filtered_derivatives_are_exact_for_piecewise_linear_input() -> None:
    """FOH: the filter sees the straight-line interpolation of the samples exactly (lsim
    integrates linearly interpolated input exactly)."""
    ts, tf, m = 0.1, 0.7, 3
    rng = np.random.default_rng(3)
    u = np.cumsum(rng.standard_normal(400))
    u -= u[0]
    t = ts * np.arange(u.size)
    x = svf_filter.filtered_derivatives(u, svf_filter.discretise_filter(tf, ts, m))
    den = np.poly1d([tf, 1.0]) ** m
    for j in range(m):
        num = np.poly1d([tf**j] + [0.0] * j)  # (tf s)^j
        _, y, _ = scipy.signal.lsim((num.coeffs, den.coeffs), u, t)
        np.testing.assert_allclose(x[j], y, rtol=0, atol=1e-9 * np.max(np.abs(u)))


@pytest.mark.parametrize(("order", "static", "tf"), [(1, "unit", 0.05), (2, "unit", 0.03),
                                                      (1, "affine", 0.05)])
def test_noise_covariance_matches_monte_carlo(order: int, static: str, tf: float) -> None:
    ts, n = 0.01, 200_000
    rng = np.random.default_rng(7)
    s1, s2 = 0.3, 0.7
    disc = svf_filter.discretise_filter(tf, ts, order + 1)
    z = svf.regression_columns(s1 * rng.standard_normal(n), s2 * rng.standard_normal(n), disc,
                               order, static=static)[:, 1000:]
    empirical = z @ z.T / z.shape[1]
    model = svf.noise_covariance(disc, order, s1, s2, static)
    scale = np.sqrt(np.outer(np.diag(model), np.diag(model)))
    # ~2e4 effective samples (correlation time ~10 Ts): sampling error ~1 %
    np.testing.assert_allclose(empirical / scale, model / scale, atol=0.04)


def test_noise_free_first_order_exact_off_grid_and_mid_transient() -> None:
    rec = _pair(PT1, PT2, ts=0.1, duration=1200.0)
    start = int(np.searchsorted(rec.t, rec.jumps[0] + 3.0))  # sensors far from rest
    for tf in (1.0, 5.0, 20.0):
        res = svf.estimate(rec.t1[start:], rec.t2[start:], 0.1, tf=tf)
        assert res.status == "ok"
        # FOH interpolation error at the kinks of off-grid steps: ~1e-6 relative
        assert res.time_constants[0][0] == pytest.approx(12.48, rel=1e-5)
        assert res.time_constants[1][0] == pytest.approx(28.95, rel=1e-5)
    # without the start-up projection the mid-transient start biases the estimate
    biased = svf.estimate(rec.t1[start:], rec.t2[start:], 0.1, tf=20.0, project_initial=False)
    assert abs(biased.time_constants[0][0] / 12.48 - 1.0) > 0.05


def test_noise_free_second_order_exact() -> None:
    rec = _pair(sim.SensorModel((12.30, 0.17)), sim.SensorModel((25.72, 1.08)), ts=0.01,
                duration=300.0, seed=1)
    res = svf.estimate(rec.t1, rec.t2, 0.01, tf=1.0, order=2)
    assert res.status == "ok"
    # measured ~1e-9; the margin covers the kink interpolation error
    np.testing.assert_allclose(res.time_constants[0], (12.30, 0.17), rtol=1e-6)
    np.testing.assert_allclose(res.time_constants[1], (25.72, 1.08), rtol=1e-6)


def test_affine_model_recovers_gain_ratio_offset_and_time_constants() -> None:
    rec = _pair(sim.SensorModel((12.48,), gain=0.99), sim.SensorModel((28.95,), gain=1.03),
                ts=0.1, duration=1200.0, seed=2)
    t2 = rec.t2 + 1.5  # a calibration offset on the slow sensor
    unit = svf.estimate(rec.t1, t2, 0.1, tf=5.0)
    assert abs(unit.time_constants[0][0] / 12.48 - 1.0) > 0.2  # the unit model cannot fit
    res = svf.estimate(rec.t1, t2, 0.1, tf=5.0, static="affine")
    assert res.time_constants[0][0] == pytest.approx(12.48, rel=1e-5)
    assert res.time_constants[1][0] == pytest.approx(28.95, rel=1e-5)
    assert res.extra["gain_ratio"] == pytest.approx(0.99 / 1.03, rel=1e-7)
    # P1 T1 = g P2 T2 + offset with g = 0.99/1.03: offset = -g * 1.5
    assert res.extra["offset"] == pytest.approx(-1.5 * 0.99 / 1.03, rel=1e-4)


def test_hysteresis_noise_free() -> None:
    rng = np.random.default_rng(4)
    profile = sim.multistep_profile(1200.0, mean=400.0, amplitude=150.0, mean_hold=150.0, rng=rng)
    t = 0.1 * np.arange(12001)
    truth = (11.0, 14.5, 24.0, 31.0)  # heat1, cool1, heat2, cool2
    t1 = sim.simulate_hysteretic_sensor(profile, truth[0], truth[1], t)
    t2 = sim.simulate_hysteretic_sensor(profile, truth[2], truth[3], t)
    res = svf.estimate(t1, t2, 0.1, tf=5.0, hysteresis=True)
    assert res.status == "ok"
    heat, cool = res.extra["heat"], res.extra["cool"]
    got = (heat[0][0], cool[0][0], heat[1][0], cool[1][0])  # type: ignore[index]
    # direction switches fall between samples: ~1e-4 relative
    np.testing.assert_allclose(got, truth, rtol=1e-3)


def test_direction_indicator_ignores_the_noise_of_its_own_interval() -> None:
    rng = np.random.default_rng(5)
    x = rng.standard_normal(400_000)
    h = svf_filter.direction_indicator(x, 10)
    step = np.diff(x)
    # independent: mean(h * dx) ~ N(0, ~1/sqrt(N)); including the interval would give ~0.2
    assert abs(np.mean(h * step)) < 5.0 * np.std(step) / math.sqrt(step.size)
    ramp = np.concatenate((np.linspace(0, 10, 50), np.linspace(10, 0, 50)))
    hr = svf_filter.direction_indicator(ramp, 3)
    assert np.all(hr[:48] == 1.0)
    assert np.all(hr[51:] == 0.0)


def test_dead_zone_leaves_flat_stretches_undecided() -> None:
    x = np.concatenate((np.zeros(100), np.linspace(0.0, 20.0, 100)))
    h = svf_filter.direction_indicator(x, 5, sigma=0.1, dead_zone=2.0)
    assert np.all(h[:90] == 0.5)
    assert np.all(h[105:] == 1.0)


def test_smallest_generalised_eigenvalue_is_one_with_the_true_noise() -> None:
    """With the exact noise model the equation error's scatter is rows * C: mu_1 ~ 1."""
    values = []
    for seed in range(3):
        rec = _pair(PT1, PT2, ts=0.1, duration=1200.0, noise=0.1, seed=seed, amplitude=5.0)
        res = svf.estimate(rec.t1, rec.t2, 0.1, tf=6.0, sigma1=0.1, sigma2=0.1)
        values.append(res.eigenvalues[0])
    # ~1000 effective samples each: spread ~5 %
    np.testing.assert_allclose(values, 1.0, atol=0.15)


def test_split_noise_model_is_exact_where_the_direction_switches(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A hysteretic pair on a drive cycle (cooling 1.3 times slower, 10 Hz, 0.05 K): the gas's
    1 Hz fluctuation turns the fast sensor about once a second. Classified by the true
    directions (gas above the sensor: heating) the split columns' noise is that of the
    model, so mu_1 ~ 1 with the switch term; the per-row weights alone count only part of it
    (measured 2.55 without the term, 1.06 with it)."""
    rng = np.random.default_rng(5)
    conditions = sim.drive_cycle(1800.0, rng)
    sensors = [sim.FieldSensor(tau, 0.0, cooling_factor=1.3, noise_std=0.05)
               for tau in (4.0, 12.0)]
    rec = sim.simulate_field_pair(conditions, *sensors, sample_rate=10.0, rng=rng)
    clean = {id(rec.t1): rec.t1_clean, id(rec.t2): rec.t2_clean}
    gas = 0.5 * (rec.tg[1:] + rec.tg[:-1])

    def true_directions(x: np.ndarray, *_: object) -> np.ndarray:
        sensor = clean[id(x)]
        return (gas > 0.5 * (sensor[1:] + sensor[:-1])).astype(float)

    monkeypatch.setattr(svf, "direction_indicator", true_directions)
    res = svf.estimate(rec.t1, rec.t2, rec.ts, tf=2.4, sigma1=0.05, sigma2=0.05,
                       hysteresis=True)
    # ~1500 effective samples: mu_1's spread sqrt(2 / 1500) ~ 0.04; 4 of those
    assert res.eigenvalues[0] == pytest.approx(1.0, abs=0.15)
    heat, cool = res.extra["heat"], res.extra["cool"]
    got = (heat[0][0], cool[0][0], heat[1][0], cool[1][0])  # type: ignore[index]
    # measured 0.05 % at most
    np.testing.assert_allclose(got, (4.0, 5.2, 12.0, 15.6), rtol=5e-3)


def test_switch_noise_matches_the_unsplit_noise() -> None:
    """One column's noise ``C0 = sigma^2 (tf/Ts)^2 (2 G0 - 2 G1)``: with h = 1 throughout the
    split column is x_1, so the lag-1 sum of its pulse response and the Lyapunov covariance
    must agree (G0 from the same response)."""
    for tf, ts in ((2.4, 0.1), (0.3, 0.05), (5.0, 1.0)):
        disc = svf_filter.discretise_filter(tf, ts, 2)
        zoh = svf_filter.discretise_filter(tf, ts, 2, "zoh")
        n = math.ceil(62.0 * tf / ts) + 2
        pulse = np.zeros(n - 1)
        pulse[0] = 1.0
        g = svf_filter.filter_states(np.concatenate((pulse, [0.0])), zoh)[-1]
        g0 = float(g @ g) * (tf / ts) ** 2
        c0 = svf.noise_covariance(disc, 1, 1.0, 0.0)[0, 0]
        assert c0 == pytest.approx(2.0 * g0 - 2.0 * svf.split_switch_noise(disc), rel=1e-9)


def test_effective_samples_model_agrees_with_residual() -> None:
    rng = np.random.default_rng(6)
    n, ts, tf = 100_000, 0.01, 0.1
    disc = svf_filter.discretise_filter(tf, ts, 2)
    theta = np.array([1.3, 2.9, -1.0])
    z = svf.regression_columns(0.1 * rng.standard_normal(n), 0.1 * rng.standard_normal(n), disc, 1)
    model = svf.effective_samples(disc, theta, 1, 0.1, 0.1, n)
    residual = svf.residual_effective_samples(z, theta, 400)
    assert model < n / 5  # the filtered noise is strongly correlated
    assert residual == pytest.approx(model, rel=0.25)  # sampling noise of the empirical ACF


def test_polynomial_time_constants() -> None:
    c, d = 12.30 + 0.17, 12.30 * 0.17
    np.testing.assert_allclose(svf.polynomial_time_constants((c, d)), (12.30, 0.17), rtol=1e-12)
    assert svf.polynomial_time_constants((5.0,)) == (5.0,)
    assert all(math.isnan(v) for v in svf.polynomial_time_constants((1.0, 1.0)))  # complex
    assert all(math.isnan(v) for v in svf.polynomial_time_constants((-2.0,)))


def test_constant_signals_raise() -> None:
    with pytest.raises(np.linalg.LinAlgError):
        svf.estimate(np.full(500, 20.0), np.full(500, 20.0), 0.1, tf=1.0)


def test_bad_arguments() -> None:
    with pytest.raises(ValueError, match="tf > 0"):
        svf_filter.discretise_filter(0.0, 0.1, 2)
    with pytest.raises(ValueError, match="static model"):
        svf.column_maps(1, "cubic")
    with pytest.raises(ValueError, match="order 1"):
        svf.estimate(np.arange(50.0), np.arange(50.0), 0.1, tf=1.0, order=2, hysteresis=True)


def test_heating_and_cooling_columns_add_up_to_the_derivative_column() -> None:
    rng = np.random.default_rng(8)
    x = np.cumsum(rng.standard_normal(2000))
    y = np.cumsum(rng.standard_normal(2000))
    disc = svf_filter.discretise_filter(0.7, 0.1, 2)
    h = (rng.random(1999) > 0.5).astype(float)
    split = svf.regression_columns(x, y, disc, 1, (h, 1.0 - h))
    whole = svf.regression_columns(x, y, disc, 1)
    # ZOH of the FOH interpolation's slope is the FOH derivative: equal to rounding
    np.testing.assert_allclose(split[0] + split[1], whole[0], atol=1e-12)
    np.testing.assert_allclose(split[2] + split[3], whole[1], atol=1e-12)
    np.testing.assert_array_equal(split[4], whole[2])
