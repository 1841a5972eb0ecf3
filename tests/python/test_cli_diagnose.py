"""`dualprobe diagnose`: files in, JSON and report out, one error line and exit 2/3 on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dualprobe.cli import main
from dualprobe.diagnose import FIGURES, REPORT_NAME
from hidden_effects import make_case


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
