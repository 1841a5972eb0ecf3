"""Gas-temperature reconstruction (issue 7): smoother, causal filter and exact inverse against
the true gas temperature of exact simulations (dualprobe.simulate).

RMSE ratios are "reconstruction RMSE / faster sensor's own RMSE" over the same samples, with
the samples beside a gas jump excluded: those with a jump less than 2 sample intervals away
(``PairRecording.jump_mask(margin=2)``), where the value at the instant depends on where
inside the interval the jump fell.
"""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from dualprobe import simulate
from dualprobe.models import noise
from dualprobe.models.inverse import zoh_inverse
from dualprobe.reconstruction import fit_smoother, reconstruct_pair, resolvable_stages
from dualprobe.reconstruction.statespace import causal_filter, pair_model, process_floor
from dualprobe.reconstruction.trajectory import Trajectory
from dualprobe.reference import kalman

PT100_FAST = (12.48,)
PT100_SLOW = (28.95,)
PT100_FAST_2 = (12.30, 0.17)
PT100_SLOW_2 = (25.72, 1.08)


def _step_profile(
    duration: float, rng: np.random.Generator, hold: tuple[float, float] = (40.0, 100.0)
) -> simulate.GasProfile:
    """Jumps of 100-300 K at uniformly random (off-grid) times, levels kept in 100-800 C."""
    times: list[float] = []
    levels = [300.0]
    t = rng.uniform(*hold) / 2.0
    while t < duration:
        size = rng.uniform(100.0, 300.0)
        up = levels[-1] + size <= 800.0 and (levels[-1] - size < 100.0 or rng.random() < 0.5)
        levels.append(levels[-1] + size if up else levels[-1] - size)
        times.append(t)
        t += rng.uniform(*hold)
    return simulate.multistep_profile(duration, levels=levels, step_times=times)


def _pair(
    profile: simulate.GasProfile,
    taus1: tuple[float, ...],
    taus2: tuple[float, ...],
    ts: float,
    duration: float,
    noise: float,
    rng: np.random.Generator,
) -> simulate.PairRecording:
    return simulate.simulate_pair(
        profile,
        simulate.SensorModel(taus1),
        simulate.SensorModel(taus2),
        ts=ts,
        duration=duration,
        noise_std=noise,
        rng=rng,
    )


def estimate_noise_std(x: np.ndarray) -> float:
    """The package's noise estimator with the difference order the reconstruction uses."""
    return noise.estimate_noise_std(x, noise.ORDER_RECONSTRUCTION)


def _ratio(estimate: np.ndarray, rec: simulate.PairRecording) -> float:
    keep = ~rec.jump_mask(margin=2) & np.isfinite(estimate)
    err = math.sqrt(float(np.mean((estimate[keep] - rec.tg[keep]) ** 2)))
    sensor = math.sqrt(float(np.mean((rec.t1[keep] - rec.tg[keep]) ** 2)))
    return err / sensor


@pytest.fixture(scope="module")
def steps_10hz() -> simulate.PairRecording:
    rng = np.random.default_rng(11)
    return _pair(_step_profile(600.0, rng), PT100_FAST, PT100_SLOW, 0.1, 600.0, 0.1, rng)


@pytest.fixture(scope="module")
def band_10hz() -> simulate.PairRecording:
    """Gas moving only within +/-5 K: band-limited to 0.1 Hz (the sensors' corner frequencies
    are 0.013 and 0.0055 Hz, so most of the motion is attenuated 10-50x by the sensors)."""
    unit = simulate.fluctuating_profile(600.0, mean=0.0, std=1.0, bandwidth=0.1, rng=12)
    peak = float(np.max(np.abs(unit(np.linspace(0.0, 600.0, 60001)))))
    # same draws scaled so that the extreme is 4.9 K: the whole +/-5 K range is used
    profile = simulate.fluctuating_profile(600.0, mean=300.0, std=4.9 / peak, bandwidth=0.1, rng=12)
    rec = _pair(profile, PT100_FAST, PT100_SLOW, 0.1, 600.0, 0.1, np.random.default_rng(13))
    assert np.max(np.abs(rec.tg - 300.0)) <= 5.0  # the case asked for: within +/-5 K
    return rec


# --------------------------------------------------------------------------------------------
# The acceptance cases of issue 7
# --------------------------------------------------------------------------------------------


def test_smoother_on_steps_is_far_better_than_the_sensor(
    steps_10hz: simulate.PairRecording,
) -> None:
    rec = steps_10hz
    gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW)
    ratio = _ratio(gas, rec)
    print(f"smoother, steps, 10 Hz: RMSE ratio {ratio:.2e}")
    assert gas.shape == rec.t1.shape and np.all(np.isfinite(gas))
    assert ratio <= 0.06  # issue 7: at most 6 % of the faster sensor's RMSE
    assert ratio <= 0.02  # ... and its aim of 2 % (measured 1e-4 to 1e-3 over 6 seeds)


