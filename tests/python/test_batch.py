"""`dualprobe batch`: many recordings in parallel (processes, a Dask cluster), one row per file,
tau(flow) pooled over the recordings."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.cli import main
from dualprobe.io import write_columns
from dualprobe.workflows.batch import SUMMARY_FIELDS, run_batch
from dualprobe.workflows.pool import pool_documents

EXPONENT = 0.45


def drive_cycle_files(directory: Path, count: int, *, seed: int = 0) -> list[Path]:
    """Field recordings of a flow-following pair (tau ~ v^-0.45), 5-10 min at 10 Hz."""
    rng = np.random.default_rng(seed)
    paths = []
    for index in range(count):
        conditions = sim.drive_cycle(float(rng.uniform(300.0, 600.0)), rng=rng)
        recording = sim.simulate_field_pair(
            conditions,
            sim.FieldSensor(tau_ref=float(rng.uniform(1.5, 2.5)), exponent=EXPONENT,
                            noise_std=0.05),
            sim.FieldSensor(tau_ref=float(rng.uniform(5.0, 7.0)), exponent=EXPONENT,
                            noise_std=0.05),
            sample_rate=10.0,
            rng=rng,
        )
        path = directory / f"cycle{index:02d}.csv"
        recording.to_csv(str(path), truth=False)
        paths.append(path)
    return paths


def broken_file(directory: Path) -> Path:
    path = directory / "broken.csv"
    path.write_text("t,T_m1,T_m2\n0,1,2\n0.1,x,3\n")
    return path


def read_summary(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def power_law_document(rng: np.random.Generator, exponent: float, v_ref: float) -> dict[str, Any]:
    m_std = float(rng.uniform(0.01, 0.05))
    taus = [2.0 * (1 + 0.01 * rng.standard_normal()), 6.0 * (1 + 0.01 * rng.standard_normal())]
    return {
        "sensors": [
            {"column": "T_m1", "time_constants": [taus[0]], "time_constants_std": [0.02]},
            {"column": "T_m2", "time_constants": [taus[1]], "time_constants_std": [0.06]},
        ],
        "flow_model": {
            "kind": "power_law",
            "exponent": exponent + m_std * rng.standard_normal(),
            "exponent_std": m_std,
            "reference_flow": v_ref,
            "flow_range": [v_ref / float(rng.uniform(2, 3)), v_ref * float(rng.uniform(2, 3))],
        },
    }


def test_pooling_weights_by_uncertainty() -> None:
    rng = np.random.default_rng(1)
    documents = [power_law_document(rng, EXPONENT, 20.0) for _ in range(40)]
    # A recording whose flow model is uncertain barely moves the pool.
    wild = power_law_document(rng, 1.5, 20.0)
    wild["flow_model"]["exponent_std"] = 5.0
    wild["sensors"][0]["time_constants_std"] = [50.0]
    wild["sensors"][1]["time_constants_std"] = [50.0]
    for document in documents:
        document["flow_model"]["delay"] = 0.3 + 0.02 * float(rng.standard_normal())
    wild["flow_model"]["delay"] = -1.9  # one law that absorbed something else
    pooled = pool_documents([*documents, wild])
    assert pooled["n_with_flow_model"] == 41
    delay = pooled["flow_delay"]
    assert delay["n"] == 41 and delay["median"] == pytest.approx(0.3, abs=0.02)
    assert delay["min"] == -1.9
    for sensor, tau in zip(pooled["sensors"], (2.0, 6.0), strict=True):
        assert sensor["weighting"] == "inverse-variance"
        assert sensor["exponent"] == pytest.approx(EXPONENT, abs=0.01)
        assert sensor["time_constant"] == pytest.approx(tau, rel=0.01)
        curve = sensor["curve"]
        assert curve["exponent"] == pytest.approx(EXPONENT, abs=0.01)
        assert 0 < curve["exponent_std"] < 0.05
        flow, taus = np.array(curve["flow"]), np.array(curve["time_constants"])
        covered = np.array(curve["n_recordings"]) >= 5  # the ends: a few recordings' support
        assert np.count_nonzero(covered) > 15
        np.testing.assert_allclose(
            taus[covered], tau * (flow[covered] / 20.0) ** -EXPONENT, rtol=0.03
        )
        assert max(curve["n_recordings"]) == 41 and min(curve["n_recordings"]) >= 1
    # Curves instead of power laws; missing keys are NaN, not errors.
    flow = [5.0, 10.0, 20.0, 40.0]
    curve_doc = {"sensors": [{"time_constants": [2.0]}, {"time_constants": [6.0]}],
                 "flow_model": {"kind": "table", "curve": {
                     "flow": flow,
                     "time_constants": [[2.0 * (v / 20) ** -0.5 for v in flow],
                                        [6.0 * (v / 20) ** -0.5 for v in flow]]}}}
    pooled = pool_documents([curve_doc, curve_doc, curve_doc, {"sensors": []}])
    first = pooled["sensors"][0]
    assert first["weighting"] == "equal (no uncertainties)" and math.isnan(first["exponent"])
    assert pooled["flow_delay"]["n"] == 0 and math.isnan(pooled["flow_delay"]["median"])
    assert first["curve"]["exponent"] == pytest.approx(0.5, abs=1e-9)


def test_batch_local_processes_with_a_broken_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    files = [*drive_cycle_files(tmp_path, 4, seed=3), broken_file(tmp_path)]
    out = tmp_path / "out"
    status = main(["batch", *map(str, files), "--out", str(out), "--workers", "2"])
    printed = capsys.readouterr().out
    assert status == 0
    assert "5 recordings (2 local worker(s)): 4 ok, 1 failed" in printed
    rows = read_summary(out / "summary.csv")
    assert [row["file"] for row in rows] == [str(f) for f in files]  # input order
    assert tuple(rows[0]) == SUMMARY_FIELDS
    assert [row["status"] for row in rows] == ["ok"] * 4 + ["error"]
    assert "line 3, column 'T_m1': not a number: 'x'" in rows[-1]["error"]
    for row in rows[:4]:
        assert 1.0 < float(row["tau1"]) < 4.0 and 3.0 < float(row["tau2"]) < 12.0
        assert float(row["wall_time_s"]) > 0
    pooled = json.loads((out / "pooled.json").read_text())
    assert pooled["n_recordings"] == 4 and pooled["failed"][0]["status"] == "error"
    assert pooled["sensors"][0]["n_recordings"] == 4
    assert pooled["mean_wall_time_per_recording_s"] > 0
    # Nothing usable at all: exit 3 after writing the summary.
    assert main(["batch", str(files[-1]), "--out", str(out), "--workers", "1", "--quiet"]) == 3


def test_batch_on_a_dask_cluster(tmp_path: Path) -> None:
    from distributed import LocalCluster

    files = [*drive_cycle_files(tmp_path, 2, seed=5), broken_file(tmp_path)]
    with LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster:
        result = run_batch(files, tmp_path / "dask", scheduler=cluster.scheduler_address,
                           progress=False)
    assert [r.status for r in result.results] == ["ok", "ok", "error"]
    assert "Dask scheduler" in result.summary()
    rows = read_summary(tmp_path / "dask" / "summary.csv")
    assert len(rows) == 3 and rows[0]["status"] == "ok"


@pytest.mark.slow
def test_batch_of_50_drive_cycles_pools_the_flow_exponent(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Needs the flow model in the characterisation (``characterise_file(flow=...)`` and the
    ``flow_model`` / ``*_std`` keys of its JSON document)."""
    files = [*drive_cycle_files(tmp_path, 50, seed=11), broken_file(tmp_path)]
    out = tmp_path / "out"
    status = main(
        ["batch", *map(str, files), "--flow", "flow", "--out", str(out), "--workers", "2"]
    )
    printed = capsys.readouterr().out
    print(printed)
    assert status == 0
    rows = read_summary(out / "summary.csv")
    assert [row["status"] for row in rows].count("ok") == 50, [r["error"] for r in rows][:3]
    assert rows[-1]["status"] == "error" and rows[-1]["error"]
    assert all(float(row["wall_time_s"]) > 0 for row in rows[:50])
    assert "s per recording in its worker" in printed
    pooled = json.loads((out / "pooled.json").read_text())
    assert pooled["n_with_flow_model"] == 50
    for sensor in pooled["sensors"]:
        assert sensor["curve"]["exponent"] == pytest.approx(EXPONENT, abs=0.03)


