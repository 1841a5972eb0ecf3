"""The C++ causal Kalman reconstruction (dualprobe._core.KalmanReconstructor[F], kalman_filter)
against its specification's reference implementation (dualprobe.reference.kalman): first- and
second-order sensors, random-walk and integrated-random-walk gas, with and without GLR jump
detection, hysteresis modes; double to rounding, float to a fraction of the filter's own
uncertainty; and the physics of issue 7 through the product's pipeline."""

from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from dualprobe import _core as core
from dualprobe import simulate
from dualprobe.reconstruction import fit_smoother
from dualprobe.reconstruction.statespace import causal_filter
from dualprobe.reference import kalman

TS = 0.1
SIGMA = 0.1
FIRST = ((12.48,), (28.95,))  # Pt-100 1.5 mm / 4.5 mm, first-order fits (paper, Table I)
SECOND = ((12.30, 0.17), (25.72, 1.08))  # second-order fits (Table II)
HEAT_COOL = (21.96, 28.86)  # 1.5 mm probe heating / cooling (paper)

# Double: the two implementations differ only in rounding (closed-form 2x2 inverses vs LAPACK,
# fused loops); the start-up and each jump amplify rounding by up to ~1e7 relative to the
# filter's own standard deviation (measured worst 1e-9 of it, on second-order sensors).
DOUBLE_REL_STD = 1e-7
# Float: single-precision rounding (6e-8) of states of 1e2-1e3 K, amplified the same way, is
# measured at most 0.11 of the filter's standard deviation (start-up of second-order sensors,
# hysteresis mode switches decided differently right at equilibrium); 0.25 keeps it a
# statistically irrelevant fraction.
FLOAT_REL_STD = 0.25
# ... and once started (after 20 s), within 0.02 K rms (a fifth of the noise; measured 0.006).
FLOAT_RMS_SETTLED = 0.02
SETTLED = 200


def _steps(duration: float, seed: int) -> simulate.GasProfile:
    """Gas steps of 100-300 K (random sign) every 30-60 s, off the sample grid."""
    rng = np.random.default_rng(seed)
    times = np.cumsum(rng.uniform(30.0, 60.0, size=int(duration / 30.0)))
    times = times[times < duration]
    sizes = rng.uniform(100.0, 300.0, times.size) * rng.choice([-1.0, 1.0], times.size)
    levels = 400.0 + np.concatenate([[0.0], np.cumsum(sizes)])
    return simulate.multistep_profile(duration, levels=list(levels), step_times=list(times))


# (name, taus, gas, detect_jumps, cooling taus of sensor 1 or None)
CASES = [
    (f"{order}-{gas}-{'glr' if detect else 'gauss'}", taus, gas, detect, None)
    for order, taus in (("first", FIRST), ("second", SECOND))
    for gas in ("rw", "irw")
    for detect in (True, False)
] + [
    ("hysteresis-first", ((HEAT_COOL[0],), FIRST[1]), "rw", True, (HEAT_COOL[1],)),
    ("hysteresis-second", ((HEAT_COOL[0], 0.17), SECOND[1]), "irw", True, (HEAT_COOL[1], 0.25)),
]
CASE_IDS = [c[0] for c in CASES]


