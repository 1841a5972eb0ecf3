"""Missing readings (empty cells, NaN, Parquet nulls, MDF4 invalid samples): refused by
default naming the cell (issue 2's bad input); with --missing bridge a row without a reading in
every requested column is a dropped row: short runs are bridged, long ones split the record,
rows at the ends trim it, a channel of another rate is refused."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dualprobe.io import InputError, Recording, load_columns, load_recording

TS = 0.1


def signals(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Smooth sensor-like signals: |x''| <= 0.3 * 0.8^2 + 0.5 * 0.3^2 = 0.237 K/s^2."""
    return 300.0 + 0.3 * np.sin(0.8 * t), 300.0 + 0.5 * np.cos(0.3 * t)


def write(path: Path, t: np.ndarray | None, x: np.ndarray, y: np.ndarray,
          empty: dict[str, list[int]], text: str = "") -> Path:
    """A CSV whose cells listed in ``empty`` (column -> rows) hold ``text`` ("" or "nan")."""
    header = ["T_m1", "T_m2"] if t is None else ["t", "T_m1", "T_m2"]
    lines = [",".join(header)]
    for k in range(x.size):
        cells = {"t": "" if t is None else f"{t[k]:.1f}", "T_m1": repr(float(x[k])),
                 "T_m2": repr(float(y[k]))}
        for column, rows in empty.items():
            if k in rows:
                cells[column] = text
        lines.append(",".join(cells[name] for name in header))
    path.write_text("\n".join(lines) + "\n")
    return path


def bridged(path: Path, columns: list[str], **kwargs: Any) -> Recording:
    """The loader with --missing bridge (the default refuses a missing reading)."""
    return load_recording(path, columns, missing="bridge", **kwargs)


def refusal(path: Path, **kwargs: object) -> str:
    with pytest.raises(InputError) as info:
        bridged(path, ["T_m1", "T_m2"], **kwargs)
    text = str(info.value)
    assert "\n" not in text
    return text


@pytest.mark.parametrize("text", ["", "nan", "NaN"])
def test_missing_readings_are_dropped_rows_bridged_and_trimmed(tmp_path: Path, text: str) -> None:
    t = np.arange(400) * TS
    x, y = signals(t)
    # the second channel starts 2 rows late, the first stops a row early, and 1-3 readings
    # are lost inside (one of them in both channels at once)
    empty = {"T_m1": [50, 51, 52, 200, 399], "T_m2": [0, 1, 120, 200, 300, 301]}
    rec = bridged(write(tmp_path / "m.csv", t, x, y, empty, text), ["T_m1", "T_m2"])
    assert rec.contiguous
    assert rec.t[0] == pytest.approx(0.2) and rec.t[-1] == pytest.approx(39.8)
    assert np.allclose(np.diff(rec.t), TS)
    note = next(n for n in rec.notes if n.startswith("missing readings"))
    assert "'T_m1' 5 (first at line 52)" in note and "'T_m2' 6 (first at line 2)" in note
    assert "10 rows of 400 treated as dropped rows, 3 of them at the ends (trimmed)" in note
    assert any("dropped rows: 4 intervals" in n for n in rec.notes), rec.notes
    # linear interpolation over at most 4 intervals: h^2 max|x''| / 8 = 0.4^2 * 0.237 / 8
    bound = 0.4**2 * 0.237 / 8 + 1e-12
    tx, ty = signals(rec.t)
    assert np.max(np.abs(rec.columns["T_m1"] - tx)) <= bound
    assert np.max(np.abs(rec.columns["T_m2"] - ty)) <= bound


def test_without_a_time_column_the_row_numbers_are_the_clock(tmp_path: Path) -> None:
    t = np.arange(100) * TS
    x, y = signals(t)
    path = write(tmp_path / "n.csv", None, x, y, {"T_m2": [40, 41]})
    rec = bridged(path, ["T_m1", "T_m2"], time=None, sample_interval=TS)
    assert rec.t.size == 100 and rec.sample_interval == pytest.approx(TS)
    assert np.max(np.abs(rec.columns["T_m2"] - signals(rec.t)[1])) <= 0.3**2 * 0.237 / 8 + 1e-12
    assert any("'T_m2' 2 (first at line 42)" in n for n in rec.notes)


