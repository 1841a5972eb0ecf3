"""`dualprobe bench`: throughput of the C++ streaming estimator against NumPy and memory bandwidth.

All throughputs are measured in one run on the same arrays: the C++ streaming update + solve
(double and float), the NumPy reference estimator, and a memory-bandwidth baseline that only
reads both arrays once (``np.add.reduce``), which bounds what any one-pass estimator can do.
"""

from __future__ import annotations

import math
import platform
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import scipy.signal

__all__ = ["DEFAULT_SAMPLES", "BenchUnavailable", "bench_throughput", "make_pair"]

DEFAULT_SAMPLES = 10_000_000
BENCH_TS = 1e-3  # s: a 1 kHz thermocouple pair
BENCH_TAUS = (0.020, 0.080)  # s
BENCH_NOISE = 0.05  # K


class BenchUnavailable(RuntimeError):
    """A component to benchmark (e.g. the compiled core) is not available."""


def make_pair(
    samples: int, *, ts: float = BENCH_TS, seed: int = 7
) -> tuple[np.ndarray, np.ndarray]:
    """A long first-order sensor pair (20 ms / 80 ms at 1 kHz) on random gas steps, with noise.

    Generated with `scipy.signal.lfilter` (exact discrete first-order model, eq. 8) because the
    bench needs 10^7 samples quickly; the content only has to be realistic, not off-grid exact.
    """
    if samples < 3:
        raise ValueError(f"bench: need at least 3 samples, got {samples}")
    rng = np.random.default_rng(seed)
    hold = int(0.5 / ts)  # a new gas level every 0.5 s
    levels = 600.0 + 50.0 * rng.standard_normal(samples // hold + 2)
    gas = np.repeat(levels, hold)[:samples]
    pair = []
    for tau in BENCH_TAUS:
        a = math.exp(-ts / tau)
        # T(k) = a T(k-1) + (1 - a) Tg(k-1), started in equilibrium with the first level.
        b, den = [0.0, 1.0 - a], [1.0, -a]
        initial = scipy.signal.lfilter_zi(b, den) * gas[0]
        response, _ = scipy.signal.lfilter(b, den, gas, zi=initial)
        pair.append(response + BENCH_NOISE * rng.standard_normal(samples))
    return pair[0], pair[1]


def _best_time(action: Callable[[], object], repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        start = time.perf_counter()
        action()
        best = min(best, time.perf_counter() - start)
    return best


def bench_throughput(
    samples: int = DEFAULT_SAMPLES,
    *,
    repeats: int = 3,
    reference_repeats: int = 1,
    method: str = "gtls",
    progress: bool = False,
) -> dict[str, Any]:
    """Samples per second of core (double, float), NumPy reference and bandwidth baseline.

    Each figure is the best of ``repeats`` runs (the reference, much slower, of
    ``reference_repeats``) to suppress interference from other processes on the machine.
    """
    from tqdm import tqdm

    if samples < 3:
        raise ValueError(f"bench: need at least 3 samples, got {samples}")
    try:
        from dualprobe import _core  # type: ignore[attr-defined]
    except ImportError as exc:
        raise BenchUnavailable(
            f"the C++ core dualprobe._core is not built ({exc}); run `pip install -e .`"
        ) from None
    try:
        from dualprobe.reference import difference
    except ImportError as exc:
        raise BenchUnavailable(f"the NumPy reference is not available ({exc})") from None

    t1, t2 = make_pair(samples)
    t1f, t2f = t1.astype(np.float32), t2.astype(np.float32)
    ts = BENCH_TS
    sigma = BENCH_NOISE

    def core_double() -> dict[str, Any]:
        estimator = _core.DifferenceEstimator(ts, method=method, sigma1=sigma, sigma2=sigma)
        estimator.update_batch(t1, t2)
        return dict(estimator.solve())

    def core_float() -> dict[str, Any]:
        estimator = _core.DifferenceEstimatorF(ts, method=method, sigma1=sigma, sigma2=sigma)
        estimator.update_batch(t1f, t2f)
        return dict(estimator.solve())

    def reference() -> object:
        return difference.estimate(t1, t2, ts, method=method, sigma1=sigma, sigma2=sigma)

    def bandwidth() -> float:
        return float(np.add.reduce(t1)) + float(np.add.reduce(t2))

    stages: list[tuple[str, Callable[[], object], int]] = [
        ("bandwidth", bandwidth, repeats),
        ("core", core_double, repeats),
        ("core_float", core_float, repeats),
        ("reference", reference, reference_repeats),
    ]
    seconds: dict[str, float] = {}
    for name, action, count in tqdm(stages, desc="bench", disable=not progress, leave=False):
        seconds[name] = _best_time(action, max(1, count))

    rates = {name: samples / max(value, 1e-12) for name, value in seconds.items()}
    solution = core_double()
    solution_float = core_float()
    return {
        "samples": samples,
        "method": method,
        "core_samples_per_s": rates["core"],
        "core_float_samples_per_s": rates["core_float"],
        "reference_samples_per_s": rates["reference"],
        "bandwidth_samples_per_s": rates["bandwidth"],
        "core_vs_reference": rates["core"] / rates["reference"],
        "core_float_vs_reference": rates["core_float"] / rates["reference"],
        "core_vs_bandwidth": rates["core"] / rates["bandwidth"],
        "core_float_vs_bandwidth": rates["core_float"] / rates["bandwidth"],
        "seconds": seconds,
        "true_time_constants": list(BENCH_TAUS),
        "core_time_constants": [solution.get("tau1"), solution.get("tau2")],
        "core_float_time_constants": [solution_float.get("tau1"), solution_float.get("tau2")],
        "platform": {
            "python": sys.version.split()[0],
            "numpy": np.__version__,
            "machine": platform.machine(),
            "processor": platform.processor() or platform.machine(),
        },
    }