def test_smoother_on_small_band_limited_motion(band_10hz: simulate.PairRecording) -> None:
    rec = band_10hz
    gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW)
    ratio = _ratio(gas, rec)
    print(f"smoother, +/-5 K band-limited, 10 Hz: RMSE ratio {ratio:.3f}")
    assert ratio <= 0.35  # issue 7: at most 35 % (measured 0.13-0.16 over 7 records)


def test_smoother_degrades_gracefully_with_wrong_time_constants(
    steps_10hz: simulate.PairRecording, band_10hz: simulate.PairRecording
) -> None:
    # 3 % off in opposite directions: the worst case for the pair (the sensors disagree most)
    wrong1 = (PT100_FAST[0] * 1.03,)
    wrong2 = (PT100_SLOW[0] / 1.03,)
    rec = steps_10hz
    steps = _ratio(reconstruct_pair(rec.t1, rec.t2, rec.ts, wrong1, wrong2), rec)
    rec = band_10hz
    band = _ratio(reconstruct_pair(rec.t1, rec.t2, rec.ts, wrong1, wrong2), rec)
    print(f"3 % wrong time constants: steps {steps:.3f}, band {band:.3f}")
    # an exact inverse with tau 3 % off errs by 0.03 tau dT/dt, ~2-3 % of the sensor's RMSE
    # after 100-300 K steps; the smoother stays within the bounds for correct taus
    assert steps <= 0.06
    assert band <= 0.35


def test_inverse_is_the_noisy_comparison(steps_10hz: simulate.PairRecording) -> None:
    rec = steps_10hz
    inverse = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW, mode="inverse")
    smooth = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW)
    assert np.isnan(inverse[0]) and np.isnan(inverse[-1])
    assert np.all(np.isfinite(inverse[1:-1]))
    # noise gain ~ tau/Ts: with 0.1 K noise the inverse errs by several K, 10-100x the smoother
    assert _ratio(inverse, rec) > 10.0 * _ratio(smooth, rec)


def test_filter_is_causal_and_better_than_the_sensor(steps_10hz: simulate.PairRecording) -> None:
    rec = steps_10hz
    full = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW, mode="filter")
    ratio = _ratio(full, rec)
    print(f"causal filter, steps, 10 Hz: RMSE ratio {ratio:.3f}")
    assert ratio <= 0.06  # the smoother's bound holds causally too (measured 0.009-0.013)
    fit = fit_smoother(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW)
    y = np.column_stack([rec.t1, rec.t2]) - fit.offset
    whole = causal_filter(y, fit.model, fit.background_q, fit.sigma)[0]
    head = causal_filter(y[:2000], fit.model, fit.background_q, fit.sigma)[0]
    # causality of the filter the product runs (the core's): the first 2000 outputs do not
    # change when later samples are cut off
    np.testing.assert_allclose(head, whole[:2000], rtol=0.0, atol=1e-12)


def test_filter_stays_bounded_with_a_wrong_model() -> None:
    """Cooling time constants 14-17 % off (the sensors are not hysteretic at all): the GLR
    keeps 'finding' jumps that explain the model error; it must not run away."""
    rng = np.random.default_rng(15)
    rec = _pair(_step_profile(200.0, rng), PT100_FAST_2, PT100_SLOW_2, 0.1, 200.0, 0.05, rng)
    cool1, cool2 = (14.0, 0.2), (30.0, 1.2)
    out = {
        mode: _ratio(
            reconstruct_pair(
                rec.t1,
                rec.t2,
                rec.ts,
                PT100_FAST_2,
                PT100_SLOW_2,
                mode=mode,
                taus1_cool=cool1,
                taus2_cool=cool2,
            ),
            rec,
        )
        for mode in ("smoother", "filter")
    }
    print(f"wrong cooling time constants: {out}")
    assert out["smoother"] < 0.3  # measured 0.04 (0.10 on another record)
    assert out["filter"] < 0.5  # measured 0.24 (unconstrained GLR diverged: 2.6 on another)


# --------------------------------------------------------------------------------------------
# Second-order sensors (paper Tables I and II), 100 Hz
# --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_second_order_pair_at_100hz() -> None:
    rng = np.random.default_rng(21)
    duration = 150.0
    rec = _pair(
        _step_profile(duration, rng, hold=(30.0, 60.0)),
        PT100_FAST_2,
        PT100_SLOW_2,
        0.01,
        duration,
        0.01,
        rng,
    )
    second = _ratio(reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST_2, PT100_SLOW_2), rec)
    first = _ratio(reconstruct_pair(rec.t1, rec.t2, rec.ts, (12.48,), (28.95,)), rec)
    print(f"second-order sensors, 100 Hz: ratio {second:.2e} (first-order model: {first:.3f})")
    assert second <= 0.02  # as good as the first-order pair's aim
    # issue 6: the right model at most half the error of the first-order one on the same data
    assert second <= 0.5 * first


