"""`dualprobe bench --section pipeline`: the whole `characterise` at recording scale.

Each case writes a simulated recording as CSV (a drive cycle from
:mod:`dualprobe.simulate.drive_cycle`: load-following gas, 0.05 K noise, 0.02 K ADC steps),
runs ``dualprobe characterise --json --output`` on it (estimation, uncertainties, the
smoother's reconstruction) in a child process exactly as a user would, and reports
the child's wall time, its peak resident memory (``ru_maxrss`` from ``wait4``) and the rows per
second. The constant-time-constant cases (10 min, 1 h and 6 h at 100 Hz) show the cost's
growth with length; the flow case (30 min at 10 Hz, time constants following the gas velocity,
``--flow``) the field path, with both sensors sheathed its order-2 law, and the same without
the flow column and with gains 0.97/1.03 the tracking with its searched static map, or with a
sheathed fast sensor the sheathed path. (The core's streaming rate against memory bandwidth is
the throughput section's.)
"""

from __future__ import annotations

import math
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dualprobe import simulate as sim
from dualprobe.io.csv import write_columns

__all__ = [
    "PIPELINE_CASES",
    "PipelineCase",
    "bench_pipeline",
    "pipeline_failures",
    "pipeline_table",
    "uncertainty_cost",
]


@dataclass(frozen=True)
class PipelineCase:
    label: str
    duration: float  # s
    rate: float  # Hz
    exponent: float  # time constants ~ velocity^-exponent (0: constant)
    flow: bool  # pass the flow column with --flow
    gains: tuple[float, float] = (1.0, 1.0)  # the sensors' static gains
    sheaths: tuple[float, float] = (0.0, 0.0)  # sheath time constants at the reference flow


PIPELINE_CASES = (
    PipelineCase("10 min at 100 Hz", 600.0, 100.0, 0.0, False),
    PipelineCase("1 h at 100 Hz", 3600.0, 100.0, 0.0, False),
    PipelineCase("6 h at 100 Hz", 21600.0, 100.0, 0.0, False),
    PipelineCase("30 min at 10 Hz, --flow", 1800.0, 10.0, 0.5, True),
    # both sensors sheathed: the order-2 law and the level term's searches (issue 11's 5 s)
    PipelineCase("30 min at 10 Hz, --flow, sheaths 0.3/0.6 s", 1800.0, 10.0, 0.5, True,
                 sheaths=(0.3, 0.6)),
    # no flow column and unequal gains: tracked time constants with a searched static map
    PipelineCase("30 min at 10 Hz, tracked, gains 0.97/1.03", 1800.0, 10.0, 0.5, False,
                 (0.97, 1.03)),
    # no flow column, a sheathed fast sensor: the sheathed path (crossfit + psi_map)
    PipelineCase("30 min at 10 Hz, tracked, sheath 0.7 s", 1800.0, 10.0, 0.5, False,
                 sheaths=(0.7, 0.0)),
    # the same at 50 Hz: 90,000 rows, over the sheathed path's limit, so on block means
    PipelineCase("30 min at 50 Hz, tracked, sheath 0.7 s", 1800.0, 50.0, 0.5, False,
                 sheaths=(0.7, 0.0)),
)


def _write_case(case: PipelineCase, path: Path, seed: int) -> int:
    rng = np.random.default_rng(seed)
    conditions = sim.drive_cycle(case.duration, rng)
    rec = sim.simulate_field_pair(
        conditions,
        sim.FieldSensor(4.0, case.exponent, case.sheaths[0], gain=case.gains[0]),
        sim.FieldSensor(12.0, case.exponent, case.sheaths[1], gain=case.gains[1]),
        sample_rate=case.rate,
        quantisation=0.02, rng=rng)
    columns = {"t": rec.t, "T_m1": rec.t1, "T_m2": rec.t2}
    if case.flow:
        columns["flow"] = rec.flow
    write_columns(path, columns)
    return int(rec.t.size)


# Measures one command from a small intermediate process: a child's ru_maxrss on Linux
# includes the memory of the process it was forked from (counted again at exec), so forking
# the command from this (large) process would add this process's size to the figure.
_MEASURE = """
import os, sys, time
start = time.perf_counter()
pid = os.fork()
if pid == 0:
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 1)
    os.execv(sys.argv[1], sys.argv[1:])
_, status, usage = os.wait4(pid, 0)
print(time.perf_counter() - start, usage.ru_maxrss, os.waitstatus_to_exitcode(status))
"""


def _run_child(command: list[str]) -> tuple[float, float, int, str]:
    """Wall time (s), peak RSS (MB), exit status and the last stderr line of a command."""
    with tempfile.TemporaryFile() as err:
        done = subprocess.run([sys.executable, "-c", _MEASURE, *command], stdout=subprocess.PIPE,
                              stderr=err, check=True, text=True)
        wall, peak_kb, status = done.stdout.split()
        err.seek(0)
        lines = err.read().decode(errors="replace").strip().splitlines()
    # ru_maxrss is in kilobytes on Linux
    return float(wall), float(peak_kb) / 1024.0, int(status), lines[-1] if lines else ""


