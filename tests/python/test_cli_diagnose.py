"""`dualprobe diagnose`: files in, JSON and report out, one error line and exit 2/3 on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dualprobe.cli import main
from dualprobe.diagnose import FIGURES, REPORT_NAME
from hidden_effects import make_case
from hidden_field import make_field_case, make_logger_case


def _write_csv(path: Path, columns: dict[str, np.ndarray], fmt: str = "%.5f") -> Path:
    names = list(columns)
    np.savetxt(
        path,
        np.column_stack([columns[n] for n in names]),
        delimiter=",",
        fmt=fmt,
        header=",".join(names),
        comments="",
    )
    return path


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    case = make_case(("dead_time",), 7, duration=900.0)
    path = tmp_path_factory.mktemp("diagnose") / "rec.csv"
    return _write_csv(path, {"t": case.t, "T_ref": case.reference, "T_m": case.measured})


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: ")
    return lines[0]


def test_diagnose_writes_json_and_report(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    json_path = tmp_path / "out.json"
    report_dir = tmp_path / "report"
    status = main(
        [
            "diagnose",
            str(recording),
            "--input",
            "T_ref",
            "--output",
            "T_m",
            "--json",
            str(json_path),
            "--report",
            str(report_dir),
        ]
    )
    out = capsys.readouterr()
    assert status == 0, out.err
    assert "dead_time" in out.out
    doc = json.loads(json_path.read_text())
    assert {"baseline", "steps", "effects", "final_rmse", "residual_white"} <= set(doc)
    assert doc["verdict"] == "explained"
    assert doc["effects"] == ["dead_time"]
    assert doc["final_rmse"] <= 0.5 * doc["baseline"]["rmse"]
    assert (report_dir / REPORT_NAME).is_file()
    for name in FIGURES.values():
        assert (report_dir / name).stat().st_size > 1000


def test_no_time_column_needs_the_sample_interval(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = np.genfromtxt(recording, delimiter=",", names=True)
    path = _write_csv(tmp_path / "nt.csv", {"a": data["T_ref"], "b": data["T_m"]})
    args = ["diagnose", str(path), "--input", "a", "--output", "b", "--time", ""]
    assert main(args) == 2
    assert "--sample-interval" in _one_error_line(capsys)
    assert main([*args, "--sample-interval", "0.1", "--quiet"]) == 0
    assert capsys.readouterr().out == ""


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--input", "T_ref", "--output", "T_x"], "T_x"),
        (["--input", "T_ref", "--output", "T_ref"], "same column"),
        (["--input", "T_ref"], "--output"),
        (
            ["--input", "T_ref", "--output", "T_m", "--json", "/nonexistent/dir/x.json"],
            "does not exist",
        ),
        (["--input", "T_ref", "--output", "T_m", "--sample-interval", "-1"], "sample-interval"),
    ],
)
def test_bad_arguments_exit_2_with_one_line(
    recording: Path, args: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["diagnose", str(recording), *args]) == 2
    assert message in _one_error_line(capsys)


def test_bad_files_exit_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    args = ["--input", "T_ref", "--output", "T_m"]
    assert main(["diagnose", str(tmp_path / "missing.csv"), *args]) == 2
    assert "missing.csv" in _one_error_line(capsys)
    bad = tmp_path / "bad.csv"
    rows = ["t,T_ref,T_m"] + [f"{0.1 * k:.1f},{200 + k},{200 + k}" for k in range(100)]
    rows[40] = "3.9,201,abc"
    bad.write_text("\n".join(rows) + "\n")
    assert main(["diagnose", str(bad), *args]) == 2
    assert "T_m" in _one_error_line(capsys)
    short = _write_csv(
        tmp_path / "short.csv",
        {"t": np.arange(12) * 0.1, "T_ref": np.full(12, 200.0), "T_m": np.full(12, 200.0)},
    )
    assert main(["diagnose", str(short), *args]) == 2
    _one_error_line(capsys)


def test_no_excitation_exits_3(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(3)
    n = 2000
    flat = _write_csv(
        tmp_path / "flat.csv",
        {
            "t": np.arange(n) * 0.1,
            "T_ref": 250.0 + rng.normal(0.0, 0.05, n),
            "T_m": 250.0 + rng.normal(0.0, 0.05, n),
        },
    )
    assert main(["diagnose", str(flat), "--input", "T_ref", "--output", "T_m"]) == 3
    assert "cannot be identified" in _one_error_line(capsys)


# --- issue 14: flow, noise level, logger data -------------------------------------------------


def test_flow_column_and_noise_level(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    case = make_field_case(("flow_dependence",), 2, duration=600.0)
    path = _write_csv(
        tmp_path / "drive.csv",
        {"t": case.t, "T_ref": case.reference, "T_m": case.measured, "v": case.flow},
        fmt="%.6f",
    )
    json_path = tmp_path / "out.json"
    args = ["diagnose", str(path), "--input", "T_ref", "--output", "T_m", "--flow", "v"]
    assert main([*args, "--json", str(json_path)]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "flow_dependence" in out and "flow_exponent = " in out
    assert out.splitlines()[-1].startswith("verdict: explained.")
    doc = json.loads(json_path.read_text())
    assert doc["effects"] == ["flow_dependence"]
    assert doc["steps"][0]["units"]["flow_reference"] == "flow unit"
    # without --flow the effect cannot be named, and the verdict does not hide that
    assert (
        main(
            [
                "diagnose",
                str(path),
                "--input",
                "T_ref",
                "--output",
                "T_m",
                "--quiet",
                "--json",
                str(json_path),
            ]
        )
        == 0
    )
    assert json.loads(json_path.read_text())["verdict"] != "nothing_missing"
    assert main([*args, "--noise-std", "0.05,0.06", "--json", str(json_path)]) == 0
    noise = json.loads(json_path.read_text())["noise"]
    assert (noise["reference_std"], noise["measured_std"]) == (0.05, 0.06)
    assert noise["measured_source"] == "given"


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--noise-std", "0"], "--noise-std"),
        (["--noise-std", "-0.1"], "--noise-std"),
        (["--noise-std", "a,b"], "--noise-std"),
        (["--noise-std", "0.1,0.1,0.1"], "--noise-std"),
        (["--flow", "T_ref"], "--flow"),
        (["--flow", "nope"], "nope"),
        (["--flow", "bad"], "column 'bad' is 0 or below on 1 of"),
    ],
)
def test_bad_flow_or_noise_exit_2_with_one_line(
    tmp_path: Path, extra: list[str], message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    case = make_field_case((), 3, conditions="drive", duration=60.0)
    bad = case.flow.copy()
    bad[5] = -1.0
    path = _write_csv(
        tmp_path / "d.csv",
        {"t": case.t, "T_ref": case.reference, "T_m": case.measured, "v": case.flow, "bad": bad},
    )
    assert main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m", *extra]) == 2
    assert message in _one_error_line(capsys)


def test_logger_data_quantised_and_held(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A thermocouple plunge from a logger: 15 ms rows, 0.25 K steps, the reading held for 5
    rows (issue 14's ZeroDivisionError): exit 0, the hold and the grid named."""
    case = make_logger_case(4)
    path = _write_csv(
        tmp_path / "plunge.csv",
        {"t": case.t, "T_ref": case.reference, "T_m": case.measured},
        fmt="%.3f",
    )
    assert main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m"]) == 0
    captured = capsys.readouterr()
    assert captured.err == ""
    assert "+ sample_and_hold (hold_samples = 5 samples" in captured.out
    assert "+ quantisation (quantisation_step = 0.25 K" in captured.out
    assert "verdict: " in captured.out


