"""`dualprobe bench`: throughput of the C++ streaming estimator against NumPy and memory bandwidth.

All throughputs are measured in one run on the same arrays: the C++ streaming update + solve
(double and float), the NumPy reference estimator, and a memory-bandwidth baseline that only
reads both arrays once (``np.add.reduce``), which bounds what any one-pass estimator can do.
"""

from __future__ import annotations

import math
import os
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import scipy.signal

from dualprobe import simulate as sim
from dualprobe.estimation import characterise_pair
from dualprobe.reconstruction import reconstruct_pair
from dualprobe.report.plots import pyplot, save

__all__ = [
    "DEFAULT_SAMPLES",
    "BenchUnavailable",
    "bench_noise",
    "bench_throughput",
    "make_pair",
    "noise_figure",
    "noise_study_report",
    "noise_table",
]

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


# --------------------------------------------------------------------------------------------
# Issue 7: the paper's plain method against the noise-robust defaults
# --------------------------------------------------------------------------------------------

PLAIN = "plain"  # difference-equation GTLS (paper, Hung et al.) + weighted exact inverse
ROBUST = "robust"  # SVF with automatic filter (method auto) + smoother (CLI defaults)


def bench_noise(
    *,
    noise_levels: tuple[float, ...] = (0.01, 0.03, 0.1, 0.3),
    sample_rates: tuple[float, ...] = (1.0, 10.0, 100.0),
    time_constants: tuple[float, float] = (12.48, 28.95),
    duration: float = 600.0,
    amplitude: float = 5.0,
    seeds: int = 2,
    rng_seed: int = 7,
    progress: bool = False,
) -> list[dict[str, Any]]:
    """Time-constant error and reconstruction RMSE of the plain and the robust method.

    For every sample rate (Hz) and white-noise level (K, both sensors), ``seeds`` recordings of a
    unit-gain first-order pair on a multistep gas profile (levels within +/- ``amplitude`` K,
    holds ~ duration/12, steps off the sample grid) are characterised without being told the
    noise level, both ways: ``plain`` = the paper's difference-equation GTLS and weighted exact
    inverse; ``robust`` = `method="auto"` and the smoother (the `characterise` defaults).

    One row per (rate, noise, method) with the median over seeds of the larger relative
    time-constant error of the two sensors (`tau_error`), its maximum (`tau_error_max`), the
    median reconstruction RMSE against the true gas temperature over samples not right beside
    a jump (`rmse`, K), the fast sensor's own RMSE (`sensor_rmse`) and the number of failed
    estimates (`failures`, counted as error 1 and RMSE NaN).
    """
    from tqdm import tqdm

    sensors = (sim.SensorModel((time_constants[0],)), sim.SensorModel((time_constants[1],)))
    truth = np.asarray(time_constants, dtype=float)
    settings = {PLAIN: ("gtls", "inverse"), ROBUST: ("auto", "smoother")}
    grid = [(rate, noise) for rate in sample_rates for noise in noise_levels]
    rows: list[dict[str, Any]] = []
    for rate, noise in tqdm(grid, desc="noise study", disable=not progress, leave=False):
        ts = 1.0 / float(rate)
        errors: dict[str, list[float]] = {name: [] for name in settings}
        rmses: dict[str, list[float]] = {name: [] for name in settings}
        failures = dict.fromkeys(settings, 0)
        sensor_rmse: list[float] = []
        for seed in range(seeds):
            rng = np.random.default_rng([rng_seed, seed])
            profile = sim.multistep_profile(
                duration, mean=20.0, amplitude=amplitude, mean_hold=duration / 12.0, rng=rng
            )
            rec = sim.simulate_pair(
                profile, *sensors, ts=ts, duration=duration, noise_std=float(noise), rng=rng
            )
            keep = ~rec.jump_mask(margin=1)
            sensor_rmse.append(float(np.sqrt(np.mean((rec.t1[keep] - rec.tg[keep]) ** 2))))
            for name, (method, mode) in settings.items():
                est = characterise_pair(rec.t1, rec.t2, ts, method=method)
                taus = np.array([est.time_constants[0][0], est.time_constants[1][0]])
                if est.status != "ok" or not np.all(np.isfinite(taus) & (taus > 0)):
                    failures[name] += 1
                    errors[name].append(1.0)
                    rmses[name].append(math.nan)
                    continue
                errors[name].append(float(np.max(np.abs(taus / truth - 1.0))))
                gas = reconstruct_pair(
                    rec.t1,
                    rec.t2,
                    ts,
                    est.time_constants[0],
                    est.time_constants[1],
                    mode=mode,
                    noise_std=est.noise_std,
                )
                valid = keep & np.isfinite(gas)
                rmses[name].append(float(np.sqrt(np.mean((gas[valid] - rec.tg[valid]) ** 2))))
        for name in settings:
            finite = [value for value in rmses[name] if math.isfinite(value)]
            rows.append(
                {
                    "sample_rate": float(rate),
                    "noise_std": float(noise),
                    "method": name,
                    "estimator": settings[name][0],
                    "reconstruction": settings[name][1],
                    "runs": seeds,
                    "failures": failures[name],
                    "tau_error": float(np.median(errors[name])),
                    "tau_error_max": float(np.max(errors[name])),
                    "rmse": float(np.median(finite)) if finite else math.nan,
                    "sensor_rmse": float(np.median(sensor_rmse)),
                }
            )
    return rows