def uncertainty_cost(seed: int = 3, repeats: int = 3) -> list[dict[str, Any]]:
    """What the standard uncertainties add to ``characterise`` (estimation and smoother), in
    process, best of ``repeats``: a 30 min, 10 Hz drive cycle with and without its flow, and
    10 min of laboratory multisteps at 5 Hz."""
    from dualprobe.workflows.characterise import characterise_arrays

    rng = np.random.default_rng(seed)
    drive = sim.simulate_field_pair(sim.drive_cycle(1800.0, rng), sim.FieldSensor(4.0, 0.5),
                                    sim.FieldSensor(12.0, 0.5), sample_rate=10.0,
                                    quantisation=0.02, rng=rng)
    profile = sim.multistep_profile(600.0, mean=300.0, amplitude=5.0, mean_hold=50.0, rng=rng)
    lab = sim.simulate_pair(profile, sim.SensorModel((5.0,)), sim.SensorModel((15.0,)),
                            ts=0.2, duration=600.0, noise_std=0.05, rng=rng)
    cases = [("drive cycle 30 min at 10 Hz, flow", drive.t1, drive.t2, drive.ts, drive.flow),
             ("drive cycle 30 min at 10 Hz, tracked", drive.t1, drive.t2, drive.ts, None),
             ("laboratory steps 10 min at 5 Hz", lab.t1, lab.t2, lab.ts, None)]
    rows = []
    for label, t1, t2, ts, flow in cases:
        seconds = {}
        for with_uncertainty in (False, True):
            best = math.inf
            for _ in range(repeats):
                start = time.perf_counter()
                characterise_arrays(t1, t2, ts, flow=flow, flow_column=None if flow is None
                                    else "flow", uncertainty=with_uncertainty,
                                    reconstruction="smoother")
                best = min(best, time.perf_counter() - start)
            seconds[with_uncertainty] = best
        rows.append({"case": label, "seconds_without": seconds[False],
                     "seconds_with": seconds[True],
                     "added_percent": 100.0 * (seconds[True] / seconds[False] - 1.0)})
    return rows


def bench_pipeline(cases: tuple[PipelineCase, ...] = PIPELINE_CASES, *, seed: int = 1,
                   workdir: str | os.PathLike[str] | None = None) -> dict[str, Any]:
    """Run ``dualprobe characterise`` on each case's recording; see the module docstring."""
    rows: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory(dir=workdir) as tmp:
        for i, case in enumerate(cases):
            path = Path(tmp) / f"case{i}.csv"
            n = _write_case(case, path, seed + i)
            command = [sys.executable, "-m", "dualprobe", "characterise", str(path),
                       "--json", str(Path(tmp) / f"case{i}.json"),
                       "--output", str(Path(tmp) / f"case{i}_gas.csv")]
            if case.flow:
                command += ["--flow", "flow"]
            wall, peak, status, last = _run_child(command)
            rows.append({"case": case.label, "rows": n, "csv_mb": path.stat().st_size / 2**20,
                         "seconds": wall, "peak_mb": peak, "rows_per_s": n / wall,
                         "exit_status": status, "message": last if status else ""})
            path.unlink()
    per_row = {r["case"]: r["seconds"] / r["rows"] for r in rows}
    result: dict[str, Any] = {"cases": rows, "uncertainty_cost": uncertainty_cost()}
    if "1 h at 100 Hz" in per_row and "6 h at 100 Hz" in per_row:
        # linear cost: the time per row at 6 h over that at 1 h stays near 1
        result["time_per_row_6h_vs_1h"] = per_row["6 h at 100 Hz"] / per_row["1 h at 100 Hz"]
    return result


def pipeline_failures(result: dict[str, Any]) -> list[str]:
    """One line per case whose ``characterise`` did not exit 0. The bench fails on any: a
    refused pipeline recording is a regression, not a slow row (the sheathed no-flow case went
    to exit 3 on 2026-11-30 after CI had passed, and only the table's exit column showed it)."""
    return [f"{r['case']}: characterise exited {r['exit_status']} ({r['message']})"
            for r in result["cases"] if r["exit_status"] != 0]


def pipeline_table(result: dict[str, Any]) -> str:
    lines = ["| recording | rows | CSV MB | wall s | peak MB | rows/s | exit |",
             "|---|---|---|---|---|---|---|"]
    for r in result["cases"]:
        lines.append(f"| {r['case']} | {r['rows']} | {r['csv_mb']:.1f} | {r['seconds']:.2f} | "
                     f"{r['peak_mb']:.0f} | {r['rows_per_s']:.3g} | {r['exit_status']} |")
    for r in result.get("uncertainty_cost", []):
        lines.append(f"uncertainties, {r['case']}: {r['seconds_without']:.2f} s -> "
                     f"{r['seconds_with']:.2f} s ({r['added_percent']:+.0f} %)")
    if "time_per_row_6h_vs_1h" in result:
        lines.append(f"time per row, 6 h / 1 h: {result['time_per_row_6h_vs_1h']:.2f}")
    return "\n".join(lines)
