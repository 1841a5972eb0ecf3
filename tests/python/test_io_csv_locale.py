"""CSV exports as loggers write them outside the dot-decimal world: a semicolon or tab with
decimal commas, and ISO 8601 date-times in the time column (dualprobe.io.csv)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dualprobe.io import InputError, load_recording


def _error(path: Path, **kwargs: object) -> str:
    with pytest.raises(InputError) as info:
        load_recording(path, ["T1", "T2"], **kwargs)  # type: ignore[arg-type]
    text = str(info.value)
    assert "\n" not in text
    return text


def _rows(count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(count) * 0.1
    return t, 500.0 + 3.0 * np.sin(0.2 * t), 499.5 + 3.0 * np.cos(0.15 * t)


@pytest.mark.parametrize("delimiter", [";", "\t"])
def test_decimal_commas_read_as_the_same_numbers(tmp_path: Path, delimiter: str) -> None:
    t, a, b = _rows(300)
    lines = [delimiter.join(("Zeit", "T1", "T2"))]
    lines += [delimiter.join(f"{v:.3f}".replace(".", ",") for v in row)
              for row in zip(t, a, b, strict=True)]
    path = tmp_path / "eu.csv"
    path.write_text("\n".join(lines) + "\n")
    recording = load_recording(path, ["T1", "T2"], time="Zeit")
    np.testing.assert_array_equal(recording.columns["T1"], np.round(a, 3))
    np.testing.assert_array_equal(recording.columns["T2"], np.round(b, 3))
    assert recording.sample_interval == pytest.approx(0.1)
    # a cell the fast reader refuses goes through the line-by-line one, which names it
    lines[101] = lines[101].replace(lines[101].split(delimiter)[1], "kaputt")
    path.write_text("\n".join(lines) + "\n")
    assert "line 102, column 'T1': not a number: 'kaputt'" in _error(path, time="Zeit")


def test_a_comma_delimited_file_keeps_the_decimal_point(tmp_path: Path) -> None:
    path = tmp_path / "us.csv"
    path.write_text("t,T1,T2\n" + "".join(f"{k / 10},{500 + k},{501 + k}\n" for k in range(50)))
    recording = load_recording(path, ["T1", "T2"])
    assert recording.columns["T1"][3] == 503.0


@pytest.mark.parametrize("zone", ["", "Z", "+01:00"])
def test_iso_date_times_become_seconds_from_the_first(tmp_path: Path, zone: str) -> None:
    t, a, b = _rows(400)
    start = np.datetime64("2026-12-01T10:00:00.000", "ms")
    stamps = [str(start + np.timedelta64(round(v * 1000), "ms")) + zone for v in t]
    stamps[7] = stamps[7].replace("T", " ")  # a space for the T is ISO 8601 too
    path = tmp_path / "stamped.csv"
    path.write_text("timestamp,T1,T2\n" + "".join(
        f"{s},{x:.4f},{y:.4f}\n" for s, x, y in zip(stamps, a, b, strict=True)))
    recording = load_recording(path, ["T1", "T2"])
    assert recording.t[0] == 0.0 and recording.sample_interval == pytest.approx(0.1)
    np.testing.assert_allclose(recording.t, t, rtol=0, atol=1e-9)
    assert any("seconds from its first value" in note for note in recording.notes)
    # the stamps carry their unit: a --time-unit beside them is a conflict
    assert "conflicts" in _error(path, time_unit="ms")


def test_bad_stamps_are_named_by_line(tmp_path: Path) -> None:
    start = np.datetime64("2026-12-01T10:00:00.000", "ms")
    stamps = [str(start + np.timedelta64(100 * k, "ms")) for k in range(60)]
    path = tmp_path / "bad.csv"

    def write(cells: list[str]) -> Path:
        path.write_text("timestamp,T1,T2\n" + "".join(f"{s},1.0,2.0\n" for s in cells))
        return path

    assert "line 12, column 'timestamp': not an ISO 8601 date and time: '10:00:01'" in _error(
        write([*stamps[:10], "10:00:01", *stamps[11:]]))
    assert "line 5, column 'timestamp': missing time stamp" in _error(
        write([*stamps[:3], "", *stamps[4:]]))
    zoned = [s + "Z" for s in stamps]
    assert "line 9, column 'timestamp'" in (text := _error(write(zoned[:7] + stamps[7:])))
    assert "give every stamp a zone or none" in text


def test_the_cli_characterises_a_european_export(tmp_path: Path) -> None:
    """End to end: a semicolon file with decimal commas and ISO stamps, as a German logger
    exports it, through ``dualprobe characterise`` (exit 0, the stamps' note)."""
    rng = np.random.default_rng(5)
    t = np.arange(3000) * 0.1
    gas = 500.0 + 40.0 * np.sin(2 * np.pi * t / 50.0) + 15.0 * np.sin(2 * np.pi * t / 11.0)
    readings = []
    for tau in (2.0, 6.0):  # first-order sensors, exact for a gas linear between rows
        y = np.empty_like(gas)
        y[0] = gas[0]
        a = np.exp(-0.1 / tau)
        for k in range(1, gas.size):
            y[k] = a * y[k - 1] + (1 - a) * gas[k]
        readings.append(y + 0.03 * rng.standard_normal(gas.size))
    start = np.datetime64("2026-12-01T10:00:00.000", "ms")
    path = tmp_path / "export.csv"
    rows = [";".join((str(start + np.timedelta64(100 * k, "ms")),
                      f"{x:.3f}".replace(".", ","), f"{y:.3f}".replace(".", ",")))
            for k, (x, y) in enumerate(zip(*readings, strict=True))]
    path.write_text("Zeitstempel;T_m1;T_m2\n" + "\n".join(rows) + "\n")
    assert rows[1] == "2026-12-01T10:00:00.100;" + rows[1].split(";", 1)[1]
    assert "," in rows[1] and "." not in rows[1].split(";", 1)[1]
    # as German loggers write the seconds too: every stamp with a decimal comma
    rows = [row.replace(".", ",", 1) for row in rows]
    assert rows[1].startswith("2026-12-01T10:00:00,100;")
    done = subprocess.run([sys.executable, "-m", "dualprobe", "characterise", str(path),
                           "--time", "Zeitstempel"], capture_output=True, text=True,
                          check=False)
    assert done.returncode == 0, done.stderr
    assert "ISO 8601 date and time" in done.stdout + done.stderr
    assert "time constant 2.0" in done.stdout and "time constant 6.0" in done.stdout