@pytest.mark.parametrize("kind", ["noise-free", "held-both", "quantised-coarse", "flat"])
def test_no_internal_error_on_degenerate_data(
    tmp_path: Path, kind: str, capsys: pytest.CaptureFixture[str]
) -> None:
    case = make_field_case((), 8, duration=120.0)
    u, y = case.reference, case.measured
    if kind == "noise-free":
        u = case.gas
        y = np.interp(case.t, case.t, case.gas)  # the gas itself: a sensor without lag
    elif kind == "held-both":
        u, y = np.repeat(u[::4], 4)[: u.size], np.repeat(y[::4], 4)[: y.size]
    elif kind == "quantised-coarse":
        u, y = np.round(u / 2.0) * 2.0, np.round(y / 2.0) * 2.0
    else:
        u = y = np.full(u.size, 21.5)
    path = _write_csv(tmp_path / f"{kind}.csv", {"t": case.t, "a": u, "b": y}, fmt="%.4f")
    status = main(["diagnose", str(path), "--input", "a", "--output", "b"])
    captured = capsys.readouterr()
    assert status in (0, 2, 3), captured.err
    assert "internal" not in captured.err
    if status:
        assert len(captured.err.strip().splitlines()) == 1
    else:
        assert "verdict: " in captured.out


def test_time_in_milliseconds(recording: Path, tmp_path: Path,
                              capsys: pytest.CaptureFixture[str]) -> None:
    """The same record with its time in ms (by option, and by a 'Time (ms)' header) gives
    the same baseline as in seconds (issue 15: every command reads every time unit)."""
    data = np.loadtxt(recording, delimiter=",", skiprows=1)
    ms = _write_csv(tmp_path / "ms.csv", {"t": data[:, 0] * 1e3, "T_ref": data[:, 1],
                                          "T_m": data[:, 2]})
    header = _write_csv(tmp_path / "header.csv", {"Time (ms)": data[:, 0] * 1e3,
                                                  "T_ref": data[:, 1], "T_m": data[:, 2]})
    docs = []
    for path, extra in ((recording, []), (ms, ["--time-unit", "ms"]),
                        (header, ["--time", "Time"])):
        out = tmp_path / f"{path.stem}.json"
        status = main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m",
                       "--json", str(out), *extra])
        assert status == 0, capsys.readouterr().err
        docs.append(json.loads(out.read_text()))
    for doc in docs[1:]:
        for name, value in docs[0]["baseline"]["params"].items():
            assert doc["baseline"]["params"][name] == pytest.approx(value, rel=1e-6)


