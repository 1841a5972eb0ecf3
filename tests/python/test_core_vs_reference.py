"""The C++ core (through the bindings) against the independent NumPy/SciPy reference."""

from __future__ import annotations

import numpy as np
import pytest

from dualprobe import _core
from dualprobe import simulate as sim
from dualprobe.reference import difference as ref


def _noisy_pair(seed: int, ts: float = 1.0, noise: float = 0.05) -> sim.PairRecording:
    profile = sim.multistep_profile(3000.0, mean=300.0, amplitude=10.0, mean_hold=200.0, rng=seed)
    return sim.simulate_pair(
        profile,
        sim.SensorModel((12.48,)),
        sim.SensorModel((28.95,)),
        ts=ts,
        duration=3000.0,
        noise_std=noise,
        rng=seed + 1000,
    )


@pytest.mark.parametrize("method", ["ls", "tls", "gtls"])
@pytest.mark.parametrize("forgetting", [1.0, 0.999])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_core_matches_reference_on_noisy_data(method: str, forgetting: float, seed: int) -> None:
    rec = _noisy_pair(seed)
    core = _core.estimate_difference(
        rec.t1, rec.t2, rec.ts, method, sigma1=0.05, sigma2=0.05, forgetting=forgetting
    )
    reference = ref.estimate(
        rec.t1, rec.t2, rec.ts, method=method, sigma1=0.05, sigma2=0.05, forgetting=forgetting
    )
    assert core["status"] == reference.status == "ok"
    # Issue 2: double agreement to 1e-9 relative. Both solve the same 3x3 problem; the
    # reference works on the data matrix (SVD/lstsq), the core on accumulated moments, so
    # they differ by rounding amplified by the scatter's condition number (~1e4 here).
    for key in ("beta", "b1", "b2", "tau1", "tau2"):
        assert core[key] == pytest.approx(getattr(reference, key), rel=1e-9), key


def test_streaming_equals_batch() -> None:
    rec = _noisy_pair(4)
    streaming = _core.DifferenceEstimator(rec.ts, "gtls", 0.05, 0.05)
    for a, b in zip(rec.t1, rec.t2, strict=True):
        assert streaming.update(float(a), float(b)) == "ok"
    chunked = _core.DifferenceEstimator(rec.ts, "gtls", 0.05, 0.05)
    for part in np.array_split(np.arange(rec.t1.size), 7):
        chunked.update_batch(rec.t1[part], rec.t2[part])
    batch = _core.estimate_difference(rec.t1, rec.t2, rec.ts, "gtls", 0.05, 0.05)
    s, c = streaming.solve(), chunked.solve()
    for key in ("tau1", "tau2", "beta"):
        # Identical arithmetic in the same order: equal to the last bit.
        assert s[key] == c[key] == batch[key]
    np.testing.assert_array_equal(streaming.scatter, chunked.scatter)


def test_float_core_close_to_double_reference() -> None:
    rec = _noisy_pair(5)
    core = _core.estimate_difference(
        rec.t1.astype(np.float32), rec.t2.astype(np.float32), rec.ts, "gtls", 0.05, 0.05
    )
    reference = ref.estimate(rec.t1, rec.t2, rec.ts, method="gtls", sigma1=0.05, sigma2=0.05)
    # float32 samples of ~300 K carry 1.5e-5 K rounding against 0.05 K noise: the estimate
    # moves by well under 1e-3 relative.
    assert core["tau1"] == pytest.approx(reference.tau1, rel=1e-3)
    assert core["tau2"] == pytest.approx(reference.tau2, rel=1e-3)


def test_reconstruction_matches_reference() -> None:
    rec = _noisy_pair(6)
    core = _core.reconstruct_inverse(rec.t1, 12.48, rec.ts)
    reference = ref.exact_inverse(rec.t1, 12.48, rec.ts)
    np.testing.assert_allclose(core, reference, rtol=1e-12, atol=1e-9)
    assert np.isnan(core[-1]) and np.isnan(reference[-1])


