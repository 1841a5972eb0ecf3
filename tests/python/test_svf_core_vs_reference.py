"""The streaming C++ SVF core (``dualprobe._core.SvfEstimator``/``SvfEstimatorF``/``estimate_svf``)
against the independent batch reference :mod:`dualprobe.reference.svf` (design.md 1.4), and the
physics of issues 6 and 7 through the core, with the filter time constant, noise level and
direction windows chosen by the Python layer as the ECU would receive them."""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
import pytest

from dualprobe import _core
from dualprobe import simulate as sim
from dualprobe.estimation import svf as estimation_svf
from dualprobe.models.noise import ORDER_ESTIMATION, estimate_noise_std
from dualprobe.reference import svf, svf_filter

PT1 = (12.48,)
PT2 = (28.95,)
SECOND1 = (12.30, 0.17)
SECOND2 = (25.72, 1.08)


@functools.cache
def _small_moves(seed: int, static: str) -> tuple[np.ndarray, np.ndarray, float]:
    """Issue 7: 10 Hz Pt-100 pair, 0.1 K noise, gas within +/- 5 K (affine: the paper's static
    gains 0.99 / 1.03 and a 0.3 K offset, which only the affine model explains)."""
    rng = np.random.default_rng(700 + seed)
    profile = sim.multistep_profile(600.0, mean=20.0, amplitude=5.0, mean_hold=60.0, rng=rng)
    gains = (0.99, 1.03) if static == "affine" else (1.0, 1.0)
    rec = sim.simulate_pair(profile, sim.SensorModel(PT1, gain=gains[0]),
                            sim.SensorModel(PT2, gain=gains[1]), ts=0.1, duration=600.0,
                            noise_std=0.1, rng=rng)
    offset = 0.3 if static == "affine" else 0.0
    return rec.t1, rec.t2 + offset, 0.1


@functools.cache
def _second_order(seed: int) -> tuple[np.ndarray, np.ndarray, float]:
    """Issue 6: 100 Hz, the paper's second-order pair, 0.01 K, 100-300 K steps off the grid."""
    rng = np.random.default_rng(600 + seed)
    levels = 300.0 + np.cumsum(rng.choice([-1.0, 1.0], 6) * rng.uniform(100.0, 300.0, 6))
    times = np.cumsum(rng.uniform(60.0, 90.0, 5)) + 0.00371
    profile = sim.multistep_profile(450.0, levels=levels, step_times=times)
    rec = sim.simulate_pair(profile, sim.SensorModel(SECOND1), sim.SensorModel(SECOND2),
                            ts=0.01, duration=450.0, noise_std=0.01, rng=rng)
    return rec.t1, rec.t2, 0.01


@functools.cache
def _hysteretic(seed: int) -> tuple[np.ndarray, np.ndarray, float, tuple[float, ...]]:
    """Issue 6: 10 Hz pair, heating 25-35 % faster than cooling, 0.05 K, 100-300 K steps."""
    rng = np.random.default_rng(800 + seed)
    heat1 = rng.uniform(10.0, 20.0)
    heat2 = heat1 * rng.uniform(2.0, 3.0)
    cool1 = heat1 * rng.uniform(1.25, 1.35)
    cool2 = heat2 * rng.uniform(1.25, 1.35)
    levels = 300.0 + np.cumsum(rng.choice([-1.0, 1.0], 8) * rng.uniform(100.0, 300.0, 8))
    times = np.cumsum(rng.uniform(150.0, 200.0, 7)) + 0.0371
    profile = sim.multistep_profile(1500.0, levels=levels, step_times=times)
    t = 0.1 * np.arange(15001)
    t1 = sim.simulate_hysteretic_sensor(profile, heat1, cool1, t)
    t2 = sim.simulate_hysteretic_sensor(profile, heat2, cool2, t)
    t1 = t1 + 0.05 * rng.standard_normal(t.size)
    t2 = t2 + 0.05 * rng.standard_normal(t.size)
    return t1, t2, 0.1, (heat1, cool1, heat2, cool2)


