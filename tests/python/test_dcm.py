"""DCM output (`characterise --dcm`): round trip through an independent DCM parser."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest
from dcmReader.dcm_reader import DcmReader

from dualprobe.cli import main
from dualprobe.io import EstimationError, InputError
from dualprobe.report.dcm import dcm_text, write_dcm
from recordings import write_csv


def parse(path: Path) -> DcmReader:
    reader = DcmReader()
    reader.read(str(path))
    return reader


def document(**extra: Any) -> dict[str, Any]:
    base: dict[str, Any] = {
        "method": "svf",
        "order": 1,
        "sensors": [
            {"column": "T_m1", "time_constants": [1.25], "time_constants_std": [0.01]},
            {"column": "T_m2", "time_constants": [3.5], "time_constants_std": [0.02]},
        ],
    }
    base.update(extra)
    return base


def test_festwert_without_flow_model(tmp_path: Path) -> None:
    doc = document()
    doc["sensors"][1]["time_constants"] = [3.5, 0.25]  # order 2: a second stage
    doc["sensors"][0].update(time_constants_heat=[1.1], time_constants_cool=[1.4])
    path = tmp_path / "tau.dcm"
    write_dcm(doc, path, names=("TC_FAST", "TC_SLOW"), source="run.mf4")
    values = {p.name: (p.value, p.unit, p.description) for p in parse(path).get_parameters()}
    assert values["TC_FAST"] == (1.25, "s", "Time constant of sensor 1 (T_m1)")
    assert values["TC_SLOW"][0] == 3.5 and values["TC_SLOW_2"][0] == 0.25
    assert values["TC_FAST_HEAT"][0] == 1.1 and values["TC_FAST_COOL"][0] == 1.4
    assert path.read_text().splitlines()[3] == "KONSERVIERUNG_FORMAT 2.0"


def test_kennlinie_from_the_curve_and_from_the_power_law(tmp_path: Path) -> None:
    flow = [5.0, 10.0, 20.0, 40.0, 60.0, 80.0, 100.0]
    curve = {"flow": flow, "time_constants": [[2.0 * (v / 20) ** -0.45 for v in flow],
                                               [[5.0 * (v / 20) ** -0.5, 0.1] for v in flow]]}
    model = {"kind": "power_law", "exponent": 0.45, "reference_flow": 20.0, "curve": curve,
             "unit": "m/s"}
    path = tmp_path / "curve.dcm"
    write_dcm(document(flow_model=model), path)
    (first, second) = parse(path).get_characteristic_lines()
    assert first.name == "DP_TAU_S1" and first.unit_x == "m/s" and first.unit_values == "s"
    assert list(first.values) == flow  # ST/X over two lines of six
    np.testing.assert_allclose(list(first.values.values()), curve["time_constants"][0], atol=1e-6)
    np.testing.assert_allclose(list(second.values.values()),
                               [5.0 * (v / 20) ** -0.5 for v in flow], atol=1e-6)

    # Power law only (no curve): tau_ref at the reference flow, one exponent per sensor.
    model = {"kind": "power_law", "exponent": [0.4, 0.6], "reference_flow": 20.0,
             "flow_range": [5.0, 80.0]}
    write_dcm(document(flow_model=model), path, flow_unit="kg/h")
    lines = parse(path).get_characteristic_lines()
    for line, tau, exponent in zip(lines, (1.25, 3.5), (0.4, 0.6), strict=True):
        grid = np.array(list(line.values))
        assert grid[0] == 5.0 and grid[-1] == 80.0 and line.unit_x == "kg/h"
        np.testing.assert_allclose(list(line.values.values()), tau * (grid / 20.0) ** -exponent,
                                   atol=1e-6)
    # A constant flow model is a FESTWERT.
    write_dcm(document(flow_model={"kind": "constant"}), path)
    assert [p.name for p in parse(path).get_parameters()] == ["DP_TAU_S1", "DP_TAU_S2"]


def test_a_flow_delay_is_a_festwert_per_sensor(tmp_path: Path) -> None:
    model = {"kind": "power_law", "exponent": 0.5, "reference_flow": 20.0,
             "flow_range": [5.0, 80.0], "delay": 0.35}
    path = tmp_path / "delay.dcm"
    write_dcm(document(flow_model=model), path)
    values = {p.name: (p.value, p.unit) for p in parse(path).get_parameters()}
    assert values["DP_TAU_S1_FLOW_DELAY"] == (0.35, "s")
    assert values["DP_TAU_S2_FLOW_DELAY"] == (0.35, "s")
    write_dcm(document(flow_model={**model, "delay": 0.0}), path)  # no delay: no entry
    assert not [p.name for p in parse(path).get_parameters() if "DELAY" in p.name]


def test_refusals() -> None:
    with pytest.raises(InputError, match="letters, digits"):
        dcm_text(document(), names=("TAU 1", "TAU2"))
    with pytest.raises(InputError, match="one per sensor"):
        dcm_text(document(), names=("TAU1",))
    doc = document()
    doc["sensors"][0]["time_constants"] = [None]
    with pytest.raises(EstimationError, match="not finite"):
        dcm_text(doc)


def test_characterise_writes_dcm(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    ts, rows = 0.1, 3000
    t = np.arange(rows) * ts
    gas = 300.0 + 50.0 * np.sign(np.sin(2 * np.pi * t / 60.0))
    t1, t2 = np.empty(rows), np.empty(rows)
    t1[0] = t2[0] = gas[0]
    a1, a2 = np.exp(-ts / 2.0), np.exp(-ts / 6.0)
    for k in range(1, rows):
        t1[k] = a1 * t1[k - 1] + (1 - a1) * gas[k - 1]
        t2[k] = a2 * t2[k - 1] + (1 - a2) * gas[k - 1]
    path = write_csv(tmp_path / "pair.csv", {"t": t, "T_m1": t1, "T_m2": t2})
    target = tmp_path / "out.dcm"
    argv = ["characterise", str(path), "--dcm", str(target), "--dcm-names", "TAU_A,TAU_B"]
    assert main(argv) == 0, capsys.readouterr().err
    values = {p.name: p.value for p in parse(target).get_parameters()}
    assert values["TAU_A"] == pytest.approx(2.0, rel=0.01)
    assert values["TAU_B"] == pytest.approx(6.0, rel=0.01)
    assert main([*argv[:-2], "--dcm-names", "ONE"]) == 2