# --------------------------------------------------------------------------------------------
# Hysteresis
# --------------------------------------------------------------------------------------------


def test_hysteretic_sensors_use_their_cooling_time_constants() -> None:
    rng = np.random.default_rng(31)
    duration, ts = 600.0, 0.1
    profile = _step_profile(duration, rng)
    t = ts * np.arange(round(duration / ts) + 1)
    heat, cool = (12.48, 28.95), (12.48 * 1.3, 28.95 * 1.3)  # cooling 30 % slower
    t1 = simulate.simulate_hysteretic_sensor(profile, heat[0], cool[0], t)
    t2 = simulate.simulate_hysteretic_sensor(profile, heat[1], cool[1], t)
    t1 = t1 + 0.1 * rng.standard_normal(t.size)
    t2 = t2 + 0.1 * rng.standard_normal(t.size)
    rec = simulate.PairRecording(t=t, tg=profile(t), t1=t1, t2=t2, ts=ts, jumps=profile.jumps)
    aware = reconstruct_pair(t1, t2, ts, heat[0], heat[1], taus1_cool=cool[0], taus2_cool=cool[1])
    naive = reconstruct_pair(t1, t2, ts, heat[0], heat[1])
    print(f"hysteretic pair: ratio {_ratio(aware, rec):.2e}, ignoring it {_ratio(naive, rec):.3f}")
    assert _ratio(aware, rec) <= 0.06  # the bound holds for hysteretic sensors too
    assert _ratio(aware, rec) <= 0.2 * _ratio(naive, rec)  # modelling it is what does it


# --------------------------------------------------------------------------------------------
# Building blocks
# --------------------------------------------------------------------------------------------


def test_inverse_is_exact_on_difference_equation_data() -> None:
    """On data obeying eq. 8 exactly (gas held over [k, k+1)), each sensor's ZOH inverse is
    exact, so the output at t_k is the mean of the two held values around it."""
    rng = np.random.default_rng(41)
    held = 300.0 + np.cumsum(rng.normal(0.0, 2.0, 500))
    t1, t2 = simulate.difference_equation_pair(held, 12.48, 28.95, 0.1)
    out = reconstruct_pair(t1, t2, 0.1, 12.48, 28.95, mode="inverse", noise_std=0.1)
    expected = 0.5 * (held[:-2] + held[1:-1])
    np.testing.assert_allclose(out[1:-1], expected, rtol=0.0, atol=1e-8)  # float64 rounding


def test_inverse_alignment_removes_the_half_sample_lag() -> None:
    """On a ramp r, the ZOH value of an interval lags the instant by r Ts/2; the aligned
    output errs only by O(r Ts^2 / tau)."""
    ts, rate = 0.1, 2.0
    profile = simulate.GasProfile.from_samples(np.array([0.0, 100.0]), np.array([0.0, 200.0]))
    t = ts * np.arange(1001)
    t1 = simulate.simulate_sensor(profile, simulate.SensorModel((12.48,)), t)
    t2 = simulate.simulate_sensor(profile, simulate.SensorModel((28.95,)), t)
    out = reconstruct_pair(t1, t2, ts, 12.48, 28.95, mode="inverse", noise_std=0.01)
    late = slice(600, 999)  # the start-up transient of the ramp has died out
    err = out[late] - profile(t[late])
    assert np.max(np.abs(err)) < 0.01 * rate * ts / 2.0  # far below the half-sample lag


def test_noise_level_is_estimated_from_the_signals(steps_10hz: simulate.PairRecording) -> None:
    rec = steps_10hz
    for signal in (rec.t1, rec.t2):
        # 6000 samples: the MAD's standard error is ~1.3 %; 5 % covers it and the kinks
        assert estimate_noise_std(signal) == pytest.approx(0.1, rel=0.05)
    quiet = np.zeros(100)
    assert estimate_noise_std(quiet) == 0.0


def test_smoother_with_estimated_noise_matches_given_noise(
    band_10hz: simulate.PairRecording,
) -> None:
    rec = band_10hz
    estimated = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW)
    given = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW, noise_std=0.1)
    # a few % error in sigma moves q by the same; the gas moves far less than its own error
    assert np.sqrt(np.mean((estimated - given) ** 2)) < 0.1 * np.sqrt(
        np.mean((given - rec.tg) ** 2)
    )


def test_noise_free_data_are_reconstructed_almost_exactly() -> None:
    rng = np.random.default_rng(51)
    rec = _pair(_step_profile(300.0, rng), PT100_FAST, PT100_SLOW, 0.1, 300.0, 0.0, rng)
    gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW)
    assert _ratio(gas, rec) < 1e-4  # noise floored at 1e-9 of the signal scale