def _settings(t1: np.ndarray, t2: np.ndarray, ts: float, order: int, static: str,
              hysteresis: bool = False) -> dict[str, Any]:
    """What the Python layer hands the core: noise levels, tf and (hysteresis) windows."""
    sigma = (estimate_noise_std(t1, ORDER_ESTIMATION), estimate_noise_std(t2, ORDER_ESTIMATION))
    tf, _ = estimation_svf.choose_filter_time_constant(t1, t2, ts, order, sigma, static)
    out: dict[str, Any] = {"tf": tf, "order": order, "static": static, "sigma1": sigma[0],
                           "sigma2": sigma[1]}
    if hysteresis:
        disc = svf_filter.discretise_filter(tf, ts, 2)
        out["hysteresis"] = True
        out["direction_half_window"] = tuple(
            svf_filter.choose_direction_half_window(x, disc, s, estimation_svf.DIRECTION_TOLERANCE)
            for x, s in ((t1, sigma[0]), (t2, sigma[1])))
    return out


def _case(name: str, static: str, seed: int) -> tuple[np.ndarray, np.ndarray, float,
                                                      dict[str, Any]]:
    if name == "order1":
        t1, t2, ts = _small_moves(seed, static)
        return t1, t2, ts, _settings(t1, t2, ts, 1, static)
    if name == "order2":
        t1, t2, ts = _second_order(seed)
        return t1, t2, ts, _settings(t1, t2, ts, 2, static)
    t1, t2, ts, _ = _hysteretic(seed)
    return t1, t2, ts, _settings(t1, t2, ts, 1, static, hysteresis=True)


def _reference(t1: np.ndarray, t2: np.ndarray, ts: float, s: dict[str, Any]) -> svf.SvfResult:
    hysteresis = bool(s.get("hysteresis", False))
    result = svf.estimate(t1, t2, ts, tf=s["tf"], order=s["order"], sigma1=s["sigma1"],
                          sigma2=s["sigma2"], static=s["static"], hysteresis=hysteresis,
                          direction_half_window=None, diagnostics=False,
                          direction_tolerance=estimation_svf.DIRECTION_TOLERANCE)
    if hysteresis:  # the reference chose the same windows from the same rule
        assert tuple(result.extra["direction_half_windows"]) == s["direction_half_window"]
    return result


def _core_taus(d: dict[str, Any]) -> np.ndarray:
    if d["hysteresis"]:
        heat, cool = d["time_constants_heat"], d["time_constants_cool"]
        return np.array([heat[0][0], cool[0][0], heat[1][0], cool[1][0]])
    return np.concatenate([d["time_constants"][0], d["time_constants"][1]])


def _reference_taus(r: svf.SvfResult) -> np.ndarray:
    if "heat" in r.extra:
        heat, cool = r.extra["heat"], r.extra["cool"]
        return np.array([heat[0][0], cool[0][0], heat[1][0], cool[1][0]])  # type: ignore[index]
    return np.concatenate([r.time_constants[0], r.time_constants[1]])


CASES = [(name, static, seed) for name in ("order1", "order2", "hysteresis")
         for static in ("unit", "affine") for seed in (0, 1)]


# --------------------------------------------------------------------------------------------
# Agreement with the reference
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "static", "seed"), CASES)
def test_double_core_matches_reference(name: str, static: str, seed: int) -> None:
    t1, t2, ts, s = _case(name, static, seed)
    ref = _reference(t1, t2, ts, s)
    core = _core.estimate_svf(t1, t2, ts, **s)
    assert core["precision"] == "float64"
    assert core["status"] == ref.status == "ok"
    assert core["rows"] == t1.size == ref.rows
    # Both solve the same GTLS problem; they differ by the rounding of the accumulated moments
    # (streaming sums vs matrix products, ~1e-16 per row over 6000-45000 rows) amplified by
    # the conditioning of the generalised eigenvector (largest eigenvalue / gap up to ~1e6 for
    # the 0.17 s pole): measured <= 6e-10 relative on every time constant and theta entry.
    np.testing.assert_allclose(_core_taus(core), _reference_taus(ref), rtol=1e-8)
    np.testing.assert_allclose(core["theta"], ref.theta, rtol=1e-8)
    assert core["gain_ratio"] == pytest.approx(ref.extra["gain_ratio"], rel=1e-9)
    if static == "affine":
        # A mean of theta . z: absolute rounding of kelvin-sized sums (measured <= 2e-11 K).
        assert core["offset"] == pytest.approx(float(ref.extra["offset"]), abs=1e-8)
    # Eigenvalues of a symmetric matrix carry absolute rounding of eps * the largest one.
    mu_core = np.asarray(core["eigenvalues"])
    np.testing.assert_allclose(mu_core, ref.eigenvalues, rtol=1e-9,
                               atol=1e-11 * float(np.max(np.abs(ref.eigenvalues))))