@functools.cache
def _run(name: str) -> tuple[kalman.FilterResult, dict, dict, np.ndarray]:
    """Reference, C++ double and C++ float on one simulated record of the case (inputs rounded
    to float32 once, so that all three see the same numbers)."""
    _, taus, gas, detect, cool = next(c for c in CASES if c[0] == name)
    seed = CASE_IDS.index(name) + 1
    profile = _steps(300.0, seed)
    t = TS * np.arange(3001)
    rng = np.random.default_rng(seed)
    if cool is None:
        clean1 = simulate.simulate_sensor(profile, simulate.SensorModel(taus[0]), t)
    else:  # hysteretic first stage, then (second order) a linear stage
        clean1 = simulate.simulate_hysteretic_sensor(profile, taus[0][0], cool[0], t)
        if len(taus[0]) == 2:
            clean1 = simulate.simulate_sensor(
                simulate.GasProfile.from_samples(t, clean1), simulate.SensorModel(taus[0][1:]), t
            )
    clean2 = simulate.simulate_sensor(profile, simulate.SensorModel(taus[1]), t)
    y = np.column_stack([clean1, clean2]) + SIGMA * rng.standard_normal((t.size, 2))
    y32 = y.astype(np.float32)
    q = 1e-4 if gas == "rw" else 1e-5  # background intensity: levels hold between steps
    model = kalman.pair_model(taus[0], taus[1], TS, gas=gas, taus1_cool=cool)
    ref = kalman.kalman_filter(y32.astype(float), model, q, (SIGMA, SIGMA), detect_jumps=detect)
    kwargs = {"gas": gas, "detect_jumps": detect, "taus1_cool": cool}
    out64 = core.kalman_filter(
        y32[:, 0].astype(float), y32[:, 1].astype(float), TS, taus[0], taus[1], SIGMA, q, **kwargs
    )
    out32 = core.kalman_filter(y32[:, 0], y32[:, 1], TS, taus[0], taus[1], SIGMA, q, **kwargs)
    return ref, out64, out32, y32


@pytest.mark.parametrize("name", CASE_IDS)
def test_double_agrees_with_reference_to_rounding(name: str) -> None:
    ref, out, _, _ = _run(name)
    assert out["gas"].dtype == np.float64
    std = np.sqrt(ref.gas_variance)
    assert np.max(np.abs(out["gas"] - ref.gas) / std) < DOUBLE_REL_STD
    np.testing.assert_allclose(out["gas_variance"], ref.gas_variance, rtol=1e-8)  # measured 2e-11
    # The same jumps, declared at the same samples, placed in the same intervals.
    np.testing.assert_array_equal(out["jump_detected_at"], ref.jump_detected_at)
    np.testing.assert_array_equal(out["jump_interval"], ref.jump_interval)
    np.testing.assert_allclose(out["jump_size"], ref.jump_size, rtol=1e-7)
    # log-likelihood: a sum of ~3000 terms, rounding 1e-16 each (measured 5e-10 relative).
    assert out["log_likelihood"] == pytest.approx(ref.log_likelihood, rel=1e-8)
    assert out["refused"] == 0


@pytest.mark.parametrize("name", CASE_IDS)
def test_float_agrees_with_reference_within_its_uncertainty(name: str) -> None:
    ref, _, out, _ = _run(name)
    assert out["gas"].dtype == np.float32
    diff = np.abs(out["gas"].astype(float) - ref.gas)
    assert np.all(np.isfinite(diff))
    assert np.max(diff / np.sqrt(ref.gas_variance)) < FLOAT_REL_STD
    assert math.sqrt(np.mean(diff[SETTLED:] ** 2)) < FLOAT_RMS_SETTLED
    # Every jump found by the reference is found in float, at most a sample apart.
    assert out["jump_detected_at"].size == ref.jump_detected_at.size
    assert np.all(np.abs(out["jump_detected_at"] - ref.jump_detected_at) <= 1)
    # The covariance recursion does not depend on the data: float rounding only (measured
    # 3e-2 relative at worst, on the ill-conditioned start of second-order sensors).
    np.testing.assert_allclose(out["gas_variance"], ref.gas_variance, rtol=0.1)


@pytest.mark.parametrize("name", ["second-irw-glr", "hysteresis-second"])
def test_discretisation_matches_the_pair_model(name: str) -> None:
    _, taus, gas, _, cool = next(c for c in CASES if c[0] == name)
    q = 0.7
    model = kalman.pair_model(taus[0], taus[1], TS, gas=gas, taus1_cool=cool)
    filt = core.KalmanReconstructor(TS, taus[0], taus[1], (0.1, 0.2), q, gas=gas, taus1_cool=cool)
    assert filt.states == model.n
    assert filt.modes == model.phi.shape[0]
    process = q * model.q_unit + model.floor((0.1, 0.2), q)
    for m in range(filt.modes):
        # Taylor/doubling vs scipy's Pade on the Van Loan matrix: both ~1e-16 of the largest
        # entry; entries span 1e-12..1, so compare against the largest.
        np.testing.assert_allclose(filt.transition(m), model.phi[m], rtol=0, atol=1e-14)
        scale = np.max(np.abs(process[m]))
        np.testing.assert_allclose(filt.process_noise(m), process[m], rtol=0, atol=1e-13 * scale)


