"""`dualprobe characterise` on real-world recordings: the same pair as CSV, Parquet and MDF4, time
in ms, clock jitter, gaps and malformed files of each format."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.cli import main
from dualprobe.io import load_recording
from recordings import write_csv, write_mdf, write_parquet

TAUS = (3.0, 9.0)


def gas(duration: float, rng: np.random.Generator) -> sim.GasProfile:
    """Gas steps of 20-60 K every 25-45 s, at instants off any sample grid."""
    times = np.cumsum(rng.uniform(25.0, 45.0, size=int(duration / 25.0)))
    times = times[times < duration - 10.0] + rng.uniform(0.0, 1.0)
    levels = 400.0 + np.cumsum(rng.choice([-1.0, 1.0], times.size + 1) * rng.uniform(20, 60,
                                                                                   times.size + 1))
    return sim.multistep_profile(duration, levels=list(levels), step_times=times)


def pair_at(profile: sim.GasProfile, t: np.ndarray, noise: np.ndarray) -> dict[str, np.ndarray]:
    """Both sensors sampled at the instants t (exact, off-grid steps included), plus noise."""
    return {
        "T_m1": sim.simulate_sensor(profile, sim.SensorModel((TAUS[0],)), t) + noise[0],
        "T_m2": sim.simulate_sensor(profile, sim.SensorModel((TAUS[1],)), t) + noise[1],
    }


def characterise(capsys: pytest.CaptureFixture[str], path: Path, *extra: str) -> dict[str, Any]:
    target = path.with_suffix(".json")
    status = main(["characterise", str(path), "--json", str(target), *extra])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    document: dict[str, Any] = json.loads(target.read_text())
    document["printed"] = captured.out
    return document


def taus_of(document: dict[str, Any]) -> np.ndarray:
    return np.array([sensor["time_constants"][0] for sensor in document["sensors"]])


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    status = main(list(argv))
    err = capsys.readouterr().err
    assert len(err.splitlines()) <= 1 and "Traceback" not in err
    return status, err


@pytest.fixture(scope="module")
def field_pair() -> dict[str, np.ndarray]:
    """Sensors at 10 Hz for 400 s, and a flow signal at 50 Hz."""
    rng = np.random.default_rng(15)
    profile = gas(400.0, rng)
    t10 = np.arange(4000) * 0.1
    t50 = np.arange(20000) * 0.02
    pair = pair_at(profile, t10, 0.05 * rng.standard_normal((2, t10.size)))
    return {"t": t10, **pair, "t50": t50, "flow50": 20.0 + 10.0 * np.sin(0.05 * t50)}


def test_same_recording_as_csv_parquet_and_mdf4(
    field_pair: dict[str, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = field_pair
    flow10 = np.interp(data["t"], data["t50"], data["flow50"])
    table = {"t": data["t"], "T_m1": data["T_m1"], "T_m2": data["T_m2"], "flow": flow10}
    csv_path = write_csv(tmp_path / "rec.csv", table, fmt="%.12g")
    parquet_path = write_parquet(tmp_path / "rec.parquet", table)
    mdf_path = write_mdf(
        tmp_path / "rec.mf4",
        [
            (data["t"], {"T_m1": data["T_m1"], "T_m2": data["T_m2"]}),
            (data["t50"], {"flow": data["flow50"]}),
        ],
        units={"T_m1": "degC", "T_m2": "degC", "flow": "m/s"},
    )
    results = [taus_of(characterise(capsys, path)) for path in (csv_path, parquet_path, mdf_path)]
    for taus in results:
        np.testing.assert_allclose(taus, results[0], rtol=0.01)
        np.testing.assert_allclose(taus, TAUS, rtol=0.05)
    # The flow from its own 50 Hz group, interpolated onto the sensors' 10 Hz raster.
    recording = load_recording(mdf_path, ["T_m1", "T_m2", "flow"])
    assert "interpolated linearly" in recording.notes[0]
    np.testing.assert_allclose(recording.columns["flow"], flow10, atol=1e-9)


def test_time_in_ms_gives_the_answer_in_seconds(
    field_pair: dict[str, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = field_pair
    signals = {"T_m1": data["T_m1"], "T_m2": data["T_m2"]}
    seconds = characterise(capsys, write_csv(tmp_path / "s.csv", {"t": data["t"], **signals}))
    ms = write_csv(tmp_path / "ms.csv", {"t": data["t"] * 1e3, **signals})
    option = characterise(capsys, ms, "--time-unit", "ms")
    headed = write_csv(tmp_path / "h.csv", {"Time (ms)": data["t"] * 1e3, **signals})
    header = characterise(capsys, headed, "--time", "Time")
    assert "note: time column 'Time (ms)': unit ms read from the header" in header["printed"]
    for document in (option, header):
        assert document["sample_interval"] == pytest.approx(0.1, rel=1e-12)
        np.testing.assert_allclose(taus_of(document), taus_of(seconds), rtol=1e-6)
    status, err = run_cli(capsys, "characterise", str(headed), "--time", "Time",
                          "--time-unit", "s")
    assert status == 2 and "conflicts with the unit in the header" in err


def test_clock_jitter_within_the_estimates_uncertainty(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A logger at 15 ms rows with +/-0.5 ms clock jitter (the time column records the actual
    instants) against the same logger without jitter, same noise."""
    rng = np.random.default_rng(21)
    profile = gas(240.0, rng)
    ts = 0.015
    rows = int(240.0 / ts)
    nominal = np.arange(rows) * ts
    jittered = nominal + rng.uniform(-0.5e-3, 0.5e-3, rows)
    jittered[0] = 0.0
    estimates = []
    for seed in range(3):
        noise = 0.05 * np.random.default_rng(seed).standard_normal((2, rows))
        path = write_csv(tmp_path / f"clean{seed}.csv", {"t": nominal,
                                                         **pair_at(profile, nominal, noise)})
        estimates.append(taus_of(characterise(capsys, path)))
        if seed == 0:
            path = write_csv(tmp_path / "jitter.csv", {"t": jittered,
                                                       **pair_at(profile, jittered, noise)})
            document = characterise(capsys, path)
    assert "note: clock jitter: intervals scatter by up to" in document["printed"]
    assert document["sample_interval"] == pytest.approx(ts, rel=1e-4)
    # The estimate's uncertainty: its std when reported, else its scatter over noise draws.
    spread = np.std(estimates, axis=0, ddof=1)
    reported = [s.get("time_constants_std", [np.nan])[0] for s in document["sensors"]]
    sigma = np.where(np.isfinite(np.asarray(reported, dtype=float)), reported, spread)
    print("jitter vs clean:", taus_of(document) - estimates[0], "sigma", sigma)
    assert np.all(np.abs(taus_of(document) - estimates[0]) < 2.0 * sigma)


