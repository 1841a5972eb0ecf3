"""`dualprobe characterise` through the command line: bad input and accuracy with defaults."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dualprobe import simulate
from dualprobe.cli import main
from dualprobe.io import load_columns, write_columns
from dualprobe.simulate import GasProfile

REPO = Path(__file__).resolve().parents[2]


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    status = main(list(argv))
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def assert_one_error_line(err: str) -> str:
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ")
    assert "Traceback" not in err
    return lines[0]


def write_pair(path: Path, rows: int = 200, ts: float = 0.1) -> Path:
    """A small first-order pair (1 s and 3 s) on a ramp-and-hold gas profile."""
    t = np.arange(rows) * ts
    gas = 20.0 + np.minimum(t, 5.0) * 4.0
    t1, t2 = np.empty(rows), np.empty(rows)
    t1[0] = t2[0] = gas[0]
    a1, a2 = np.exp(-ts / 1.0), np.exp(-ts / 3.0)
    for k in range(1, rows):
        t1[k] = a1 * t1[k - 1] + (1 - a1) * gas[k - 1]
        t2[k] = a2 * t2[k - 1] + (1 - a2) * gas[k - 1]
    write_columns(path, {"t": t, "T_m1": t1, "T_m2": t2, "T_g": gas})
    return path


def edit_line(path: Path, index: int, text: str) -> Path:
    lines = path.read_text().splitlines()
    lines[index] = text
    path.write_text("\n".join(lines) + "\n")
    return path


BAD_INPUTS = {
    "missing file": (lambda d: d / "absent.csv", "no such file"),
    "directory": (lambda d: d, "directory"),
    "empty file": (lambda d: _write(d / "e.csv", ""), "empty"),
    "header only": (lambda d: _write(d / "h.csv", "t,T_m1,T_m2\n"), "header only"),
    "missing column": (
        lambda d: _write(d / "m.csv", "t,T_m1,T_x\n" + "".join(f"{k},1,2\n" for k in range(20))),
        "'T_m2'",
    ),
    "non-numeric": (lambda d: edit_line(write_pair(d / "n.csv"), 7, "0.6,warm,20,21"), "line 8"),
    "nan": (lambda d: edit_line(write_pair(d / "f.csv"), 9, "0.8,20,nan,21"), "non-finite"),
    "empty cell": (lambda d: edit_line(write_pair(d / "c.csv"), 9, "0.8,20,,21"), "empty cell"),
    "inf": (lambda d: edit_line(write_pair(d / "i.csv"), 9, "0.8,inf,20,21"), "non-finite"),
    "time decreasing": (
        lambda d: edit_line(write_pair(d / "d.csv"), 4, "0.1,20,20,21"),
        "not strictly increasing",
    ),
    "time irregular": (
        lambda d: edit_line(write_pair(d / "r.csv"), 4, "0.35,20,20,21"),
        "irregular",
    ),
    "too few rows": (lambda d: write_pair(d / "s.csv", rows=4), "too few"),
    "binary junk": (
        lambda d: _write_bytes(d / "b.csv", b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR" * 4),
        "binary",
    ),
    "not utf-8": (lambda d: _write_bytes(d / "u.csv", b"t,T_m1\n\xff\xfe\xfa,1\n"), "UTF-8"),
}


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def _write_bytes(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_bad_input_exits_2_with_one_line(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    make, fragment = BAD_INPUTS[case]
    path = make(tmp_path)
    status, out, err = run_cli(capsys, "characterise", str(path))
    line = assert_one_error_line(err)
    assert status == 2
    assert fragment in line
    assert out == ""


def test_constant_signal_exits_3(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = _write(
        tmp_path / "c.csv", "t,T_m1,T_m2\n" + "".join(f"{k},300,301\n" for k in range(50))
    )
    status, _, err = run_cli(capsys, "characterise", str(path))
    line = assert_one_error_line(err)
    assert status == 3
    assert "no excitation" in line and "'T_m1'" in line


@pytest.mark.parametrize(
    ("argv", "fragment"),
    [
        (["characterise"], "DATA"),
        (["characterise", "x.csv", "--method", "magic"], "--method"),
        (["characterise", "x.csv", "--order", "3"], "--order"),
        (["characterise", "x.csv", "--noise-std", "-1"], "--noise-std"),
        (["characterise", "x.csv", "--noise-std", "a,b"], "--noise-std"),
        (["characterise", "x.csv", "--bogus"], "--bogus"),
        (["characterise", "x.csv", "--time", ""], "--sample-interval"),
        (["no-such-command"], "no-such-command"),
        ([], "no command"),
    ],
)
def test_bad_usage_exits_2_with_one_line(
    argv: list[str], fragment: str, capsys: pytest.CaptureFixture[str]
) -> None:
    status, _, err = run_cli(capsys, *argv)
    line = assert_one_error_line(err)
    assert status == 2
    assert fragment in line


def test_help_exits_0(capsys: pytest.CaptureFixture[str]) -> None:
    status, out, _ = run_cli(capsys, "--help")
    assert status == 0 and "characterise" in out and "demo" in out and "bench" in out


def test_same_column_twice(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = write_pair(tmp_path / "p.csv")
    status, _, err = run_cli(capsys, "characterise", str(path), "--sensor2", "T_m1")
    assert status == 2 and "same column" in assert_one_error_line(err)


def test_unwritable_output_is_refused_before_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_pair(tmp_path / "p.csv")
    target = str(tmp_path / "no" / "such" / "dir" / "out.csv")
    status, _, err = run_cli(capsys, "characterise", str(path), "--output", target)
    assert status == 2 and "does not exist" in assert_one_error_line(err)


def test_real_process_has_no_traceback(tmp_path: Path) -> None:
    env = dict(os.environ, PYTHONPATH=str(REPO / "python"))
    result = subprocess.run(
        [sys.executable, "-m", "dualprobe", "characterise", str(tmp_path / "absent.csv")],
        capture_output=True,
        text=True,
        env=env,
        check=False,
        timeout=120,
    )
    assert result.returncode == 2
    assert result.stderr.startswith("error: ") and result.stderr.count("\n") == 1


# --- accuracy with defaults (needs dualprobe.simulate, .estimation, .reconstruction) ---------


def characterise_csv(
    capsys: pytest.CaptureFixture[str], path: Path, tmp_path: Path, *extra: str
) -> tuple[dict[str, object], np.ndarray]:
    json_path, out_path = tmp_path / "result.json", tmp_path / "tg.csv"
    status, out, err = run_cli(
        capsys,
        "characterise",
        str(path),
        "--json",
        str(json_path),
        "--output",
        str(out_path),
        *extra,
    )
    assert status == 0, err
    assert "T_m1" in out
    document = json.loads(json_path.read_text())
    t_out, columns, _ = load_columns(out_path, ["T_g_hat"], min_rows=1)
    t_in, _, _ = load_columns(path, ["T_m1"], min_rows=1)
    assert t_out is not None and t_in is not None
    np.testing.assert_array_equal(t_out, t_in)  # one output row per input row, same stamps
    return document, columns["T_g_hat"]


def gas_steps(duration: float, rng: np.random.Generator) -> GasProfile:
    """Gas steps of 100-300 K between 300 K and 1000 K, at times off any sample grid."""
    times = np.cumsum(rng.uniform(80.0, 140.0, size=int(duration / 80.0) + 1))
    times = times[times < duration - 40.0] + rng.uniform(0.0, 1.0)
    levels = [rng.uniform(400.0, 700.0)]
    for _ in times:
        size = rng.uniform(100.0, 300.0)
        up = levels[-1] + size <= 1000.0 and (levels[-1] - size < 300.0 or rng.random() < 0.5)
        levels.append(levels[-1] + size if up else levels[-1] - size)
    return simulate.multistep_profile(duration, levels=levels, step_times=times)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("noise", "seed"), [((0.01, 0.01), 11), ((0.1, 0.1), 12), ((0.03, 0.08), 13)]
)
def test_pt100_pair_at_10_hz_with_defaults(
    noise: tuple[float, float],
    seed: int,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    rng = np.random.default_rng(seed)
    duration, taus = 900.0, (12.48, 28.95)
    rec = simulate.simulate_pair(
        gas_steps(duration, rng),
        simulate.SensorModel((taus[0],)),
        simulate.SensorModel((taus[1],)),
        ts=0.1,
        duration=duration,
        noise_std=noise,
        rng=rng,
    )
    path = tmp_path / "pt100.csv"
    rec.to_csv(path)
    document, gas_hat = characterise_csv(capsys, path, tmp_path, "--reference", "T_g")
    assert document["status"] == "ok"
    assert document["sample_interval"] == pytest.approx(0.1, rel=1e-9)  # from the time column
    sensors = document["sensors"]
    assert isinstance(sensors, list)
    for sensor, tau in zip(sensors, taus, strict=True):
        assert sensor["time_constants"][0] == pytest.approx(tau, rel=0.03)  # issue 2: 3 %
    # A usable reconstruction: issue 7 asks for at most 6 % of the fast sensor's own RMSE at
    # 0.1 K noise, samples right beside a gas jump excluded.
    keep = ~rec.jump_mask(margin=1) & np.isfinite(gas_hat)
    assert keep.mean() > 0.99  # NaN only at the very ends / beside jumps
    rmse_hat = np.sqrt(np.mean((gas_hat[keep] - rec.tg[keep]) ** 2))
    rmse_sensor = np.sqrt(np.mean((rec.t1[keep] - rec.tg[keep]) ** 2))
    assert rmse_hat < 0.06 * rmse_sensor
    reconstruction = document["reconstruction"]
    assert isinstance(reconstruction, dict) and reconstruction["rmse_vs_reference"] > 0


@pytest.mark.slow
def test_thermocouple_pair_at_1_khz_with_defaults(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    rng = np.random.default_rng(21)
    duration, taus = 10.0, (0.020, 0.080)  # 10^4 samples, 50 band periods
    profile = simulate.fluctuating_profile(duration, mean=550.0, std=10.0, bandwidth=5.0, rng=rng)
    rec = simulate.simulate_pair(
        profile,
        simulate.SensorModel((taus[0],)),
        simulate.SensorModel((taus[1],)),
        ts=1e-3,
        duration=duration,
        noise_std=0.05,
        rng=rng,
    )
    path = tmp_path / "tc.csv"
    rec.to_csv(path)
    document, gas_hat = characterise_csv(capsys, path, tmp_path)
    assert document["status"] == "ok"
    sensors = document["sensors"]
    assert isinstance(sensors, list)
    for sensor, tau in zip(sensors, taus, strict=True):
        assert sensor["time_constants"][0] == pytest.approx(tau, rel=0.02)  # issue 2: 2 %
    # Usable: far closer to the gas than the fast sensor, which lags a 5 Hz band by up to 32 deg
    # (35 % is issue 7's bound for small-signal data).
    keep = np.isfinite(gas_hat)
    rmse_hat = np.sqrt(np.mean((gas_hat[keep] - rec.tg[keep]) ** 2))
    rmse_sensor = np.sqrt(np.mean((rec.t1[keep] - rec.tg[keep]) ** 2))
    assert rmse_hat < 0.35 * rmse_sensor


@pytest.fixture(scope="module")
def pt100_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rng = np.random.default_rng(31)
    rec = simulate.simulate_pair(
        gas_steps(600.0, rng),
        simulate.SensorModel((12.48,)),
        simulate.SensorModel((28.95,)),
        ts=0.1,
        duration=600.0,
        noise_std=0.05,
        rng=rng,
    )
    path = tmp_path_factory.mktemp("pt100") / "pair.csv"
    rec.to_csv(path)
    return path


def test_json_document_and_output_rows(
    pt100_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    document, gas_hat = characterise_csv(capsys, pt100_csv, tmp_path, "--reference", "T_g")
    assert set(document) == {
        "method",
        "order",
        "sample_interval",
        "status",
        "beta",
        "sensors",
        "noise_std",
        "identifiability",
        "reconstruction",
        "static_model",  # issue 16: gain ratio and offset with their uncertainties
        "uncertainty",  # issue 16: how the standard uncertainties were computed
        "model_check",  # issue 11: does the model explain both signals
        "notes",  # the loader's and the characterisation's notes (units, held readings)
    }
    assert document["order"] == 1 and document["method"] in ("svf", "auto")
    assert document["notes"] == []  # a regular CSV of fresh readings: nothing to note
    sensors = document["sensors"]
    assert isinstance(sensors, list)
    assert [s["column"] for s in sensors] == ["T_m1", "T_m2"]
    assert all(set(s) == {"column", "time_constants", "time_constants_std", "identifiable",
                          "identifiability_reasons"} for s in sensors)
    for sensor in sensors:
        assert len(sensor["time_constants_std"]) == len(sensor["time_constants"])
        assert all(0.0 < s < 0.05 * t for s, t in zip(sensor["time_constants_std"],
                                                       sensor["time_constants"], strict=True))
    assert document["model_check"]["adequate"] is True
    reconstruction = document["reconstruction"]
    assert isinstance(reconstruction, dict)
    _, columns, _ = load_columns(pt100_csv, ["T_g"])
    valid = np.isfinite(gas_hat)
    rmse = np.sqrt(np.mean((gas_hat[valid] - columns["T_g"][valid]) ** 2))
    # The JSON's RMSE is over the same finite samples; the CSV round trip is exact (repr).
    assert reconstruction["rmse_vs_reference"] == pytest.approx(rmse, rel=1e-12)


def test_file_without_time_column(
    pt100_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, columns, _ = load_columns(pt100_csv, ["T_m1", "T_m2"])
    bare = tmp_path / "bare.csv"
    write_columns(bare, {"A": columns["T_m1"], "B": columns["T_m2"]})
    with_time = tmp_path / "with.json"
    without_time = tmp_path / "without.json"
    assert main(["characterise", str(pt100_csv), "--json", str(with_time)]) == 0
    argv = ["characterise", str(bare), "--time", "", "--sample-interval", "0.1"]
    argv += ["--sensor1", "A", "--sensor2", "B", "--json", str(without_time)]
    assert main(argv) == 0
    capsys.readouterr()
    first, second = json.loads(with_time.read_text()), json.loads(without_time.read_text())
    assert [s["column"] for s in second["sensors"]] == ["A", "B"]
    for a, b in zip(first["sensors"], second["sensors"], strict=True):
        # Same data; Ts from the time column differs from 0.1 only by float rounding.
        assert a["time_constants"] == pytest.approx(b["time_constants"], rel=1e-6)


def test_swapped_columns_report_per_column(
    pt100_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "swapped.json"
    argv = ["characterise", str(pt100_csv), "--sensor1", "T_m2", "--sensor2", "T_m1"]
    assert main([*argv, "--json", str(target)]) == 0
    capsys.readouterr()
    sensors = json.loads(target.read_text())["sensors"]
    assert sensors[0]["column"] == "T_m2"
    # Physics does not depend on which column is called sensor 1 (3 %: issue 2's accuracy).
    assert sensors[0]["time_constants"][0] == pytest.approx(28.95, rel=0.03)
    assert sensors[1]["time_constants"][0] == pytest.approx(12.48, rel=0.03)


def test_hysteresis_adds_heating_and_cooling(
    pt100_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    target = tmp_path / "h.json"
    assert main(["characterise", str(pt100_csv), "--hysteresis", "--json", str(target)]) == 0
    capsys.readouterr()
    for sensor, tau in zip(json.loads(target.read_text())["sensors"], (12.48, 28.95), strict=True):
        # A non-hysteretic sensor: heating and cooling agree with the truth (5 %: each half of
        # the record carries about half the information).
        assert sensor["time_constants_heat"][0] == pytest.approx(tau, rel=0.05)
        assert sensor["time_constants_cool"][0] == pytest.approx(tau, rel=0.05)


def test_noise_only_exits_3(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(4)
    t = np.arange(3000) * 0.1
    path = tmp_path / "noise.csv"
    noise = {"T_m1": rng.standard_normal(3000), "T_m2": rng.standard_normal(3000)}
    write_columns(path, {"t": t, **{k: 300.0 + 0.05 * v for k, v in noise.items()}})
    status, out, err = run_cli(capsys, "characterise", str(path))
    line = assert_one_error_line(err)
    assert status == 3 and "estimation failed" in line and out == ""


def test_a_misfit_rounded_below_zero_is_printed_as_zero() -> None:
    """The estimation's misfit is a generalised eigenvalue: on a noise-free record it rounds
    to -9e-9, which the summary printed as a negative misfit."""
    from dualprobe.workflows.checks import ModelCheck

    (line,) = ModelCheck(True, -8.67e-9, 0.0, (1.0, 1.0)).summary_lines()
    assert "(misfit 0 x the noise, residuals 1, 1 x each sensor's noise)" in line
    assert ModelCheck(True, -8.67e-9, 0.0, None).to_json_dict()["estimation_misfit"] < 0.0


def test_a_sensor_that_moves_against_the_other_exits_3(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An inverted channel (T_m2 logged as 1000 - T): the cross-relation is blind to the sign
    of the gain, so both time constants came out right with "ok" (and no reconstruction, or
    a message about `relative_static`). Now one line that says which column and why."""
    rng = np.random.default_rng(8)
    rows, ts = 3000, 0.1
    t = np.arange(rows) * ts
    gas = 500.0 + 50.0 * np.sign(np.sin(2 * np.pi * t / 60.0)) + 5.0 * np.sin(t / 3.0)
    sensors = []
    for tau in (3.0, 9.0):
        a, x = np.exp(-ts / tau), np.empty(rows)
        x[0] = gas[0]
        for k in range(1, rows):
            x[k] = a * x[k - 1] + (1.0 - a) * gas[k]
        sensors.append(x + rng.normal(0.0, 0.05, rows))
    path = tmp_path / "inverted.csv"
    write_columns(path, {"t": t, "T_m1": sensors[0], "T_m2": 1000.0 - sensors[1]})
    for extra in ((), ("--output", str(tmp_path / "out.csv"))):
        status, _, err = run_cli(capsys, "characterise", str(path), *extra)
        assert status == 3
        line = assert_one_error_line(err)
        assert "T_m2 moves against T_m1 (gain -1" in line and "wrong sign" in line