def test_streaming_batch_and_skip_are_consistent() -> None:
    _, out64, _, y32 = _run("first-rw-glr")
    y = y32[:600].astype(float)
    taus = FIRST
    streaming = core.KalmanReconstructor(TS, taus[0], taus[1], SIGMA, 1e-4)
    gas = []
    for a, b in y:
        assert streaming.update(a, b) == "ok"
        gas.append(streaming.gas)
    batch = core.KalmanReconstructor(TS, taus[0], taus[1], SIGMA, 1e-4)
    out = batch.update_batch(y[:, 0], y[:, 1])
    np.testing.assert_array_equal(out, np.array(gas))  # same arithmetic, bit for bit
    np.testing.assert_array_equal(out, out64["gas"][:600])
    assert batch.samples == 600
    assert batch.state.shape == (3,) and batch.covariance.shape == (3, 3)
    assert batch.state[0] == out[-1]
    # A non-finite pair is refused (state untouched), and in a batch the instant is skipped
    # so that later samples stay on their time grid: equal to an explicit skip().
    assert streaming.update(float("nan"), 1.0) == "non_finite_input"
    assert streaming.samples == 600
    holes = y.copy()
    holes[300, 1] = np.inf
    with_holes = core.KalmanReconstructor(TS, taus[0], taus[1], SIGMA, 1e-4).update_batch(
        holes[:, 0], holes[:, 1]
    )
    manual = core.KalmanReconstructor(TS, taus[0], taus[1], SIGMA, 1e-4)
    manual.update_batch(y[:300, 0], y[:300, 1])
    assert manual.skip() == "ok"
    rest = manual.update_batch(y[301:, 0], y[301:, 1])
    assert np.isnan(with_holes[300])
    np.testing.assert_array_equal(with_holes[301:], rest)
    # reset() starts over.
    batch.reset()
    np.testing.assert_array_equal(batch.update_batch(y[:, 0], y[:, 1]), out)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"taus1": (1.0, 2.0, 3.0)}, "taus1"),
        ({"taus2": (-1.0,)}, "taus2"),
        ({"taus1_cool": (1.0, 2.0)}, "taus1_cool"),
        ({"sigma": 0.0}, "invalid Kalman configuration"),
        ({"sigma": (0.1, 0.1, 0.1)}, "sigma"),
        ({"q": -1.0}, "invalid Kalman configuration"),
        ({"ts": 0.0}, "invalid Kalman configuration"),
        ({"window": 257}, "invalid Kalman configuration"),
        ({"false_alarm": 1.0}, "invalid Kalman configuration"),
        ({"gas": "brownian"}, "gas must be"),
    ],
)
def test_bad_configuration_raises(kwargs: dict, message: str) -> None:
    args = {"ts": TS, "taus1": (12.48,), "taus2": (28.95,), "sigma": SIGMA, "q": 1e-4}
    args.update(kwargs)
    with pytest.raises(ValueError, match=message):
        core.KalmanReconstructor(**args)
    with pytest.raises(ValueError, match=message):
        core.kalman_filter(np.zeros(5), np.zeros(5), **args)