def test_gap_is_refused_naming_it(
    field_pair: dict[str, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    keep = np.ones(field_pair["t"].size, dtype=bool)
    keep[1234:1242] = False
    table = {name: field_pair[name][keep] for name in ("t", "T_m1", "T_m2")}
    path = write_parquet(tmp_path / "gap.parquet", table)
    status, err = run_cli(capsys, "characterise", str(path))
    assert status == 2
    assert "row 1235 (t = 123.3 s): gap of 0.9 s (9 intervals); characterise needs a record " \
        "without gaps" in err


def test_malformed_files_of_each_format_exit_2(
    field_pair: dict[str, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = field_pair
    mdf = write_mdf(tmp_path / "full.mf4", [(data["t"], {"T_m1": data["T_m1"],
                                                          "T_m2": data["T_m2"]})])
    raw = mdf.read_bytes()
    (tmp_path / "cut.mf4").write_bytes(raw[: len(raw) * 2 // 3])
    status, err = run_cli(capsys, "characterise", str(tmp_path / "cut.mf4"))
    assert status == 2 and "not a readable MDF4 file" in err
    parquet = write_parquet(tmp_path / "p.parquet", {"t": data["t"], "T_m1": data["T_m1"]})
    status, err = run_cli(capsys, "characterise", str(parquet))
    assert status == 2 and "missing column 'T_m2'; available: t, T_m1" in err
    units = tmp_path / "units.csv"
    units.write_text("t,T_m1,T_m2\ns,degC,degC\n" + "".join(
        f"{k * 0.1:.1f},{20 + k % 7},{20 + k % 5}\n" for k in range(100)))
    status, err = run_cli(capsys, "characterise", str(units))
    assert status == 2 and "line 2: a units row under the header (s, degC, degC)" in err
    for path in (tmp_path / "cut.mf4", parquet, units):
        status, _ = run_cli(capsys, "identify", str(path), "--output", "T_m2", "--step")
        assert status == 2