def pickup_file(source: Path, directory: Path) -> Path:
    """``source`` with 0.2 K of 0.05 Hz pickup on sensor 2 only: the sensors see different
    temperatures, which no sensor model explains (characterise: misfit 5.8 x the noise)."""
    data = np.genfromtxt(source, delimiter=",", names=True)
    columns = {name: np.asarray(data[name]) for name in data.dtype.names or ()}
    columns["T_m2"] = columns["T_m2"] + 0.2 * np.sin(2.0 * np.pi * columns["t"] / 20.0)
    path = directory / "pickup.csv"
    write_columns(path, columns)
    return path


def test_a_file_the_model_check_rejects_is_warned_and_not_pooled(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A batch wrote "ok" for every characterisation that ran, warning or not, and pooled its
    time constants into the calibration; `characterise` on the same file says "warning: the
    identified model does not explain the data". One verdict per record: the batch's is
    `characterise`'s (gas reconstructed to judge it), a failed check is "warned", with its
    reasons, and the file is left out of pooled.json."""
    good = drive_cycle_files(tmp_path, 2, seed=3)
    files = [*good, pickup_file(good[0], tmp_path)]
    out = tmp_path / "out"
    status = main(["batch", *map(str, files), "--flow", "flow", "--out", str(out), "--workers",
                   "1", "--quiet"])
    assert status == 0
    rows = read_summary(out / "summary.csv")
    assert tuple(rows[0]) == SUMMARY_FIELDS
    assert [row["status"] for row in rows] == ["ok", "ok", "warned"]
    assert "does not explain the data" in rows[2]["warnings"] and rows[2]["error"] == ""
    assert rows[0]["warnings"] == ""
    pooled = json.loads((out / "pooled.json").read_text())
    assert pooled["n_recordings"] == 2 and pooled["files"] == [str(f) for f in good]
    assert pooled["excluded"][0]["file"] == str(files[2])
    # the same verdicts from `characterise`, file by file
    for path, row in zip(files, rows, strict=True):
        document = tmp_path / (path.stem + ".json")
        assert main(["characterise", str(path), "--flow", "flow", "--json", str(document)]) == 0
        adequate = json.loads(document.read_text())["model_check"]["adequate"]
        assert adequate == (row["status"] == "ok")
    capsys.readouterr()
    # nothing to pool: exit 3 naming why
    assert main(["batch", str(files[2]), "--flow", "flow", "--out", str(tmp_path / "none"),
                 "--workers", "1", "--quiet"]) == 3
    assert "no recording's model check passed" in capsys.readouterr().err
