"""A channel stuck on one value (an open circuit, a frozen channel) is refused by name, with
the stretch to keep; legitimate flat stretches (a slow sensor at a turning point behind a
coarse ADC, a logger's refresh, laboratory plateaus) are not."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.io import write_columns
from dualprobe.models.stuck import find_stuck
from field_independent import record
from test_cli_characterise import assert_one_error_line, run_cli


def _drive(seed: int, rate: float = 10.0, adc: float = 0.02, hold: int = 1,
           ) -> sim.FieldRecording:
    rng = np.random.default_rng(seed)
    conditions = sim.drive_cycle(600.0, rng)
    return sim.simulate_field_pair(conditions, sim.FieldSensor(4.0, 0.5, noise_std=0.05),
                                   sim.FieldSensor(14.0, 0.5, noise_std=0.05),
                                   sample_rate=rate, quantisation=adc, hold=hold, rng=rng)


def test_an_open_circuit_is_a_dropout_and_a_frozen_channel_is_frozen() -> None:
    rec = _drive(11)
    rows = rec.t.size
    dropout = rec.t1.copy()
    dropout[2000:2600] = 0.0  # 60 s of an open circuit read as 0
    runs = find_stuck(dropout, rec.t2, rec.ts)
    assert [(r.kind, r.start, r.rows, r.value) for r in runs] == [("dropout", 2000, 600, 0.0)]
    frozen = rec.t2.copy()
    frozen[3000:] = frozen[3000]  # the logger repeats the last frame of a lost channel
    runs = find_stuck(frozen, rec.t1, rec.ts)
    assert [(r.kind, r.start, r.rows) for r in runs] == [("frozen", 3000, rows - 3000)]
    # a slow sensor of a third of the record's duration would have moved by this much: well
    # beyond the 3 ADC steps (0.06 K) and the 0.1 K floor
    assert runs[0].movement > 1.0


@pytest.mark.parametrize("seed,rate,adc,hold,noise", [
    # the rule driving the slowest sensor from rest at the other sensor's reading flagged
    # these (1.65-2.04 K against 1.5 K): a 22 s sensor at its turning point reads one 0.5 K
    # step for 8-80 s
    (15, 1.0, 0.5, 1, 0.0), (15, 2.0, 0.5, 1, 0.05), (15, 10.0, 0.5, 1, 0.0),
    (15, 50.0, 0.5, 3, 0.005),
    # a logger's refresh and an ordinary converter
    (16, 10.0, 0.02, 3, 0.05), (17, 2.0, 0.1, 1, 0.02),
])
def test_legitimate_flat_stretches_are_not_stuck(seed: int, rate: float, adc: float,
                                                  hold: int, noise: float) -> None:
    rng = np.random.default_rng(seed)
    conditions = sim.drive_cycle(300.0, rng)
    rec = sim.simulate_field_pair(conditions, sim.FieldSensor(5.0, 0.5, noise_std=noise),
                                  sim.FieldSensor(22.0, 0.5, noise_std=noise),
                                  sample_rate=rate, quantisation=adc, hold=hold, rng=rng)
    for x, y in ((rec.t1, rec.t2), (rec.t2, rec.t1)):
        assert find_stuck(x, y, rec.ts) == []


@pytest.mark.parametrize("seed,kw", [(3, dict(rate=2.0, adc=0.1, hold=4)),
                                     (2, dict(rate=50.0, adc=0.0, noise=0.1))])
def test_the_separate_generator_has_no_stuck_channels(seed: int, kw: dict[str, float]) -> None:
    """A sweep of 432 such records (and 360 of the project's drive cycles at 1-100 Hz with
    0-0.5 K converters, 144 laboratory step records with plateaus, 14.6 M rows) found none."""
    rec = record(seed, duration=600.0, **kw)  # type: ignore[arg-type]
    assert find_stuck(rec.t2, rec.t1, rec.ts) == []
    assert find_stuck(rec.t1, rec.t2, rec.ts) == []


def test_the_command_line_names_the_stuck_channel_and_the_stretch_to_keep(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rec = _drive(11)
    t1 = rec.t1.copy()
    t1[2000:2600] = 0.0
    path = tmp_path / "dropout.csv"
    write_columns(path, {"t": rec.t, "T_m1": t1, "T_m2": rec.t2})
    status, out, err = run_cli(capsys, "characterise", str(path))
    line = assert_one_error_line(err)
    assert status == 2 and out == ""
    assert "T_m1 reads exactly 0 on 600 rows from t = 200 to 259.9 s" in line
    window = re.search(r"--window (\S+):(\S+) ", line)
    assert window is not None and window.groups() == ("260", "599.9")
    # the stretch it names characterises without the fault
    status, out, err = run_cli(capsys, "characterise", str(path), "--window",
                               f"{window[1]}:{window[2]}")
    assert status == 0, err