def _tau_cell(row: dict[str, Any]) -> str:
    if row["failures"] == row["runs"]:
        return "failed"
    text = f"{100 * row['tau_error']:.2f} %"
    return text + (f" ({row['failures']}/{row['runs']} failed)" if row["failures"] else "")


def _rmse_cell(row: dict[str, Any]) -> str:
    return f"{row['rmse']:.3g}" if math.isfinite(row["rmse"]) else "failed"


def noise_table(rows: list[dict[str, Any]]) -> str:
    """Markdown table: one line per (rate, noise), plain and robust side by side."""
    lines = [
        "| rate [Hz] | noise [K] | tau error plain | tau error robust | RMSE plain [K] "
        "| RMSE robust [K] | fast sensor RMSE [K] |",
        "|---|---|---|---|---|---|---|",
    ]
    pairs: dict[tuple[float, float], dict[str, dict[str, Any]]] = {}
    for row in rows:
        pairs.setdefault((row["sample_rate"], row["noise_std"]), {})[row["method"]] = row
    for (rate, noise), by_method in pairs.items():
        plain, robust = by_method[PLAIN], by_method[ROBUST]
        lines.append(
            f"| {rate:g} | {noise:g} | {_tau_cell(plain)} | {_tau_cell(robust)} "
            f"| {_rmse_cell(plain)} | {_rmse_cell(robust)} | {robust['sensor_rmse']:.3g} |"
        )
    return "\n".join(lines)


def noise_figure(rows: list[dict[str, Any]], path: str | os.PathLike[str]) -> None:
    """Time-constant error and reconstruction RMSE against noise, one line per rate and method."""
    plt = pyplot()
    rates = sorted({row["sample_rate"] for row in rows})
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(11, 4.5), constrained_layout=True)
    for index, rate in enumerate(rates):
        colour = colours[index % len(colours)]
        for name, style in ((PLAIN, "--"), (ROBUST, "-")):
            series = sorted(
                (row for row in rows if row["sample_rate"] == rate and row["method"] == name),
                key=lambda row: row["noise_std"],
            )
            noise = [row["noise_std"] for row in series]
            label = f"{name}, {rate:g} Hz"
            left.plot(
                noise,
                [100 * row["tau_error"] for row in series],
                style,
                color=colour,
                marker="o",
                label=label,
            )
            right.plot(
                noise, [row["rmse"] for row in series], style, color=colour, marker="o", label=label
            )
        sensor = sorted(
            (row for row in rows if row["sample_rate"] == rate and row["method"] == ROBUST),
            key=lambda row: row["noise_std"],
        )
        right.plot(
            [row["noise_std"] for row in sensor],
            [row["sensor_rmse"] for row in sensor],
            ":",
            color=colour,
            label=f"fast sensor, {rate:g} Hz",
        )
    for axis in (left, right):
        axis.set_xscale("log")
        axis.set_yscale("log")
        axis.set_xlabel("sensor noise std [K]")
        axis.grid(alpha=0.3, which="both")
    left.set_ylabel("larger time-constant error [%]")
    left.set_title("time constants (median over seeds; failed = 100 %)")
    right.set_ylabel("reconstruction RMSE vs true gas [K]")
    right.set_title("gas temperature reconstruction")
    left.legend(fontsize="small")
    right.legend(fontsize="x-small", ncol=2)
    save(fig, Path(path), tight=False)  # constrained layout


def noise_study_report(
    out: Path, seeds: int, *, progress: bool
) -> tuple[list[dict[str, Any]], str]:
    """:func:`bench_noise` written as ``noise.md`` (with :func:`noise_table`) and ``noise.png``
    (:func:`noise_figure`) into ``out``; returns the rows and the table."""
    rows = bench_noise(seeds=seeds, progress=progress)
    table = noise_table(rows)
    noise_figure(rows, out / "noise.png")
    (out / "noise.md").write_text(
        "# Plain vs noise-robust method\n\n"
        "Unit-gain first-order Pt-100 pair (12.48 s, 28.95 s), multistep gas within +/-5 K, "
        f"600 s records, {seeds} seed(s) per point, noise level not given to either method. "
        "plain: difference-equation GTLS + weighted exact inverse (the paper); robust: "
        "`method=auto` (state-variable filter) + smoother (the `characterise` defaults). "
        "tau error: the larger relative error of the two sensors (median over seeds); RMSE "
        "against the true gas temperature, samples right beside a jump excluded.\n\n"
        f"{table}\n\n![time-constant error and RMSE against noise](noise.png)\n"
    )
    return rows, table