def test_noise_free_exactness_through_bindings() -> None:
    gas = sim.multistep_profile(2000.0, mean=300.0, amplitude=10.0, mean_hold=50.0, rng=9)
    tg = gas(np.arange(2001.0))
    t1, t2 = sim.difference_equation_pair(tg, 12.48, 28.95, 1.0)
    for method in ("ls", "tls", "gtls"):
        out = _core.estimate_difference(t1, t2, 1.0, method, 0.05, 0.05)
        # Issue 2: time constants to 1e-8 s on noise-free difference-equation data.
        assert out["tau1"] == pytest.approx(12.48, abs=1e-8)
        assert out["tau2"] == pytest.approx(28.95, abs=1e-8)
    rebuilt = _core.reconstruct_inverse(t1, 12.48, 1.0)
    np.testing.assert_allclose(rebuilt[:-1], tg[:-1], rtol=0, atol=1e-9)


def test_non_finite_samples_are_refused_not_propagated() -> None:
    rec = _noisy_pair(7)
    t1 = rec.t1.copy()
    t1[500] = np.nan
    t1[900] = np.inf
    out = _core.estimate_difference(t1, rec.t2, rec.ts, "gtls", 0.05, 0.05)
    assert out["refused"] == 2
    assert out["status"] == "ok" and np.isfinite(out["tau1"])


def test_a_nan_replacing_a_sample_drops_its_two_differences() -> None:
    """Issue 12: update() and update_batch() both break the chain at a refused sample, so no
    row spans 2 Ts: the scatter is the reference's without the two rows that touch it."""
    rec = _noisy_pair(7)
    t1 = rec.t1.copy()
    t1[500] = np.nan
    single = _core.DifferenceEstimator(rec.ts, method="gtls", sigma1=0.05, sigma2=0.05)
    statuses = [single.update(float(a), float(b)) for a, b in zip(t1, rec.t2, strict=True)]
    assert statuses.count("non_finite_input") == 1 and statuses[500] == "non_finite_input"
    batch = _core.DifferenceEstimator(rec.ts, method="gtls", sigma1=0.05, sigma2=0.05)
    assert batch.update_batch(t1, rec.t2) == 1
    assert single.rows == batch.rows == t1.size - 3
    np.testing.assert_array_equal(single.scatter, batch.scatter)
    rows = ref.regression_rows(np.nan_to_num(t1), rec.t2)
    keep = np.ones(rows.shape[0], dtype=bool)
    keep[[499, 500]] = False  # rows k = 500, 501 (row index k - 1) touch sample 500
    expected = rows[keep].T @ rows[keep]
    np.testing.assert_allclose(single.scatter, expected, rtol=1e-12, atol=1e-12 * np.max(expected))


def test_bad_arguments_raise_value_error() -> None:
    x = np.zeros(10)
    with pytest.raises(ValueError, match="method"):
        _core.estimate_difference(x, x, 1.0, "foo")
    with pytest.raises(ValueError, match="sigma1"):
        _core.estimate_difference(x, x, 1.0, "gtls")
    with pytest.raises(ValueError, match="length"):
        _core.estimate_difference(x, np.zeros(9), 1.0, "ls")
    with pytest.raises(ValueError):
        _core.reconstruct_inverse(x, -1.0, 1.0)


def test_hysteretic_kernel_matches_numpy_loop() -> None:
    rng = np.random.default_rng(3)
    tg = np.repeat(rng.uniform(50, 300, size=30), 200)
    out = _core.simulate_hysteretic_first_order(tg, 0.1, 21.96, 28.86, 100.0)
    expected = np.empty_like(tg)
    expected[0] = 100.0
    b_heat, b_cool = -np.expm1(-0.1 / 21.96), -np.expm1(-0.1 / 28.86)
    for k in range(1, tg.size):
        drive = tg[k - 1] - expected[k - 1]
        expected[k] = expected[k - 1] + (b_heat if drive > 0 else b_cool) * drive
    np.testing.assert_allclose(out, expected, rtol=1e-13, atol=1e-10)