def test_banded_smoother_equals_rts_smoother() -> None:
    """The block-tridiagonal MAP solve is the Rauch-Tung-Striebel smoother (Gaussian
    increments, fixed q). RTS written here with plain matrices, nearly diffuse prior."""
    rng = np.random.default_rng(61)
    rec = _pair(_step_profile(120.0, rng), PT100_FAST, PT100_SLOW, 0.1, 120.0, 0.1, rng)
    y = np.column_stack([rec.t1, rec.t2]) - 400.0
    sigma = np.array([0.1, 0.1])
    q = 5.0
    for gas in ("rw", "irw"):
        model = pair_model(PT100_FAST, PT100_SLOW, 0.1, gas=gas)
        # the core's discretisation against the reference's independent Van Loan expm
        check = kalman.pair_model(PT100_FAST, PT100_SLOW, 0.1, gas=gas)
        np.testing.assert_allclose(model.phi, check.phi, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(model.q_unit, check.q_unit, rtol=1e-9,
                                   atol=1e-12 * float(np.max(check.q_unit)))
        system = Trajectory(model, y, sigma)
        lam = np.ones(y.shape[0] - 1)
        nll, banded, _ = system.evaluate(math.log(q), lam, np.zeros(lam.size, dtype=np.intp))
        phi = model.phi[0]
        big_q = q * model.q_unit[0] + process_floor(model, sigma, q)[0]
        h, r = model.h, np.diag(sigma**2)
        n = model.n
        # prior 1000 K wide around the first samples: its pull is ~(posterior/prior var) 1e-6
        # of a few K; a wider one loses digits to cancellation in the first update
        x, p = np.full(n, float(np.mean(y[0]))), np.eye(n) * 1e6
        if gas == "irw":
            x[1] = 0.0
        xf, pf, xp, pp = [], [], [], []
        for k in range(y.shape[0]):
            if k:
                x, p = phi @ x, phi @ p @ phi.T + big_q
            xp.append(x)
            pp.append(p)
            gain = p @ h.T @ np.linalg.inv(h @ p @ h.T + r)
            x = x + gain @ (y[k] - h @ x)
            p = (np.eye(n) - gain @ h) @ p
            xf.append(x)
            pf.append(p)
        xs = [xf[-1]]
        for k in range(y.shape[0] - 2, -1, -1):
            c = pf[k] @ phi.T @ np.linalg.inv(pp[k + 1])
            xs.insert(0, xf[k] + c @ (xs[0] - xp[k + 1]))
        rts = np.array(xs)
        # agreement limited by that prior's pull and by rounding in both (condition ~1e11)
        np.testing.assert_allclose(banded[:, 0], rts[:, 0], rtol=0.0, atol=1e-4)
        assert math.isfinite(nll)


@pytest.mark.slow
def test_one_hour_record_is_fast() -> None:
    rng = np.random.default_rng(71)
    rec = _pair(_step_profile(3600.0, rng), PT100_FAST, PT100_SLOW, 0.1, 3600.0, 0.1, rng)
    start = time.perf_counter()
    gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW)
    elapsed = time.perf_counter() - start
    print(f"one hour at 10 Hz (36001 samples): {elapsed:.1f} s, ratio {_ratio(gas, rec):.2e}")
    assert _ratio(gas, rec) <= 0.02


@pytest.mark.parametrize("mode", ["smoother", "filter", "inverse"])
def test_constant_signals_give_the_constant(mode: str) -> None:
    flat = np.full(200, 300.0)  # no excitation at all, no noise: q at its floor, no warning
    gas = reconstruct_pair(flat, flat, 0.1, 12.48, 28.95, mode=mode)
    np.testing.assert_allclose(gas[1:-1], 300.0, rtol=0.0, atol=1e-9)


def test_thermocouple_pair_at_1khz() -> None:
    """Other sensors, rate and gas: 20/80 ms beads, 1 kHz, 5 Hz band-limited gas."""
    profile = simulate.fluctuating_profile(10.0, mean=550.0, std=10.0, bandwidth=5.0, rng=81)
    rec = simulate.simulate_pair(
        profile,
        simulate.THERMOCOUPLE_20MS,
        simulate.THERMOCOUPLE_80MS,
        ts=0.001,
        duration=10.0,
        noise_std=0.05,
        rng=82,
    )
    smooth = _ratio(reconstruct_pair(rec.t1, rec.t2, rec.ts, 0.02, 0.08), rec)
    causal = _ratio(reconstruct_pair(rec.t1, rec.t2, rec.ts, 0.02, 0.08, mode="filter"), rec)
    print(f"thermocouples, 1 kHz: smoother {smooth:.3f}, filter {causal:.3f}")
    assert smooth <= 0.05  # measured 0.012: the beads are only 20-80 samples slow
    assert causal <= 0.15  # measured 0.06


