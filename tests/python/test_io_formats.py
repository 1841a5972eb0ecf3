"""load_recording: CSV, Parquet and MDF4 readers; time units, clock jitter, gaps."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from dualprobe.io import InputError, detect_format, load_columns, load_recording
from dualprobe.io.timebase import split_unit, stamp_resolution
from recordings import write_csv, write_mdf, write_parquet


def error_of(path: Path, columns: list[str], **kwargs: object) -> str:
    with pytest.raises(InputError) as info:
        load_recording(path, columns, **kwargs)  # type: ignore[arg-type]
    text = str(info.value)
    assert "\n" not in text
    return text


def slow_signals(t: np.ndarray) -> dict[str, np.ndarray]:
    return {"T_m1": 20.0 + 5.0 * np.sin(0.3 * t), "T_m2": 20.0 + 5.0 * np.cos(0.2 * t)}


# --- CSV -------------------------------------------------------------------------------------


def test_one_hour_at_100_hz_loads_well_under_a_second(tmp_path: Path) -> None:
    rows = 360_000
    t = np.arange(rows) * 0.01
    rng = np.random.default_rng(3)
    path = write_csv(
        tmp_path / "hour.csv",
        {"t": t, "T_m1": 400 + rng.normal(size=rows), "T_m2": 400 + rng.normal(size=rows)},
    )
    timings = []
    for _ in range(2):  # the first includes importing pyarrow
        start = time.perf_counter()
        recording = load_recording(path, ["T_m1", "T_m2"])
        timings.append(time.perf_counter() - start)
    print(f"360k-row CSV: {timings[0]:.3f} s cold, {timings[1]:.3f} s warm")
    assert recording.t.size == rows and recording.sample_interval == pytest.approx(0.01)
    assert not recording.notes and recording.format == "csv"
    assert min(timings) < 1.0


def test_time_unit_option_and_header(tmp_path: Path) -> None:
    t = np.arange(400) * 15.0  # ms
    signals = slow_signals(t / 1000.0)
    plain = write_csv(tmp_path / "ms.csv", {"t": t, **signals})
    seconds = load_recording(plain, ["T_m1"], time_unit="ms")
    assert seconds.sample_interval == pytest.approx(0.015, rel=1e-12)
    np.testing.assert_allclose(seconds.t, t / 1000.0)
    assert not seconds.notes

    headed = write_csv(tmp_path / "header.csv", {"Time (ms)": t, **signals})
    for name in ("Time", "Time (ms)"):
        recording = load_recording(headed, ["T_m1", "T_m2"], time=name)
        assert recording.sample_interval == pytest.approx(0.015, rel=1e-12)
        assert recording.notes == ("time column 'Time (ms)': unit ms read from the header",)
    assert load_recording(headed, ["T_m1"], time="Time", time_unit="ms").notes == ()
    text = error_of(headed, ["T_m1"], time="Time", time_unit="s")
    assert "--time-unit s conflicts" in text and "(ms)" in text

    micro = write_csv(tmp_path / "us.csv", {"t [us]": t * 1000.0, **signals})
    assert load_recording(micro, ["T_m1"]).sample_interval == pytest.approx(0.015)
    minutes = write_csv(tmp_path / "min.csv", {"t": t / 60000.0, **signals}, fmt="%.15g")
    assert load_recording(minutes, ["T_m1"], time_unit="min").sample_interval == pytest.approx(
        0.015, rel=1e-9
    )
    # Only a bracketed unit is read; a long interval without any unit gets a note.
    assert split_unit("time_ms") == ("time_ms", None)
    assert split_unit("T_m1 [degC]") == ("T_m1", "degC")
    assert "give --time-unit" in load_recording(plain, ["T_m1"]).notes[0]
    assert "time unit must be one of" in error_of(plain, ["T_m1"], time_unit="h")


def test_data_columns_with_units_in_the_header(tmp_path: Path) -> None:
    t = np.arange(50) * 0.1
    path = write_csv(tmp_path / "u.csv", {"t (s)": t, "T_m1 (degC)": t, "T_m2 [degC]": 2 * t})
    recording = load_recording(path, ["T_m1", "T_m2"])
    np.testing.assert_allclose(recording.columns["T_m2"], 2 * t, rtol=1e-12)
    assert recording.notes == ()



@pytest.mark.parametrize("fmt", ["csv", "parquet"])
def test_a_time_column_named_otherwise_is_found_without_time(tmp_path: Path, fmt: str) -> None:
    """Loggers name their clock 'time', 'Time [ms]' or 'timestamp'; the default time column
    't' is then the one column so named, with a note; never a guess among several."""
    t = np.arange(200) * 0.1
    write = write_csv if fmt == "csv" else write_parquet
    for header, scale in (("time", 1.0), ("Time [ms]", 1000.0), ("Timestamp", 1.0)):
        path = write(tmp_path / f"r.{fmt}", {header: t * scale, **slow_signals(t)})
        recording = load_recording(path, ["T_m1", "T_m2"])
        np.testing.assert_allclose(recording.t, t, rtol=1e-12, atol=1e-12)
        assert recording.sample_interval == pytest.approx(0.1, rel=1e-9)
        assert recording.notes[0] == (f"time column {header!r} (the file has no column 't'; "
                                      "--time COL names another)")
    # Two candidates: no guess, the usual error naming the columns; --time picks one.
    both = write(tmp_path / f"both.{fmt}", {"time": t, "timestamp": t + 5.0, **slow_signals(t)})
    assert "missing column 't'; available: time, timestamp" in error_of(both, ["T_m1"])
    assert load_recording(both, ["T_m1"], time="timestamp").t[0] == pytest.approx(5.0)
    # A temperature named 'T' is not a clock: the usual error.
    temperature = write(tmp_path / f"T.{fmt}", {"T": slow_signals(t)["T_m1"], **slow_signals(t)})
    assert "missing column 't'; available: T, T_m1, T_m2" in error_of(temperature, ["T_m1"])
    # A 't' is taken as before, without a note, even beside a 'time' column.
    plain = write(tmp_path / f"t.{fmt}", {"t": t, "time": t + 5.0, **slow_signals(t)})
    recording = load_recording(plain, ["T_m1"])
    assert recording.t[0] == 0.0 and recording.notes == ()

def test_clock_jitter_is_resampled_with_a_note(tmp_path: Path) -> None:
    rng = np.random.default_rng(5)
    ts = 0.015
    instants = np.arange(4000) * ts + rng.uniform(-0.5e-3, 0.5e-3, 4000)
    path = write_csv(tmp_path / "j.csv", {"t": instants, **slow_signals(instants)})
    recording = load_recording(path, ["T_m1", "T_m2"])
    assert recording.sample_interval == pytest.approx(ts, rel=1e-5)
    np.testing.assert_allclose(np.diff(recording.t), recording.sample_interval, rtol=1e-9)
    (note,) = recording.notes
    assert note.startswith("clock jitter: intervals scatter by up to") and "%" in note
    # Linear interpolation of a signal with |x''| <= 5 * 0.3^2 K/s^2: error <= Ts^2 x''/8.
    exact = slow_signals(recording.t)
    bound = (ts + 1e-3) ** 2 * 5.0 * 0.09 / 8.0
    assert np.max(np.abs(recording.columns["T_m1"] - exact["T_m1"])) < bound
    # The strict loader refuses it.
    with pytest.raises(InputError, match="irregular time step"):
        load_columns(path, ["T_m1"])


def test_event_driven_stamps_are_resampled_within_the_interpolation_bound(tmp_path: Path) -> None:
    """Stamps scattering by +-40 % of the interval (a logger stamping CAN frames as they come):
    once refused beyond 10 %, now resampled like any jitter, within the straight line's error
    bound for the longest interval h: h^2 max|x''| / 8."""
    rng = np.random.default_rng(6)
    ts = 0.1
    instants = np.arange(600) * ts + rng.uniform(-0.02, 0.02, 600)
    path = write_csv(tmp_path / "w.csv", {"t": instants, **slow_signals(instants)})
    recording = load_recording(path, ["T_m1", "T_m2"])
    assert recording.sample_interval == pytest.approx(ts, rel=2e-3)
    (note,) = recording.notes
    assert note.startswith("clock jitter: intervals scatter by up to") and "%" in note
    h = float(np.max(np.diff(instants)))
    bound = h**2 * 5.0 * 0.09 / 8.0
    exact = slow_signals(recording.t)
    for name in ("T_m1", "T_m2"):
        assert np.max(np.abs(recording.columns[name] - exact[name])) < bound


def test_stamps_off_a_uniform_clock_are_refused_naming_the_row(tmp_path: Path) -> None:
    """Jitter is scatter about a uniform grid: a clock that speeds up (t = k^2) or stamps
    further than a quarter interval from the grid (+-35 %) are refused, naming the row."""
    rng = np.random.default_rng(7)
    for name, stamps in (("speeding", np.arange(60.0) ** 2 * 0.01),
                         ("wild", np.arange(400) * 0.1 + rng.uniform(-0.035, 0.035, 400))):
        path = write_csv(tmp_path / f"{name}.csv", {"t": stamps, **slow_signals(stamps)})
        text = error_of(path, ["T_m1"])
        assert "irregular time step" in text and "not clock jitter" in text
        assert "line " in text and "\n" not in text


def test_dropped_rows_are_bridged_and_gaps_split_the_record(tmp_path: Path) -> None:
    t = np.arange(300) * 0.015
    keep = np.ones(t.size, dtype=bool)
    keep[100:107] = False  # 7 rows lost: a gap of 8 intervals after row 99
    keep[200:202] = False  # 2 rows lost: bridged (at most BRIDGE_ROWS)
    keep[250:254] = False  # 4 rows lost: a gap of 5 intervals
    path = write_csv(tmp_path / "g.csv", {"t": t[keep], **slow_signals(t[keep])})
    recording = load_recording(path, ["T_m1", "T_m2"])
    # on the grid again: rows 107-249 and 254-299 of the logger, the two lost ones interpolated
    assert [(s.start, s.stop) for s in recording.segments] == [(0, 100), (100, 243), (243, 289)]
    assert recording.sample_interval == pytest.approx(0.015)
    np.testing.assert_allclose(recording.t[100:243], t[107:250], atol=1e-12)
    exact = slow_signals(t[107:250])
    # a straight line over 3 intervals: error <= (3 Ts)^2 max|x''| / 8
    bound = (3 * 0.015) ** 2 * 5.0 * 0.09 / 8.0
    assert np.max(np.abs(recording.columns["T_m1"][100:243] - exact["T_m1"])) < bound
    first = str(recording.gaps[0])
    assert first == "line 102 (t = 1.485 s): gap of 0.12 s (8 intervals)"
    assert len(recording.gaps) == 2
    assert recording.notes[0] == (
        "dropped rows: 1 interval of up to 3 missing rows (longest: line 195 (t = 2.985 s): "
        "gap of 0.045 s (3 intervals)) bridged by linear interpolation: 2 of 289 rows "
        "interpolated (0.69 %; 287 rows in the file)"
    )
    assert recording.notes[1] == first + ": the record is split there"
    with pytest.raises(InputError) as info:
        recording.require_contiguous("characterise")
    text = str(info.value)
    assert text.startswith(f"{path}: line 102 (t = 1.485 s): gap of 0.12 s (8 intervals)")
    assert "and 1 more" in text and "characterise needs a record without gaps" in text
    # the strict loader refuses a lost row
    with pytest.raises(InputError, match="irregular time step"):
        load_columns(path, ["T_m1"])


def test_units_row_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "units.csv"
    path.write_text("t,T_m1,T_m2\ns,degC,degC\n" + "".join(f"{k},1,{k}\n" for k in range(20)))
    text = error_of(path, ["T_m1", "T_m2"])
    assert "line 2: a units row under the header (s, degC, degC)" in text


def test_stamp_resolution() -> None:
    assert stamp_resolution(np.round(np.arange(30) / 3, 4)) == pytest.approx(1e-4)
    assert stamp_resolution(np.arange(10) * 0.5) == pytest.approx(0.1)
    assert stamp_resolution(np.random.default_rng(0).normal(size=10)) == 0.0


# --- Parquet ---------------------------------------------------------------------------------


def test_parquet_reads_like_csv(tmp_path: Path) -> None:
    t = np.arange(200) * 0.1
    columns = {"t": t, **slow_signals(t), "count": np.arange(200, dtype=np.int32)}
    recording = load_recording(write_parquet(tmp_path / "r.parquet", columns), ["T_m1", "count"])
    assert recording.format == "parquet" and recording.sample_interval == pytest.approx(0.1)
    np.testing.assert_array_equal(recording.columns["T_m1"], columns["T_m1"])
    np.testing.assert_array_equal(recording.columns["count"], np.arange(200.0))
    # The format is the content's, whatever the name says.
    renamed = tmp_path / "r.dat"
    renamed.write_bytes((tmp_path / "r.parquet").read_bytes())
    assert detect_format(renamed) == "parquet"


def test_parquet_errors(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    t = np.arange(50) * 0.1
    path = write_parquet(tmp_path / "p.parquet", {"t": t, "T_m1": t})
    text = error_of(path, ["T_m1", "T_m2"])
    assert "missing column 'T_m2'; available: t, T_m1" in text
    # a null reading is a missing one: refused by default, naming it (bridged on request:
    # tests/python/test_io_missing.py); a null time stamp of a timestamp column is refused
    values = pa.array([*range(10), None, *range(11, 50)], type=pa.float64())
    pq.write_table(pa.table({"t": t, "T_m1": values}), tmp_path / "null1.parquet")
    assert "row 11, column 'T_m1': missing reading" in error_of(
        tmp_path / "null1.parquet", ["T_m1"]
    )
    stamps = pa.array([*(int(k) * 100_000 for k in range(10)), None,
                       *(int(k) * 100_000 for k in range(11, 50))],
                      type=pa.timestamp("us"))
    pq.write_table(pa.table({"t": stamps, "T_m1": t}), tmp_path / "null.parquet")
    assert "row 11, column 't': missing time stamp (null)" in error_of(
        tmp_path / "null.parquet", ["T_m1"]
    )
    pq.write_table(pa.table({"t": t, "T_m1": [str(v) for v in t]}), tmp_path / "s.parquet")
    assert "holds string, not numbers" in error_of(tmp_path / "s.parquet", ["T_m1"])
    raw = path.read_bytes()
    (tmp_path / "cut.parquet").write_bytes(raw[: len(raw) // 2])
    assert "not a readable Parquet file" in error_of(tmp_path / "cut.parquet", ["T_m1"])
    (tmp_path / "text.parquet").write_text("t,T_m1\n0,1\n")
    assert "not a Parquet file" in error_of(tmp_path / "text.parquet", ["T_m1"])


def test_parquet_timestamp_time_column(tmp_path: Path) -> None:
    import pyarrow as pa
    import pyarrow.parquet as pq

    stamps = np.datetime64("2024-05-01T12:00:00", "ms") + np.arange(100) * np.timedelta64(15, "ms")
    pq.write_table(
        pa.table({"t": pa.array(stamps), "T_m1": np.arange(100.0)}), tmp_path / "ts.parquet"
    )
    recording = load_recording(tmp_path / "ts.parquet", ["T_m1"])
    assert recording.sample_interval == pytest.approx(0.015) and recording.t[0] == 0.0
    assert "seconds from its first value" in recording.notes[0]
    assert "conflicts" in error_of(tmp_path / "ts.parquet", ["T_m1"], time_unit="ms")


# --- MDF4 ------------------------------------------------------------------------------------


def two_rate_mdf(path: Path, *, flow_start: float = 0.0) -> Path:
    t10 = np.arange(0.0, 60.0, 0.1)
    t50 = np.arange(flow_start, 60.0, 0.02)
    return write_mdf(
        path,
        [(t10, slow_signals(t10)), (t50, {"flow": 10.0 + t50})],
        units={"T_m1": "degC", "T_m2": "degC", "flow": "m/s"},
    )


def test_mdf_channels_at_two_rates(tmp_path: Path) -> None:
    recording = load_recording(two_rate_mdf(tmp_path / "r.mf4"), ["T_m1", "T_m2", "flow"])
    assert recording.format == "mdf4" and recording.sample_interval == pytest.approx(0.1)
    assert recording.t.size == 600
    np.testing.assert_allclose(recording.columns["flow"], 10.0 + recording.t, atol=1e-9)
    np.testing.assert_array_equal(recording.columns["T_m1"], slow_signals(recording.t)["T_m1"])
    (note,) = recording.notes
    assert note == (
        "channel 'flow' (group 1, 50 Hz) interpolated linearly onto the raster of 'T_m1' "
        "(group 0, 10 Hz)"
    )
    # The raster is the group of the channel named: here the flow's 50 Hz.
    fine = load_recording(tmp_path / "r.mf4", ["T_m1", "flow"], raster="flow")
    assert fine.sample_interval == pytest.approx(0.02) and fine.t[-1] <= 59.9 + 1e-9


def test_mdf_trims_rows_outside_another_channels_span(tmp_path: Path) -> None:
    recording = load_recording(
        two_rate_mdf(tmp_path / "late.mf4", flow_start=1.01), ["T_m1", "flow"]
    )
    assert recording.t[0] == pytest.approx(1.1) and recording.t.size == 589
    assert "raster trimmed to t = 1.1-59.9 s (11 rows at the start, 0 at the end" in (
        recording.notes[1]
    )


def test_mdf_errors(tmp_path: Path) -> None:
    path = two_rate_mdf(tmp_path / "r.mf4")
    text = error_of(path, ["T_m1", "T_x"])
    assert "missing column 'T_x'; available: T_m1, T_m2, flow" in text
    raw = path.read_bytes()
    for cut in (len(raw) // 2, 300, len(raw) - 10):
        (tmp_path / "cut.mf4").write_bytes(raw[:cut])
        assert "not a readable MDF4 file" in error_of(tmp_path / "cut.mf4", ["T_m1"])
    (tmp_path / "text.mf4").write_text("t,T_m1\n0,1\n")
    assert "not an MDF4 file" in error_of(tmp_path / "text.mf4", ["T_m1"])
    assert "conflicts with the format's unit (s)" in error_of(path, ["T_m1"], time_unit="ms")


def test_format_from_content_then_extension(tmp_path: Path) -> None:
    (tmp_path / "unfinished.dat").write_bytes(b"UnFinMF 4.10    " + bytes(48))
    assert detect_format(tmp_path / "unfinished.dat") == "mdf4"
    (tmp_path / "plain.txt").write_text("t,x\n0,1\n")
    assert detect_format(tmp_path / "plain.txt") == "csv"
    assert detect_format(tmp_path / "absent.mf4") == "csv"  # then "no such file" from the reader
    assert "no such file" in error_of(tmp_path / "absent.mf4", ["x"])