def test_dropped_rows_are_bridged_not_refused(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """diagnose reads a recording as characterise does: a logger that lost single rows at 6
    places (once refused by the strict loader: "resample to a uniform grid first") is bridged
    with a note, and the hidden dead time is still found, the model explained, its value
    within 2 % of the intact recording's (interpolating one row of a lagged sensor errs by
    Ts^2 max|T''| / 2, far below the noise)."""
    docs = []
    data = np.genfromtxt(recording, delimiter=",", names=True)
    keep = np.ones(data.size, dtype=bool)
    keep[np.linspace(200, data.size - 200, 6).astype(int)] = False
    lossy = _write_csv(tmp_path / "lossy.csv", {n: data[n][keep] for n in ("t", "T_ref", "T_m")})
    for path in (recording, lossy):
        json_path = tmp_path / f"{path.stem}.json"
        status = main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m",
                       "--json", str(json_path)])
        out = capsys.readouterr().out
        assert status == 0, out
        assert ("note: dropped rows: 6 intervals" in out) == (path == lossy)
        docs.append(json.loads(json_path.read_text()))
    intact, bridged = docs
    assert bridged["effects"] == ["dead_time"] and bridged["verdict"] == "explained"
    assert len(bridged["notes"]) == 1 and bridged["notes"][0].startswith("dropped rows")
    assert intact["notes"] == []
    dead = [doc["final_params"]["delay"] for doc in docs]
    print("dead time intact / bridged:", dead)
    assert abs(dead[1] - dead[0]) <= 0.02 * dead[0], dead