def test_quantised_noise_free_data() -> None:
    rng = np.random.default_rng(91)
    profile = _step_profile(300.0, rng)
    rec = simulate.simulate_pair(
        profile,
        simulate.SensorModel(PT100_FAST),
        simulate.SensorModel(PT100_SLOW),
        ts=0.1,
        duration=300.0,
        quantisation=0.01,
        rng=rng,
    )
    # ADC steps of 0.01 K act as uniform noise of 0.01/sqrt(12) K
    assert estimate_noise_std(rec.t1) == pytest.approx(0.01 / math.sqrt(12.0), rel=0.2)
    gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, PT100_FAST, PT100_SLOW)
    assert _ratio(gas, rec) <= 0.02  # measured 2e-5


# --------------------------------------------------------------------------------------------
# Regressions: fast stages, noise-free data, steps on the sample grid, inverse, gains, CLI
# --------------------------------------------------------------------------------------------


def _study(
    taus1: tuple[float, ...], taus2: tuple[float, ...], noise: float = 0.0, seed: int = 0
) -> simulate.PairRecording:
    """The paper's studies: 100 K step ON the grid at t = 10 s, 10 Hz, 200 s."""
    profile = simulate.step_profile(10.0, 20.0, 120.0)
    return simulate.simulate_pair(
        profile,
        simulate.SensorModel(taus1),
        simulate.SensorModel(taus2),
        ts=0.1,
        duration=200.0,
        noise_std=noise,
        rng=seed,
    )


def _rmse_all(estimate: np.ndarray, truth: np.ndarray) -> float:
    """RMSE over every sample, the step's own included (right-continuous truth)."""
    return math.sqrt(float(np.mean((estimate - truth) ** 2)))


def test_resolvable_stages_merge_what_the_samples_cannot_resolve() -> None:
    def stages(*args: object) -> list[list[float]]:
        heat, cool = resolvable_stages(*args)  # type: ignore[arg-type]
        return [list(heat), list(cool)]

    ts = 0.1
    close = pytest.approx  # sums of time constants: exact up to rounding
    # a stage below Ts/20 is merged into the other one, the sum of the time constants kept
    assert stages((28.95, 0.001), ts) == [[close(28.951)], [close(28.951)]]
    assert stages((0.004, 12.0), ts, (0.003, 15.0)) == [[close(12.004)], [close(15.003)]]
    # resolvable stages are kept as given; a lone stage is raised to Ts/20 at least
    assert stages((25.72, 1.08), ts) == [[25.72, 1.08], [25.72, 1.08]]
    assert stages((12.30, 0.17), ts) == [[12.30, 0.17], [12.30, 0.17]]
    assert stages((0.001,), ts) == [[close(0.005)], [close(0.005)]]


@pytest.mark.parametrize("a_p", [0.0001, 0.001, 0.003, 0.01])
def test_noise_free_study_a_with_a_fast_pole_through_characterise(a_p: float) -> None:
    """The defect: a_p = 0.001 s at Ts = 0.1 s broke the smoother ("no usable gas
    intensity", exit 2 of `characterise --order 2`). Now every sample, the step's included,
    is reconstructed from the identified time constants."""
    from dualprobe.estimation import characterise_pair

    rec = _study((12.48,), (28.95, a_p))
    est = characterise_pair(rec.t1, rec.t2, rec.ts, order=2)
    gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, *est.time_constants, noise_std=est.noise_std)
    exact = reconstruct_pair(rec.t1, rec.t2, rec.ts, (12.48,), (28.95, a_p))
    print(f"a_p {a_p}: identified {est.time_constants}, RMSE {_rmse_all(gas, rec.tg):.2e} K, "
          f"true taus {_rmse_all(exact, rec.tg):.2e} K")
    # identified taus are 1e-5..1e-4 off; their error, not the smoother, sets this (measured
    # 2.6e-5 to 2.1e-4 K against a 100 K step; before: 2.2 K or an exception)
    assert _rmse_all(gas, rec.tg) < 1e-3
    # with the true taus (the fast stage merged below Ts/20): measured 6e-9 to 1.1e-8 K
    assert _rmse_all(exact, rec.tg) < 1e-5


