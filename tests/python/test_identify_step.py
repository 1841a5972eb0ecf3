"""Plunge tests (`identify --step`) and the reference fit's offset, excitation and gain checks."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.cli import main
from dualprobe.identify import IdentificationError, fit_step, fit_transfer_function
from dualprobe.identify.step import detect_hold
from recordings import write_csv, write_parquet


def plunge(
    taus: tuple[float, ...],
    rng: np.random.Generator,
    *,
    dead_time: float,
    noise: float,
    levels: tuple[float, float] = (20.0, 100.0),
    ts: float = 0.015,
    hold: int = 5,
    quantisation: float = 0.25,
) -> tuple[np.ndarray, np.ndarray, float]:
    """A thermocouple plunged at an off-grid instant: exact response of the cascade of lags
    written out here (not the product's step_response), delayed by the dead time, noise,
    quantised, each reading held for ``hold`` rows. Returns (t, readings, response onset)."""
    pre = rng.uniform(1.0, 3.0)
    t = np.arange(int((pre + 8.0 * sum(taus) + 1.0) / ts)) * ts
    instant = pre + rng.uniform(0.0, ts)
    s = np.maximum(t - instant - dead_time, 0.0)
    if len(taus) == 1:
        g = 1.0 - np.exp(-s / taus[0])
    else:  # partial fractions of 1 / ((1 + a s)(1 + b s)) times 1/s
        a, b = taus
        g = 1.0 - a / (a - b) * np.exp(-s / a) + b / (a - b) * np.exp(-s / b)
    clean = levels[0] + (levels[1] - levels[0]) * g
    readings = np.round((clean + noise * rng.standard_normal(t.size)) / quantisation)
    readings = readings[(np.arange(t.size) // hold) * hold] * quantisation
    return t, readings, instant + dead_time


CASES = [
    ((0.5,), (20.0, 100.0)),
    ((1.7,), (300.0, 20.0)),
    ((3.2,), (20.0, 100.0)),
    ((5.0,), (25.0, 250.0)),
    ((0.8, 0.2), (20.0, 100.0)),
    ((2.5, 0.6), (400.0, 25.0)),
    ((4.6, 1.5), (20.0, 100.0)),
]


@pytest.mark.parametrize(("taus", "levels"), CASES)
def test_plunges_identified_within_2_percent(
    taus: tuple[float, ...], levels: tuple[float, float]
) -> None:
    rng = np.random.default_rng(int(100 * sum(taus)))
    dead_time = rng.uniform(0.02, 0.08)
    t, y, onset = plunge(taus, rng, dead_time=dead_time, noise=rng.uniform(0.05, 0.1),
                         levels=levels)
    fit = fit_step(t, y)
    assert fit.order == len(taus)
    for fitted, true in zip(fit.taus, taus, strict=True):
        assert fitted == pytest.approx(true, rel=0.02)
    assert fit.hold == 5 and fit.quantisation == pytest.approx(0.25)
    # Plunge instant + dead time within one row (15 ms): only their sum is identifiable.
    assert abs(fit.onset - onset) < 0.015
    assert fit.initial_level == pytest.approx(levels[0], abs=0.1)
    assert fit.final_level == pytest.approx(levels[1], abs=0.1)
    # The reported uncertainty covers the error (loosely: quantisation is not white noise).
    assert abs(fit.taus[0] - taus[0]) < 5 * fit.taus_std[0] + 1e-3 * taus[0]


def test_order_forced_and_hold_detection() -> None:
    rng = np.random.default_rng(2)
    t, y, _ = plunge((2.0,), rng, dead_time=0.05, noise=0.05, hold=1)
    assert detect_hold(y) == (1, 0)
    fit = fit_step(t, y, order=2)
    assert fit.order == 2 and fit.taus[0] == pytest.approx(2.0, rel=0.02)
    held = np.repeat(np.arange(40.0), 3)[1:]  # refreshed on rows 2, 5, 8, ...
    assert detect_hold(held) == (3, 2)


def test_plunge_refusals() -> None:
    rng = np.random.default_rng(4)
    t = np.arange(2000) * 0.015
    with pytest.raises(IdentificationError, match="no plunge"):
        fit_step(t, 20.0 + 0.05 * rng.standard_normal(t.size))
    with pytest.raises(ValueError, match="strictly increasing"):
        fit_step(t[::-1], np.arange(t.size, dtype=float))


def run_cli(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    status = main(list(argv))
    captured = capsys.readouterr()
    return status, captured.out, captured.err


def test_cli_step_with_offset_and_gaps(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(7)
    t, y, _ = plunge((1.2,), rng, dead_time=0.04, noise=0.08, levels=(20.0, 99.6))
    keep = np.ones(t.size, dtype=bool)
    keep[300:310] = False  # a gap: the step model uses the rows' own instants
    path = write_parquet(tmp_path / "plunge.parquet", {"Time (ms)": t[keep] * 1e3, "TC": y[keep]})
    target = tmp_path / "step.json"
    argv = ["identify", str(path), "--output", "TC", "--step", "--time", "Time"]
    status, out, err = run_cli(capsys, *argv, "--offset", "--bath", "100", "--json", str(target))
    assert status == 0, err
    assert "unit ms read from the header" in out and "gap of" in out and "tau" in out
    document = json.loads(target.read_text())
    assert document["kind"] == "step" and document["order"] == 1
    assert document["taus"][0] == pytest.approx(1.2, rel=0.02)
    assert document["offset"] == pytest.approx(-0.4, abs=0.05)
    assert run_cli(capsys, *argv, "--offset")[0] == 2  # --offset needs --bath
    assert run_cli(capsys, *argv, "--input", "TC")[0] == 2
    still = 20.0 + 0.25 * (rng.random(t.size) < 0.1)
    flat = write_csv(tmp_path / "flat.csv", {"t": t, "TC": still})
    status, _, err = run_cli(capsys, "identify", str(flat), "--output", "TC", "--step")
    assert status == 3 and err.startswith("error: no plunge")


@pytest.fixture(scope="module")
def reference_record() -> dict[str, np.ndarray]:
    rng = np.random.default_rng(0)
    u = np.repeat(rng.uniform(20, 80, 12), 300)
    t = 0.01 * np.arange(u.size)
    y = sim.simulate_sensor(
        sim.GasProfile.from_samples(t, u, kind="hold"), sim.SensorModel((0.8,)), t
    )
    return {"t": t, "ref": u, "y": y + 0.02 * rng.standard_normal(t.size)}


def test_offset_between_input_and_output(reference_record: dict[str, np.ndarray]) -> None:
    record = reference_record
    fit = fit_transfer_function(0.01, record["ref"], record["y"] + 1.5, hold="zoh", offset=True)
    assert fit.offset == pytest.approx(1.5, abs=0.01)
    assert fit.taus[0] == pytest.approx(0.8, rel=0.01)
    assert fit.parameter_names[-1] == "offset" and fit.model.endswith(f" {fit.offset:+.4g}")


def test_cli_refuses_implausible_gain_and_no_excitation(
    reference_record: dict[str, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    record = dict(reference_record)
    record["volts"] = 0.041 * record["y"] - 0.5  # a sensor channel in V, not degC
    rng = np.random.default_rng(1)
    record["still"] = 20.0 + 0.05 * rng.standard_normal(record["t"].size)
    path = write_csv(tmp_path / "r.csv", record)
    base = ["identify", str(path), "--input", "ref", "--hold", "zoh"]
    status, _, err = run_cli(capsys, *base, "--output", "volts")
    assert status == 3 and "implausible for a temperature sensor" in err
    assert len(err.splitlines()) == 1
    status, out, _ = run_cli(capsys, *base, "--output", "volts", "--offset", "--any-gain")
    assert status == 0 and "offset" in out
    status, _, err = run_cli(capsys, "identify", str(path), "--input", "still", "--output", "y")
    assert status == 3 and "no excitation" in err
    assert run_cli(capsys, *base, "--output", "y")[0] == 0


def test_cli_reference_fit_refuses_a_gap(
    reference_record: dict[str, np.ndarray], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    record = {name: np.delete(values, range(500, 520)) for name, values in
              reference_record.items()}
    path = write_csv(tmp_path / "gap.csv", record)
    status, _, err = run_cli(capsys, "identify", str(path), "--input", "ref", "--output", "y")
    assert status == 2
    assert "line 502 (t = 4.99 s): gap of 0.21 s (21 intervals)" in err
    assert "identify needs a record without gaps" in err