def test_missing_readings_are_dropped_rows(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Empty cells in the sensor's column at 6 places, with --missing bridge, are the same 6
    rows lost: the same bridged record, so the same dead time to the last digit, and a note
    for each."""
    data = np.genfromtxt(recording, delimiter=",", names=True)
    rows = np.linspace(200, data.size - 200, 6).astype(int)
    keep = np.ones(data.size, dtype=bool)
    keep[rows] = False
    lossy = _write_csv(tmp_path / "lossy.csv", {n: data[n][keep] for n in ("t", "T_ref", "T_m")})
    empty = _write_csv(tmp_path / "empty.csv", {n: data[n] for n in ("t", "T_ref", "T_m")})
    lines = empty.read_text().splitlines()
    for row in rows:
        lines[row + 1] = ",".join([*lines[row + 1].split(",")[:2], ""])
    empty.write_text("\n".join(lines) + "\n")
    docs = []
    for path in (lossy, empty):
        json_path = tmp_path / f"{path.stem}.json"
        status = main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m",
                       "--json", str(json_path), "--missing", "bridge"])
        out = capsys.readouterr().out
        assert status == 0, out
        docs.append(json.loads(json_path.read_text()))
    assert docs[1]["notes"][0].startswith(
        "missing readings (empty cells, NaN or invalid samples): 'T_m' 6")
    # the lines named differ (the lossy file has no line for a lost row), the counts do not
    assert docs[1]["notes"][1].startswith("dropped rows: 6 intervals")
    assert docs[0]["notes"][0].startswith("dropped rows: 6 intervals")
    assert f"6 of {data.size} rows interpolated" in docs[1]["notes"][1]
    assert docs[1]["final_params"]["delay"] == docs[0]["final_params"]["delay"]


def test_a_sensor_that_does_not_follow_its_input_exits_3(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A stuck or disconnected sensor (its column constant): it was "explained" by an offset
    and a gain of 3e-9, exit 0, beside a baseline fit of -7.7e295 %."""
    data = np.genfromtxt(recording, delimiter=",", names=True)
    path = _write_csv(tmp_path / "stuck.csv",
                      {"t": data["t"], "T_ref": data["T_ref"], "T_m": np.full(data.size, 20.0)})
    status = main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m"])
    assert status == 3
    line = _one_error_line(capsys)
    assert "the output changes by 0 only" in line and "does not follow its input" in line


def test_a_short_record_is_diagnosed_not_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """60 rows (the minimum is 50): the whiteness test asked for 25 lags of an
    autocorrelation computed to n/4 = 15 and the record was refused with "operands could not
    be broadcast together". A first-order sensor behind a step: nothing missing."""
    rng = np.random.default_rng(1)
    t = np.arange(60) * 0.5
    u = np.where(t > 3.0, 80.0, 20.0) + 0.05 * rng.standard_normal(t.size)
    a, y = np.exp(-0.5 / 4.0), np.full(t.size, 20.0)
    for k in range(1, t.size):
        y[k] = a * y[k - 1] + (1.0 - a) * u[k - 1]
    y += 0.05 * rng.standard_normal(t.size)
    path = _write_csv(tmp_path / "short.csv", {"t": t, "T_ref": u, "T_m": y})
    json_path = tmp_path / "short.json"
    status = main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m",
                   "--json", str(json_path)])
    assert status == 0, capsys.readouterr().err
    doc = json.loads(json_path.read_text())
    assert doc["verdict"] == "nothing_missing"
    assert doc["baseline"]["params"]["tau"] == pytest.approx(4.0, rel=0.1)


@pytest.mark.parametrize(("scale", "offset", "shown"), [(0.041, 0.0, "0.041"),
                                                         (-1.0, 1000.0, "-1"),
                                                         (1e-5, 0.0, None)])
def test_an_output_in_other_units_exits_3(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], scale: float, offset: float,
    shown: str | None,
) -> None:
    """A thermocouple logged in mV (41 uV/K) was "partly explained by offset, gain, extra_pole"
    with a gain of -117 and a 3000 s pole, exit 0; an inverted channel likewise. The static
    gain against the reference is estimated first and refused outside 0.5-2, as identify does.
    A type S thermocouple in V (1e-5 per K) changes by less than the 0.1 mK resolution floor
    allows a reading to and was called disconnected: it follows the input, in other units."""
    rng = np.random.default_rng(3)
    t = np.arange(600) * 0.5
    u = np.interp(t, [0, 50, 51, 150, 151, 300], [20, 20, 80, 80, 40, 40])
    u = u + 0.05 * rng.standard_normal(t.size)
    a, y = np.exp(-0.5 / 4.0), np.full(t.size, 20.0)
    for k in range(1, t.size):
        y[k] = a * y[k - 1] + (1.0 - a) * u[k - 1]
    y = offset + scale * y + 0.05 * abs(scale) * rng.standard_normal(t.size)
    path = _write_csv(tmp_path / "units.csv", {"t": t, "T_ref": u, "T_m": y}, fmt="%.7g")
    status = main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m"])
    line = _one_error_line(capsys)
    assert status == 3
    assert "different units" in line
    assert (f"static gain of {shown}" if shown else "the output follows the input") in line


def test_a_sensor_that_drops_out_for_a_stretch_exits_2_naming_it(
    recording: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """An open circuit for 30 s of the sensor (read as 0): refused as input by name with the
    stretch to keep (models/stuck.py), not diagnosed as a missing effect of the model."""
    data = np.genfromtxt(recording, delimiter=",", names=True)
    measured = data["T_m"].copy()
    measured[3000:3300] = 0.0
    path = _write_csv(tmp_path / "dropout.csv",
                      {"t": data["t"], "T_ref": data["T_ref"], "T_m": measured})
    status = main(["diagnose", str(path), "--input", "T_ref", "--output", "T_m"])
    assert status == 2
    line = _one_error_line(capsys)
    assert "T_m reads exactly 0 on 300 rows from t = 300 to 329.9 s" in line
    assert "--window 330:900 " in line