@pytest.mark.parametrize("a_p", [0.002, 0.01, 0.03])
def test_fast_pole_with_noise_costs_nothing(a_p: float) -> None:
    """A stage between Ts/50 and Ts/3 (kept in the model, or merged below Ts/20) with
    0.01 K noise: the reconstruction is as good as without the stage (before: the model-error
    floor grew as (Ts/tau)^2 and cut sensor 2 off, 5-8x worse on smooth gas)."""
    profile = simulate.fluctuating_profile(200.0, mean=300.0, std=3.0, bandwidth=0.2, rng=5)
    rng = np.random.default_rng(6)
    with_stage = _pair(profile, (12.48,), (28.95, a_p), 0.1, 200.0, 0.01, rng)
    rng = np.random.default_rng(6)
    without = _pair(profile, (12.48,), (28.95,), 0.1, 200.0, 0.01, rng)
    ratio = _ratio(reconstruct_pair(with_stage.t1, with_stage.t2, 0.1, (12.48,), (28.95, a_p)),
                   with_stage)
    plain = _ratio(reconstruct_pair(without.t1, without.t2, 0.1, (12.48,), (28.95,)), without)
    print(f"a_p {a_p}: ratio {ratio:.4f}, without the stage {plain:.4f}")
    assert ratio < 1.25 * plain  # same noise draws; measured within 1-5 %


@pytest.mark.parametrize("a_p", [0.1, 1.08])
def test_noise_free_study_b_with_true_time_constants_is_exact(a_p: float) -> None:
    """The defect: 1.2 K on noise-free study B (irw chosen after 3 rounds, the step smeared
    into a ramp). Now exact at every sample, the on-grid step's own included."""
    rec = _study((12.30, 0.17), (25.72, a_p))
    gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, (12.30, 0.17), (25.72, a_p))
    print(f"study B, a_p {a_p}: RMSE {_rmse_all(gas, rec.tg):.2e} K")
    assert _rmse_all(gas, rec.tg) < 1e-5  # measured 9e-9 and 2.5e-8 K (100 K step)


def test_noise_free_zoh_data_with_steps_on_the_grid_are_exact() -> None:
    """Eq. 8 data, gas held over [t_k, t_k+1) with steps on the grid: the smoother returns the
    held values at every sample (right-continuous at the steps); noise of 0.01 K costs
    about its own size."""
    rng = np.random.default_rng(42)
    held = np.repeat(300.0 + rng.uniform(-150.0, 150.0, 12), 250)
    t1, t2 = simulate.difference_equation_pair(held, 12.48, 28.95, 0.1)
    gas = reconstruct_pair(t1, t2, 0.1, 12.48, 28.95)
    print(f"ZOH, on-grid steps, noise-free: max error {np.max(np.abs(gas - held)):.2e} K")
    assert np.max(np.abs(gas - held)) < 1e-5  # measured 1.8e-7 K with 100-300 K steps
    t1 = t1 + 0.01 * rng.standard_normal(t1.size)
    t2 = t2 + 0.01 * rng.standard_normal(t2.size)
    gas = reconstruct_pair(t1, t2, 0.1, 12.48, 28.95)
    print(f"ZOH, on-grid steps, 0.01 K: max error {np.max(np.abs(gas - held)):.3f} K")
    assert np.max(np.abs(gas - held)) < 0.1  # measured 0.011 K; before: the full step


@pytest.mark.parametrize("noise", [0.01, 0.1])
def test_noisy_steps_on_the_grid_have_no_error_beside_them(noise: float) -> None:
    """The defect: a 51 K error one sample after an on-grid step (study A, a_p 0.01, 0.01 K,
    identified taus with a 0.009 s stage). Now the samples at and after each step are as good
    as the rest."""
    from dualprobe.estimation import characterise_pair

    rng = np.random.default_rng(5)
    times = np.round(np.cumsum(rng.uniform(40.0, 100.0, 8)) / 0.1) * 0.1
    times = times[times < 590.0]
    levels = 300.0 + np.cumsum(rng.choice([-1.0, 1.0], times.size + 1)
                               * rng.uniform(100.0, 300.0, times.size + 1))
    profile = simulate.multistep_profile(600.0, levels=levels, step_times=times)
    rec = _pair(profile, (12.48,), (28.95, 0.01), 0.1, 600.0, noise, rng)
    est = characterise_pair(rec.t1, rec.t2, rec.ts, order=2)
    gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, *est.time_constants, noise_std=est.noise_std)
    at = np.searchsorted(rec.t, rec.jumps - 1e-9)  # the samples on the steps
    beside = np.concatenate([at, at + 1, at + 2])
    worst = float(np.max(np.abs(gas - rec.tg)[beside]))
    rest = float(np.max(np.abs(gas - rec.tg)[~rec.jump_mask(2)]))
    print(f"{noise} K, on-grid steps: worst at/after a step {worst:.3f} K, elsewhere {rest:.3f}")
    # at most the error elsewhere plus 10 noise standard deviations (measured within 0.005 K
    # of it; before: up to the full 100-300 K step at the step and 51 K one sample after)
    assert worst < rest + 10.0 * noise