def test_bad_signals_raise() -> None:
    with pytest.raises(ValueError, match="differ in length"):
        core.kalman_filter(np.zeros(5), np.zeros(4), TS, 12.48, 28.95, SIGMA, 1e-4)
    with pytest.raises(ValueError, match="one-dimensional"):
        core.kalman_filter(np.zeros((5, 2)), np.zeros((5, 2)), TS, 12.48, 28.95, SIGMA, 1e-4)
    with pytest.raises(ValueError, match="numeric"):
        core.kalman_filter(np.array(["a", "b"]), np.array(["a", "b"]), TS, 12.48, 28.95, SIGMA, 1)
    # Lists are accepted (in double); float32 pairs run in float, even as strided views.
    assert core.kalman_filter([1.0, 2.0], [1.0, 2.0], TS, 12.48, 28.95, SIGMA, 1)["gas"].size == 2
    pair = np.zeros((8, 2), dtype=np.float32)
    assert core.kalman_filter(pair[:, 0], pair[:, 1], TS, 1, 2, SIGMA, 1)["gas"].dtype == np.float32
    filt = core.KalmanReconstructorF(TS, 12.48, 28.95, SIGMA, 1e-4)
    with pytest.raises(ValueError, match="retune"):
        filt.retune(TS, (12.3, 0.17), 28.95, SIGMA, 1e-4)  # another state layout


def test_physics_steps_through_the_product_pipeline() -> None:
    """Issue 7: 10 Hz Pt-100 pair, 0.1 K noise, steps of 100-300 K off the sample grid. With
    the gas model, intensity and noise levels the smoother identifies (as
    reconstruct_pair(mode="filter") does), the C++ filter in double and in float is far better
    than the faster sensor and equals the product's Python filter path."""
    profile = _steps(600.0, 7)
    rec = simulate.simulate_pair(
        profile,
        simulate.PT100_1P5MM_FIRST.with_gain(1.0),
        simulate.PT100_4P5MM_FIRST.with_gain(1.0),
        ts=TS,
        duration=600.0,
        noise_std=SIGMA,
        rng=7,
    )
    taus = (simulate.PT100_1P5MM_FIRST.taus, simulate.PT100_4P5MM_FIRST.taus)
    fit = fit_smoother(rec.t1, rec.t2, TS, taus[0], taus[1])
    q = fit.background_q
    out = core.kalman_filter(rec.t1, rec.t2, TS, taus[0], taus[1], fit.sigma, q, gas=fit.model.gas)
    out32 = core.kalman_filter(
        rec.t1.astype(np.float32),
        rec.t2.astype(np.float32),
        TS,
        taus[0],
        taus[1],
        fit.sigma,
        q,
        gas=fit.model.gas,
    )
    y = np.column_stack([rec.t1, rec.t2])
    # the reference filter on the reference's own discretisation of the same model
    model = kalman.pair_model(taus[0], taus[1], TS, gas=fit.model.gas)
    reference = kalman.kalman_filter(y - fit.offset, model, q, fit.sigma).gas + fit.offset
    # the product's causal path (what reconstruct_pair(mode="filter") runs)
    product_gas, product_variance = causal_filter(y - fit.offset, fit.model, q, fit.sigma)
    product = product_gas + fit.offset
    keep = ~rec.jump_mask(margin=2)  # samples right beside a gas jump excluded

    def rmse(x: np.ndarray) -> float:
        return float(np.sqrt(np.mean((x - rec.tg)[keep] ** 2)))

    sensor = rmse(rec.t1)
    # The issue asks <= 6 % of the faster sensor's RMSE (aim 2 %); measured 1.2-1.4 %.
    assert rmse(out["gas"]) < 0.03 * sensor
    assert rmse(out32["gas"].astype(float)) < 0.03 * sensor
    # The reference (offset removed first; the model is offset-invariant) and the product's
    # path: the same filter to rounding of the centring
    np.testing.assert_allclose(out["gas"], reference, rtol=0, atol=1e-6)
    np.testing.assert_allclose(out["gas"], product, rtol=0, atol=1e-6)
    # its variance (T_g_std in filter mode) is the core filter's, checked above against the
    # reference's; the centring changes no decision of the filter
    np.testing.assert_allclose(product_variance, out["gas_variance"], rtol=1e-9)