def test_a_gap_names_the_window_that_reads_past_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A record with a gap is refused, naming the longest segment as a --window to give; with
    it, the time constants come back (1 s and 3 s within 2 %: 0.01 K noise on 20 K steps) and a
    note names the window. The same option on identify and diagnose; a malformed one is a
    usage error."""
    rng = np.random.default_rng(40)
    ts, rows = 0.1, 1200
    t = np.arange(rows) * ts
    gas = 300.0 + 20.0 * np.sign(np.sin(2.0 * np.pi * t / 24.0))
    pair = []
    for tau in (1.0, 3.0):
        a, x = np.exp(-ts / tau), np.full(rows, 280.0)
        for k in range(1, rows):
            x[k] = a * x[k - 1] + (1.0 - a) * gas[k - 1]
        pair.append(x + 0.01 * rng.standard_normal(rows))
    keep = np.ones(rows, dtype=bool)
    keep[300:330] = False  # a logger outage of 3 s
    path = tmp_path / "gap.csv"
    write_columns(path, {"t": t[keep], "T_m1": pair[0][keep], "T_m2": pair[1][keep],
                         "T_ref": gas[keep] + 0.01 * rng.standard_normal(int(keep.sum()))})
    status, out, err = run_cli(capsys, "characterise", str(path))
    line = assert_one_error_line(err)
    assert status == 2 and "--window 33:119.9 (the longest segment, 86.9 s)" in line
    json_path = tmp_path / "w.json"
    status, out, err = run_cli(capsys, "characterise", str(path), "--window", "33:119.9",
                               "--json", str(json_path))
    assert status == 0, err
    assert "note: window t = 33-119.9 s: line 302 to line 1171, 870 of 1170 rows" in out
    taus = [s["time_constants"][0] for s in json.loads(json_path.read_text())["sensors"]]
    assert taus == pytest.approx([1.0, 3.0], rel=0.02)
    status, out, err = run_cli(capsys, "identify", str(path), "--input", "T_ref", "--output",
                               "T_m2", "--window", "33:")
    assert status == 0 and "note: window t = 33-119.9 s" in out, err
    status, out, err = run_cli(capsys, "diagnose", str(path), "--input", "T_ref", "--output",
                               "T_m2", "--window", ":29.9")
    assert status == 0 and "note: window t = 0-29.9 s" in out, err
    for bad in ("33", "50:40", "a:9", ":nan"):
        status, out, err = run_cli(capsys, "characterise", str(path), "--window", bad)
        assert status == 2 and "--window" in assert_one_error_line(err)