def test_inverse_is_exact_for_two_stage_sensors() -> None:
    """The defect: the stage-by-stage inverse assumed each stage's input held over the
    interval (0.25 K RMSE on study B with the true taus). Now the exact inverse of the whole
    sampled sensor: exact except at the step's own sample (the mean of the two levels)."""
    for a_p in (0.001, 0.1, 1.08):
        rec = _study((12.30, 0.17), (25.72, a_p))
        gas = reconstruct_pair(rec.t1, rec.t2, rec.ts, (12.30, 0.17), (25.72, a_p),
                               mode="inverse")
        keep = ~rec.jump_mask(1) & np.isfinite(gas)
        assert np.isnan(gas[0]) and np.isnan(gas[-1]) and np.all(np.isfinite(gas[1:-1]))
        # measured 1.4e-11 to 2.2e-11 K: rounding amplified by the inverse (~1e4)
        assert np.max(np.abs(gas - rec.tg)[keep]) < 1e-8


@pytest.mark.parametrize("taus", [(12.48,), (12.30, 0.17), (25.72, 1.08), (28.95, 0.001)])
def test_zoh_inverse_of_one_sensor_is_exact_on_the_grid(taus: tuple[float, ...]) -> None:
    rng = np.random.default_rng(1)
    ts = 0.1
    step_times = np.sort(rng.choice(np.arange(50, 1900), 6, replace=False)) * ts
    profile = simulate.multistep_profile(
        200.0, levels=300.0 + rng.uniform(-200.0, 200.0, 7), step_times=step_times
    )
    t = ts * np.arange(2001)
    measured = simulate.simulate_sensor(profile, simulate.SensorModel(taus), t)
    held = zoh_inverse(measured, taus, ts)
    assert np.isnan(held[-1])
    # exact up to rounding amplified by the inverse (measured <= 1.5e-8 K)
    np.testing.assert_allclose(held[:-1], profile(t[:-1]), rtol=0.0, atol=1e-6)


def test_zoh_inverse_of_a_hysteretic_sensor_is_exact_on_the_grid() -> None:
    """First-order sensor heating faster than cooling, gas held over each interval: the mode
    follows from the samples, the inverse is exact."""
    rng = np.random.default_rng(3)
    ts = 0.1
    t = ts * np.arange(2001)
    profile = simulate.multistep_profile(
        200.0, levels=300.0 + rng.uniform(-100.0, 100.0, 9),
        step_times=np.sort(rng.choice(np.arange(20, 1950), 8, replace=False)) * ts,
    )
    measured = simulate.simulate_hysteretic_sensor(profile, 12.0, 16.0, t)
    held = zoh_inverse(measured, 12.0, ts, taus_cool=16.0)
    plain = zoh_inverse(measured, 12.0, ts)
    # rounding amplified by tau/Ts (measured ~1e-9); ignoring the cooling constant: kelvins
    np.testing.assert_allclose(held[:-1], profile(t[:-1]), rtol=0.0, atol=1e-6)
    assert np.nanmax(np.abs(plain - profile(t))) > 1.0


def test_zoh_inverse_of_a_hysteretic_two_stage_sensor() -> None:
    """Two stages, each heating faster than it cools, gas held over each interval. Reference:
    exact stage matrices over Ts/160 sub-steps, each stage's mode at the sub-step's start (an
    O(Ts/160) error where the output stage switches inside an interval: its input crosses it
    after a reversal of the gas)."""
    import scipy.linalg

    rng = np.random.default_rng(2)
    ts, sub = 0.1, 160
    held = np.repeat(300.0 + rng.uniform(-100.0, 100.0, 4), 150)
    heat, cool = (12.3, 0.5), (16.0, 0.7)
    steps = {}
    for first in (False, True):
        for out in (False, True):
            ta, tb = (cool[0] if first else heat[0]), (cool[1] if out else heat[1])
            big = np.array([[-1.0 / ta, 0.0, 1.0 / ta], [1.0 / tb, -1.0 / tb, 0.0], [0, 0, 0]])
            e = scipy.linalg.expm(big * ts / sub)
            steps[(first, out)] = (e[:2, :2], e[:2, 2])
    z = np.array([held[0], held[0]])
    measured = [z[1]]
    for gas in held[:-1]:
        for _ in range(sub):
            out_cooling = bool(z[0] < z[1] or (z[0] == z[1] and gas < z[0]))
            phi, gamma = steps[(bool(gas < z[0]), out_cooling)]
            z = phi @ z + gamma * gas
        measured.append(z[1])
    inverse = zoh_inverse(np.array(measured), heat, ts, taus_cool=cool)
    plain = zoh_inverse(np.array(measured), heat, ts)
    # the reference's own error x the inverse's gain (measured 1.7e-3 K; 9e-3 K with 40
    # sub-steps: it converges); ignoring the cooling time constants: kelvins
    assert np.max(np.abs(inverse[:-1] - held[:-1])) < 0.01
    assert np.max(np.abs(plain[:-1] - held[:-1])) > 1.0