def test_a_long_run_splits_the_record_and_characterise_is_told_where(tmp_path: Path) -> None:
    t = np.arange(300) * TS
    x, y = signals(t)
    rec = bridged(write(tmp_path / "l.csv", t, x, y, {"T_m1": list(range(100, 106))}),
                         ["T_m1", "T_m2"])
    assert len(rec.gaps) == 1 and rec.gaps[0].label == "line 108"
    with pytest.raises(InputError) as info:
        rec.require_contiguous("characterise")
    # the gap says it is missing readings, the segment is named by its times (its row numbers
    # are not the file's once rows were dropped)
    assert ("line 108 (t = 9.9 s): gap of 0.7 s (7 intervals: 6 rows without a reading in "
            "every column); characterise needs a record without gaps: give --window 10.6:29.9 "
            "(the longest segment, 19.3 s) or cut the file at the gap") in str(info.value)
    window = bridged(tmp_path / "l.csv", ["T_m1", "T_m2"], window=(10.6, 29.9))
    assert window.contiguous and window.t.size == 194 and window.t[0] == pytest.approx(10.6)


def test_a_channel_of_another_rate_is_refused_not_thinned(tmp_path: Path) -> None:
    """Every other cell empty: dropping those rows would halve the rate unnoticed."""
    t = np.arange(200) * TS
    x, y = signals(t)
    path = write(tmp_path / "r.csv", t, x, y, {"T_m2": list(range(1, 200, 2))})
    text = refusal(path)
    assert "column 'T_m2' has readings in only 100 of the 199 rows" in text
    assert "different rates" in text


def test_refusals_name_what_is_missing(tmp_path: Path) -> None:
    t = np.arange(50) * TS
    x, y = signals(t)
    nothing = write(tmp_path / "a.csv", t, x, y, {"T_m1": list(range(0, 50, 2)),
                                                  "T_m2": list(range(1, 50, 2))})
    assert ("no row has a reading in every column (readings missing in 'T_m1', 'T_m2')"
            in refusal(nothing))
    blank = write(tmp_path / "b.csv", t, x, y, {"T_m2": list(range(50))})
    assert "column 'T_m2' has no reading (every cell empty, NaN or invalid)" in refusal(blank)
    few = write(tmp_path / "f.csv", t, x, y, {"T_m1": list(range(0, 44))})
    assert "too few rows with a reading in every column (6" in refusal(few)
    stamp = write(tmp_path / "s.csv", t, x, y, {})
    lines = stamp.read_text().splitlines()
    lines[10] = "," + lines[10].split(",", 1)[1]  # a row without a time stamp is a dropped row
    stamp.write_text("\n".join(lines) + "\n")
    rec = bridged(stamp, ["T_m1", "T_m2"])
    assert rec.t.size == 50 and any("'t' 1 (first at line 11)" in n for n in rec.notes)
    infinite = write(tmp_path / "i.csv", t, x, y, {"T_m2": [7]}, "inf")
    assert "line 9, column 'T_m2': non-finite value inf" in refusal(infinite)


def test_the_strict_loader_names_the_first_missing_cell(tmp_path: Path) -> None:
    t = np.arange(50) * TS
    x, y = signals(t)
    path = write(tmp_path / "s.csv", t, x, y, {"T_m2": [20], "T_m1": [30]})
    with pytest.raises(InputError, match=r"line 22, column 'T_m2': missing reading"):
        load_columns(path, ["T_m1", "T_m2"])