@pytest.mark.parametrize(("name", "static", "seed"), CASES[::2])
def test_float_core_is_close_to_double(name: str, static: str, seed: int) -> None:
    t1, t2, ts, s = _case(name, static, seed)
    double = _core.estimate_svf(t1, t2, ts, **s)
    single = _core.estimate_svf(t1.astype(np.float32), t2.astype(np.float32), ts, **s)
    assert single["precision"] == "float32"
    assert single["status"] == double["status"] == "ok"
    got, want = _core_taus(single), _core_taus(double)
    # float32: samples of up to ~1000 K carry 3e-5 K rounding, and the filter states and the
    # (block-summed, Kahan-merged) moments ~1e-7 relative rounding, amplified by the same
    # conditioning as above. Measured: <= 5e-6 (first order, hysteresis), <= 2e-5 (dominant
    # second-order poles), <= 2e-3 (the 0.17 s and 1.08 s poles), <= 4e-7 (gain ratio).
    if name == "order2":
        np.testing.assert_allclose(got[[0, 2]], want[[0, 2]], rtol=2e-4)
        np.testing.assert_allclose(got[[1, 3]], want[[1, 3]], rtol=1e-2)
    else:
        np.testing.assert_allclose(got, want, rtol=5e-5)
    assert single["gain_ratio"] == pytest.approx(double["gain_ratio"], rel=4e-6)


def test_projected_scatter_and_noise_covariance_match_reference() -> None:
    t1, t2, ts = _small_moves(0, "affine")
    for static in ("unit", "affine"):
        for order in (1, 2):
            disc = svf_filter.discretise_filter(4.0, ts, order + 1)
            est = _core.SvfEstimator(ts, 4.0, order=order, static=static, sigma1=0.1, sigma2=0.2)
            est.update_batch(t1, t2)
            cols = svf.regression_columns(t1, t2, disc, order, static=static)
            ref = svf.projected_scatter(cols, disc, 0, static == "affine")
            # rounding of the accumulated moments against the largest entry
            np.testing.assert_allclose(est.scatter, ref, rtol=0,
                                       atol=1e-10 * float(np.max(np.abs(ref))))
            cov = svf.noise_covariance(disc, order, 0.1, 0.2, static)
            np.testing.assert_allclose(est.noise_covariance, cov, rtol=1e-10, atol=1e-18)


# --------------------------------------------------------------------------------------------
# Physics through the core (issue 6, issue 7), double and float
# --------------------------------------------------------------------------------------------


def _as(dtype: type, *arrays: np.ndarray) -> list[np.ndarray]:
    return [np.asarray(a, dtype=dtype) for a in arrays]


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_issue7_small_moves_at_10_hz_within_5_percent(dtype: type, seed: int) -> None:
    t1, t2, ts = _small_moves(seed, "unit")
    s = _settings(t1, t2, ts, 1, "unit")
    core = _core.estimate_svf(*_as(dtype, t1, t2), ts, **s)
    assert core["status"] == "ok"
    # issue 7: both within 5 % by default; measured <= 1.4 % on these records
    np.testing.assert_allclose(_core_taus(core), [PT1[0], PT2[0]], rtol=0.05)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("seed", [0, 1])
def test_issue6_second_order_100_hz(dtype: type, seed: int) -> None:
    t1, t2, ts = _second_order(seed)
    s = _settings(t1, t2, ts, 2, "unit")
    core = _core.estimate_svf(*_as(dtype, t1, t2), ts, **s)
    assert core["status"] == "ok"
    taus = _core_taus(core)
    truth = np.array([*SECOND1, *SECOND2])
    # issue 6: dominant within 5 %, fast within 25 %; measured <= 0.004 % and <= 0.3 %
    np.testing.assert_allclose(taus[[0, 2]], truth[[0, 2]], rtol=0.05)
    np.testing.assert_allclose(taus[[1, 3]], truth[[1, 3]], rtol=0.25)
    for sensor in core["time_constants"]:
        assert list(sensor) == sorted(sensor, reverse=True)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("seed", [0, 1])
def test_issue6_hysteresis_four_time_constants_within_5_percent(dtype: type, seed: int) -> None:
    t1, t2, ts, truth = _hysteretic(seed)
    s = _settings(t1, t2, ts, 1, "unit", hysteresis=True)
    core = _core.estimate_svf(*_as(dtype, t1, t2), ts, **s)
    assert core["status"] == "ok"
    # issue 6: all four within 5 %; measured <= 0.06 %
    np.testing.assert_allclose(_core_taus(core), truth, rtol=0.05)