def test_relative_static_model_refers_the_gas_to_sensor_1() -> None:
    """Gains 0.99 / 1.03 (paper Tables I/II) and a 2 K offset on sensor 2: with the gain ratio
    and offset that characterise_pair identifies, the reconstruction is sensor 1's reading of
    the gas (0.99 Tg); with unit gains assumed it is off by kelvins."""
    from dualprobe.estimation import characterise_pair

    rng = np.random.default_rng(3)
    rec = simulate.simulate_pair(
        _step_profile(600.0, rng),
        simulate.SensorModel(PT100_FAST, gain=0.99),
        simulate.SensorModel(PT100_SLOW, gain=1.03),
        ts=0.1,
        duration=600.0,
        noise_std=0.05,
        rng=4,
    )
    t2 = rec.t2 + 2.0
    est = characterise_pair(rec.t1, t2, rec.ts, static_model="affine")
    static = (float(est.details["gain_ratio"]), float(est.details["offset"]))
    assert static[0] == pytest.approx(0.99 / 1.03, rel=1e-3)  # identified, not given
    keep = ~rec.jump_mask(2)
    sensor1 = 0.99 * rec.tg
    scale = math.sqrt(float(np.mean((rec.t1 - sensor1)[keep] ** 2)))

    def error(gas: np.ndarray) -> float:
        return math.sqrt(float(np.mean((gas - sensor1)[keep] ** 2))) / scale

    referred = error(reconstruct_pair(rec.t1, t2, rec.ts, *est.time_constants,
                                      relative_static=static))
    unit = error(reconstruct_pair(rec.t1, t2, rec.ts, *est.time_constants))
    print(f"gains 0.99/1.03, offset 2 K: ratio {referred:.2e} referred, {unit:.3f} unit gains")
    assert referred <= 0.02  # the aim holds (measured 1.5e-4)
    assert unit > 10.0 * referred  # measured 0.15: the gains matter


def test_characterise_reports_a_failed_reconstruction_as_estimation_error(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """A reconstruction that fails on valid input is exit 3 (estimation), never 2 (input)."""
    from dualprobe.cli import main
    from dualprobe.io import EstimationError
    from dualprobe.workflows import characterise, gas

    rec = _study((12.48,), (28.95,), noise=0.01, seed=1)

    def failing(*args: object, **kwargs: object) -> np.ndarray:
        raise ValueError("reconstruct_pair: the smoother found no usable gas intensity")

    monkeypatch.setattr(gas, "reconstruct", failing)  # where the characterisation's gas is made
    with pytest.raises(EstimationError, match=r"reconstruction \(smoother\) .*failed"):
        characterise.characterise_arrays(rec.t1, rec.t2, rec.ts)
    path = tmp_path / "pair.csv"
    rec.to_csv(path)
    assert main(["characterise", str(path), "--reference", "T_g"]) == 3


def test_characterise_order_2_on_study_a_exits_0(tmp_path: Path) -> None:
    """The reported command: `dualprobe characterise --order 2` on noise-free study A at
    a_p = 0.001 s exited with status 2."""
    from dualprobe.cli import main

    path = tmp_path / "study_a.csv"
    _study((12.48,), (28.95, 0.001)).to_csv(path)
    assert main(["characterise", str(path), "--order", "2", "--reference", "T_g"]) == 0


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"mode": "magic"}, "mode must be one of"),
        ({"taus1": (1.0, 2.0, 3.0)}, "1 or 2 time constants"),
        ({"taus1": -1.0}, "finite and > 0"),
        ({"taus2": float("nan")}, "finite and > 0"),
        ({"taus1_cool": (1.0, 2.0)}, "taus1_cool needs 1 time constants"),
        ({"noise_std": -0.1}, "noise_std must be finite and >= 0"),
        ({"ts": 0.0}, "ts must be finite and > 0"),
        ({"relative_static": (0.0, 1.0)}, "relative_static must be"),
        ({"relative_static": (1.0, float("nan"))}, "relative_static must be"),
    ],
)
def test_bad_arguments_raise_value_error(kwargs: dict[str, object], message: str) -> None:
    t1 = np.linspace(0.0, 1.0, 50)
    args: dict[str, object] = {"t1": t1, "t2": t1, "ts": 0.1, "taus1": 1.0, "taus2": 2.0}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        reconstruct_pair(**args)  # type: ignore[arg-type]


def test_bad_signals_raise_value_error() -> None:
    good = np.linspace(0.0, 1.0, 50)
    with pytest.raises(ValueError, match="equal length"):
        reconstruct_pair(good, good[:-1], 0.1, 1.0, 2.0)
    with pytest.raises(ValueError, match="need >= 8 samples"):
        reconstruct_pair(good[:5], good[:5], 0.1, 1.0, 2.0)
    bad = good.copy()
    bad[7] = np.inf
    with pytest.raises(ValueError, match="t2 is not finite at sample 7"):
        reconstruct_pair(good, bad, 0.1, 1.0, 2.0)
