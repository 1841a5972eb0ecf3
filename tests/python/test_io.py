"""CSV loading: every malformed input gives an InputError naming what and where."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dualprobe.io import EstimationError, InputError, load_columns, write_columns

COLUMNS = ["T_m1", "T_m2"]


def write_recording(path: Path, rows: int = 20, ts: float = 0.1) -> Path:
    t = np.arange(rows) * ts
    write_columns(path, {"t": t, "T_m1": 20.0 + t, "T_m2": 20.0 + 0.5 * t})
    return path


def lines_of(path: Path) -> list[str]:
    return path.read_text().splitlines()


def replace_line(path: Path, index: int, text: str) -> Path:
    lines = lines_of(path)
    lines[index] = text
    path.write_text("\n".join(lines) + "\n")
    return path


def message(path: Path, **kwargs: object) -> str:
    with pytest.raises(InputError) as info:
        load_columns(path, kwargs.pop("columns", COLUMNS), **kwargs)  # type: ignore[arg-type]
    text = str(info.value)
    assert "\n" not in text
    return text


def test_error_classes_map_to_documented_bases() -> None:
    assert issubclass(InputError, ValueError)
    assert issubclass(EstimationError, RuntimeError)


def test_round_trip_is_exact(tmp_path: Path) -> None:
    t = np.arange(500) * 1e-3 + 1234.5
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=500), rng.normal(size=500) * 1e-7
    write_columns(tmp_path / "r.csv", {"t": t, "T_m1": a, "T_m2": b})
    time, columns, ts = load_columns(tmp_path / "r.csv", COLUMNS)
    assert time is not None and ts is not None
    np.testing.assert_array_equal(time, t)  # repr round-trips floats exactly
    np.testing.assert_array_equal(columns["T_m1"], a)
    np.testing.assert_array_equal(columns["T_m2"], b)
    assert ts == pytest.approx(1e-3, rel=1e-9)  # float64 error of 1234.5 + k*1e-3


def test_accepts_whitespace_blank_lines_crlf_and_bom(tmp_path: Path) -> None:
    path = tmp_path / "w.csv"
    body = "\ufeff t , T_m1 ,T_m2,extra\r\n"
    body += "".join(f" {k * 0.5} ,{k}, {2 * k} ,x\r\n" for k in range(12))
    path.write_text(body + "\r\n\r\n", newline="")
    time, columns, ts = load_columns(path, COLUMNS)
    assert time is not None
    assert ts == 0.5
    np.testing.assert_array_equal(columns["T_m2"], 2.0 * np.arange(12))


@pytest.mark.parametrize("delimiter", [";", "\t"])
def test_semicolon_and_tab_separated(tmp_path: Path, delimiter: str) -> None:
    path = tmp_path / "s.csv"
    rows = [delimiter.join(["t", "T_m1", "T_m2"])]
    rows += [delimiter.join([str(k), str(2 * k), "1"]) for k in range(10)]
    path.write_text("\n".join(rows) + "\n")
    _, columns, ts = load_columns(path, COLUMNS)
    assert ts == 1.0
    np.testing.assert_array_equal(columns["T_m1"], 2.0 * np.arange(10))


def test_printed_time_resolution_is_not_irregularity(tmp_path: Path) -> None:
    # 1 kHz stamps printed with 3 decimals: float parsing makes the differences uneven at the
    # 1e-13 level, which is rounding, not jitter.
    path = tmp_path / "p.csv"
    body = "t,T_m1,T_m2\n" + "".join(f"{1000 + k * 1e-3:.3f},1,{k}\n" for k in range(200))
    path.write_text(body)
    _, _, ts = load_columns(path, COLUMNS)
    assert ts == pytest.approx(1e-3, rel=1e-9)  # float64 rounding at t ~ 1000


def test_rounded_stamps_of_an_irrational_interval(tmp_path: Path) -> None:
    # Ts = 1/3 s printed with 4 decimals: steps of 0.3333 and 0.3334 are rounding only.
    path = tmp_path / "third.csv"
    body = "t,T_m1,T_m2\n" + "".join(f"{k / 3:.4f},1,{k}\n" for k in range(30))
    path.write_text(body)
    _, _, ts = load_columns(path, COLUMNS)
    assert ts == pytest.approx(1 / 3, abs=1e-5)  # end stamps rounded to 5e-5, over 29 steps


def test_without_time_column(tmp_path: Path) -> None:
    path = tmp_path / "n.csv"
    path.write_text("T_m1,T_m2\n" + "".join(f"{k},{k}\n" for k in range(10)))
    time, columns, ts = load_columns(path, COLUMNS, time=None)
    assert time is None and ts is None
    assert columns["T_m1"].size == 10


def test_missing_file(tmp_path: Path) -> None:
    assert "no such file" in message(tmp_path / "absent.csv")


def test_directory(tmp_path: Path) -> None:
    assert "directory" in message(tmp_path)


def test_empty_and_whitespace_only(tmp_path: Path) -> None:
    (tmp_path / "e.csv").write_text("")
    (tmp_path / "s.csv").write_text("\n \n\n")
    assert "empty" in message(tmp_path / "e.csv")
    assert "empty" in message(tmp_path / "s.csv")


def test_header_only(tmp_path: Path) -> None:
    (tmp_path / "h.csv").write_text("t,T_m1,T_m2\n")
    assert "header only" in message(tmp_path / "h.csv")


def test_missing_column_lists_available(tmp_path: Path) -> None:
    path = write_recording(tmp_path / "m.csv")
    text = message(path, columns=["T_m1", "T_x"])
    assert "'T_x'" in text and "available: t, T_m1, T_m2" in text
    assert "'tt'" in message(path, time="tt")


def test_non_numeric_value_names_line_and_column(tmp_path: Path) -> None:
    path = write_recording(tmp_path / "v.csv")
    replace_line(path, 5, "0.4,abc,3")
    text = message(path)
    assert "line 6" in text and "'T_m1'" in text and "'abc'" in text


def test_empty_cell(tmp_path: Path) -> None:
    path = replace_line(write_recording(tmp_path / "c.csv"), 3, "0.2,21,")
    text = message(path)
    assert "line 4" in text and "'T_m2'" in text and "empty" in text


@pytest.mark.parametrize("bad", ["nan", "inf", "-Infinity", "NaN"])
def test_non_finite(tmp_path: Path, bad: str) -> None:
    path = replace_line(write_recording(tmp_path / "f.csv"), 8, f"0.7,20.7,{bad}")
    text = message(path)
    assert "line 9" in text and "'T_m2'" in text and "non-finite" in text


def test_ragged_row(tmp_path: Path) -> None:
    path = replace_line(write_recording(tmp_path / "r.csv"), 2, "0.1,20.1")
    assert "line 3" in message(path) and "fields" in message(path)


def test_time_not_increasing(tmp_path: Path) -> None:
    path = replace_line(write_recording(tmp_path / "t.csv"), 4, "0.2,20.3,20.15")
    text = message(path)
    assert "line 5" in text and "not strictly increasing" in text


def test_irregular_time(tmp_path: Path) -> None:
    path = replace_line(write_recording(tmp_path / "i.csv"), 11, "1.05,21,20.5")
    text = message(path)
    assert "line 12" in text and "irregular" in text


def test_too_few_rows(tmp_path: Path) -> None:
    path = write_recording(tmp_path / "few.csv", rows=5)
    assert "too few data rows (5" in message(path)
    assert load_columns(path, COLUMNS, min_rows=5)[2] == pytest.approx(0.1)


def test_binary_junk(tmp_path: Path) -> None:
    (tmp_path / "nul.csv").write_bytes(b"t,T_m1,T_m2\n0,1,2\n\x00\x01\x02\x03")
    (tmp_path / "bad.csv").write_bytes(bytes(range(128, 256)) * 4)
    assert "binary" in message(tmp_path / "nul.csv")
    assert "UTF-8" in message(tmp_path / "bad.csv")


def test_duplicate_and_empty_header_names(tmp_path: Path) -> None:
    (tmp_path / "d.csv").write_text("t,T_m1,T_m1\n" + "0,1,2\n" * 10)
    (tmp_path / "e.csv").write_text("t,,T_m2\n" + "0,1,2\n" * 10)
    assert "twice" in message(tmp_path / "d.csv")
    assert "empty column name" in message(tmp_path / "e.csv")


def test_write_columns_writes_nan(tmp_path: Path) -> None:
    write_columns(tmp_path / "o.csv", {"t": np.arange(3.0), "x": np.array([1.5, np.nan, 2.0])})
    assert lines_of(tmp_path / "o.csv") == ["t,x", "0.0,1.5", "1.0,nan", "2.0,2.0"]