# --------------------------------------------------------------------------------------------
# Streaming, refusals, arguments
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("cls", "dtype"), [("SvfEstimator", np.float64),
                                            ("SvfEstimatorF", np.float32)])
@pytest.mark.parametrize("name", ["order1", "order2", "hysteresis"])
def test_chunked_stream_equals_batch(cls: str, dtype: type, name: str) -> None:
    t1, t2, ts, s = _case(name, "affine", 0)
    t1, t2 = _as(dtype, t1[:6000], t2[:6000])
    batch = _core.estimate_svf(t1, t2, ts, **s)
    est = getattr(_core, cls)(ts, **s)
    for part in np.array_split(np.arange(t1.size), 7):
        assert est.update_batch(t1[part], t2[part]) == 0
        est.solve()  # must not disturb the stream
    single = getattr(_core, cls)(ts, **s)
    for a, b in zip(t1, t2, strict=True):
        assert single.update(float(a), float(b)) == "ok"
    streamed, one_by_one = est.solve(), single.solve()
    # identical arithmetic in the same order: equal to the last bit
    for result in (streamed, one_by_one):
        assert result["theta"] == batch["theta"]
        assert result["eigenvalues"] == batch["eigenvalues"]
    assert est.samples == t1.size
    est.reset()
    assert est.samples == 0 and est.solve()["status"] == "insufficient_excitation"


def test_non_finite_samples_are_refused() -> None:
    t1, t2, ts, s = _case("order1", "unit", 0)
    bad1, bad2 = t1.copy(), t2.copy()
    bad1[[100, 2000]] = np.nan
    bad2[3000] = np.inf
    dirty = _core.estimate_svf(bad1, bad2, ts, **s)
    assert dirty["refused"] == 3
    keep = np.isfinite(bad1) & np.isfinite(bad2)
    clean = _core.estimate_svf(t1[keep], t2[keep], ts, **s)
    assert dirty["theta"] == clean["theta"]  # a refused sample leaves no trace
    est = _core.SvfEstimator(ts, **s)
    assert est.update(float("nan"), 1.0) == "non_finite_input"
    assert est.samples == 0


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"order": 3}, "order"),
    ({"static": "cubic"}, "static"),
    ({"order": 2, "hysteresis": True, "direction_half_window": 5}, "order 1"),
    ({"hysteresis": True}, "direction_half_window"),
    ({"hysteresis": True, "direction_half_window": 0}, "invalid SVF configuration"),
    ({"hysteresis": True, "direction_half_window": (5, 1025)}, "invalid SVF configuration"),
    ({"tf": 0.0}, "invalid SVF configuration"),
    ({"tf": 1e-5}, "invalid SVF configuration"),
    ({"forgetting": 1.5}, "invalid SVF configuration"),
    ({"sigma1": -0.1}, "invalid SVF configuration"),
])
def test_bad_arguments_raise_value_error(kwargs: dict[str, Any], message: str) -> None:
    args: dict[str, Any] = {"tf": 2.0}
    args.update(kwargs)
    for cls in (_core.SvfEstimator, _core.SvfEstimatorF):
        with pytest.raises(ValueError, match=message):
            cls(0.1, **args)
    with pytest.raises(ValueError, match=message):
        _core.estimate_svf(np.zeros(50), np.zeros(50), 0.1, **args)


def test_bad_arrays_raise_value_error() -> None:
    with pytest.raises(ValueError, match="differ in length"):
        _core.estimate_svf(np.zeros(50), np.zeros(49), 0.1, 2.0)
    with pytest.raises(ValueError, match="one-dimensional"):
        _core.estimate_svf(np.zeros((5, 10)), np.zeros((5, 10)), 0.1, 2.0)
    # lists and integers are converted to float64
    out = _core.estimate_svf(list(range(100)), [0] * 100, 0.1, 2.0)
    assert out["precision"] == "float64"


def test_sizes_and_capacity_are_reported() -> None:
    assert _core.SvfEstimator.max_half_window == 1024
    sizes = {(order, static): _core.SvfEstimatorF(0.1, 2.0, order=order, static=static).nbytes
             for order in (1, 2) for static in ("unit", "affine")}
    # the ECU build of the first-order float estimator fits in half a kilobyte
    assert sizes[(1, "unit")] <= 512
    assert all(math.isfinite(v) and v > 0 for v in sizes.values())
