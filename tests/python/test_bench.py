"""`dualprobe bench`: runs end to end on a small N and reports the documented keys."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dualprobe.cli import main
from dualprobe.workflows.bench import (
    BENCH_TAUS,
    BENCH_TS,
    bench_noise,
    make_pair,
    noise_figure,
    noise_table,
)

THROUGHPUT_KEYS = (
    "core_samples_per_s",
    "core_float_samples_per_s",
    "reference_samples_per_s",
    "bandwidth_samples_per_s",
    "core_vs_reference",
    "core_vs_bandwidth",
    "core_float_vs_bandwidth",
)


def test_make_pair_follows_the_first_order_model() -> None:
    t1, t2 = make_pair(20_000, seed=3)
    assert t1.shape == t2.shape == (20_000,)
    # Invert eq. 8 with the true tau on the noisy data: the gas it implies must be piecewise
    # constant, i.e. mostly within noise * (1 + a) / (1 - a) of its own median level per hold.
    a = math.exp(-BENCH_TS / BENCH_TAUS[0])
    gas = (t1[1:] - a * t1[:-1]) / (1 - a)
    hold = int(0.5 / BENCH_TS)
    first = gas[5 : hold - 5]
    noise_gain = math.sqrt(1 + a**2) / (1 - a)  # std of the inverse per unit sensor noise
    assert np.std(first) < 1.2 * 0.05 * noise_gain  # 20 % margin on a 490-sample std estimate


def test_bench_cli_small(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "new" / "bench.json"  # the directory is created, as `make bench` needs
    status = main(["bench", "--samples", "20000", "--json", str(target)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    result = json.loads(target.read_text())
    for key in THROUGHPUT_KEYS:
        assert math.isfinite(result[key]) and result[key] > 0, key
    assert result["samples"] == 20_000
    # The throughput run also solves: with 20 000 samples of 1 kHz steps, GTLS recovers the
    # time constants well (loose 10 %: this checks the bench measures a working estimator).
    assert result["core_time_constants"] == pytest.approx(list(BENCH_TAUS), rel=0.1)
    assert "samples/s" in captured.out


def test_bench_rejects_bad_sample_count(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "--samples", "12"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1


@pytest.mark.slow
def test_noise_study_robust_beats_plain_at_10_hz(tmp_path: Path) -> None:

    # Issue 7's hard case: 10 Hz, 0.1 K noise, gas within +/-5 K.
    rows = bench_noise(noise_levels=(0.1,), sample_rates=(10.0,), duration=600.0, seeds=1)
    by_method = {row["method"]: row for row in rows}
    assert set(by_method) == {"plain", "robust"}
    plain, robust = by_method["plain"], by_method["robust"]
    assert robust["failures"] == 0
    assert robust["tau_error"] < 0.05  # issue 7: both time constants within 5 % by default
    # The exact inverse multiplies 0.1 K of noise by ~tau/Ts > 100: its RMSE is several K,
    # while the robust reconstruction must be at most 35 % of the fast sensor's (issue 7).
    assert robust["rmse"] < 0.35 * robust["sensor_rmse"]
    assert not plain["rmse"] <= robust["rmse"]  # NaN (plain failed) or larger
    table = noise_table(rows)
    assert table.count("\n") == 2 and "| 10 | 0.1 |" in table
    noise_figure(rows, tmp_path / "noise.png")
    assert (tmp_path / "noise.png").read_bytes()[:4] == b"\x89PNG"