def test_parquet_nulls_are_missing_readings_as_in_csv(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    t = np.arange(200) * TS
    x, y = signals(t)
    lost = [30, 31, 150]
    column = pa.array([None if k in lost else float(v) for k, v in enumerate(y)],
                      type=pa.float64())
    pq.write_table(pa.table({"t": t, "T_m1": x, "T_m2": column}), tmp_path / "p.parquet")
    from_parquet = bridged(tmp_path / "p.parquet", ["T_m1", "T_m2"])
    from_csv = bridged(write(tmp_path / "p.csv", t, x, y, {"T_m2": lost}),
                              ["T_m1", "T_m2"])
    assert np.allclose(from_parquet.t, from_csv.t)
    for name in ("T_m1", "T_m2"):
        assert np.allclose(from_parquet.columns[name], from_csv.columns[name], rtol=0, atol=1e-12)
    assert any("'T_m2' 3 (first at row 31)" in n for n in from_parquet.notes)


def test_invalid_mdf4_samples_are_missing_readings_in_step(tmp_path: Path) -> None:
    """MDF4 invalidation bits: asammdf drops invalid samples by default, so T_m1 came back
    with 3 samples fewer than T_m2 of the same group and the two were paired row by row, out
    of step after row 10 (silently). Now invalid samples are missing readings: dropped and
    bridged like any other, the channels in step whichever is the raster; an invalid sample
    of a channel of another rate spoils the raster rows next to it, which are bridged too."""
    from recordings import write_mdf

    t = np.arange(300) * TS
    x, y = signals(t)
    bad = np.zeros(t.size, dtype=bool)
    bad[[10, 11, 150]] = True
    slow = np.arange(150) * 2 * TS  # another group at half the rate
    flow_bad = np.zeros(slow.size, dtype=bool)
    flow_bad[40] = True
    flow = 10.0 + np.sin(0.1 * slow)
    path = write_mdf(tmp_path / "inv.mf4",
                     [(t, {"T_m1": np.where(bad, -999.0, x), "T_m2": y}),
                      (slow, {"mdot": np.where(flow_bad, -1.0, flow)})],
                     invalid={"T_m1": bad, "mdot": flow_bad})
    loaded = [bridged(path, columns) for columns in
              (["T_m1", "T_m2", "mdot"], ["T_m2", "T_m1", "mdot"])]
    for rec in loaded:
        assert rec.t.size == 299  # the last raster row is past the slow group's span
        tx, ty = signals(rec.t)
        # up to 3 rows bridged: 0.4^2 * 0.237 / 8 on the sensors
        assert np.max(np.abs(rec.columns["T_m1"] - tx)) <= 0.4**2 * 0.237 / 8 + 1e-12
        assert np.max(np.abs(rec.columns["T_m2"] - ty)) <= 0.4**2 * 0.237 / 8 + 1e-12
        assert np.all(rec.columns["mdot"] > 8.0)  # the -1 never leaks in
        assert any("'T_m1' 3 (first at sample 10 of group 0)" in n for n in rec.notes)
        assert any("'mdot' 3" in n for n in rec.notes), rec.notes
    assert np.array_equal(loaded[0].columns["T_m1"], loaded[1].columns["T_m1"])
    with pytest.raises(InputError, match=r"sample 10 of group 0, column 'T_m1': missing reading"):
        load_recording(path, ["T_m1", "T_m2"])  # the default refuses, naming the sample


def test_a_window_reads_only_its_rows(tmp_path: Path) -> None:
    """--window START:END: what lies outside (a gap, a missing reading, a channel that starts
    late) does not matter; a gap inside still splits; rows are named as the file names them."""
    t = np.arange(400) * TS
    x, y = signals(t)
    path = write(tmp_path / "w.csv", t, x, y, {"T_m2": [0, 1, *range(300, 310)], "T_m1": [150]})
    whole = bridged(path, ["T_m1", "T_m2"])
    assert len(whole.gaps) == 1  # the 10 missing rows at 30 s
    rec = bridged(path, ["T_m1", "T_m2"], window=(5.0, 25.0))
    assert rec.contiguous and rec.t[0] == pytest.approx(5.0) and rec.t[-1] == pytest.approx(25.0)
    assert rec.notes[0] == "window t = 5-25 s: line 52 to line 252, 201 of 400 rows"
    assert "'T_m1' 1 (first at line 152)" in rec.notes[1]  # named as the file names it
    open_end = bridged(path, ["T_m1", "T_m2"], window=(None, 25.0))
    assert open_end.t[0] == pytest.approx(0.2)  # the late start is trimmed as before
    inside = bridged(path, ["T_m1", "T_m2"], window=(20.0, None))
    assert len(inside.gaps) == 1
    bare = write(tmp_path / "n.csv", None, x, y, {})
    rows = bridged(bare, ["T_m1", "T_m2"], time=None, sample_interval=TS, window=(1, 2))
    assert rows.t.size == 11 and rows.t[0] == pytest.approx(1.0)
    assert "--window 50:60 holds 0 rows (need at least 10); the record spans t = 0-39.9 s" in (
        refusal(path, window=(50.0, 60.0)))


def test_a_missing_reading_is_refused_by_default_saying_how_to_bridge_it(tmp_path: Path) -> None:
    t = np.arange(100) * TS
    x, y = signals(t)
    for text in ("", "nan"):
        path = write(tmp_path / f"d{text}.csv", t, x, y, {"T_m2": [40]}, text)
        with pytest.raises(InputError) as info:
            load_recording(path, ["T_m1", "T_m2"])
        assert str(info.value).endswith(
            "line 42, column 'T_m2': missing reading (empty cell or non-finite value nan); give "
            "--missing bridge to drop such rows and bridge them like rows the logger lost")
