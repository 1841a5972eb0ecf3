"""`dualprobe bench --section pipeline` machinery on a small case: the child process runs the
real `dualprobe characterise`, its wall time and peak memory are measured (the figures
themselves are the bench's business, not a test's); the bench fails when a recording is refused."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dualprobe.cli import main
from dualprobe.workflows import pipeline


def test_pipeline_measures_a_child_characterise(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(pipeline, "uncertainty_cost", lambda: [])
    case = pipeline.PipelineCase("2 min at 10 Hz, --flow", 120.0, 10.0, 0.5, True)
    result = pipeline.bench_pipeline((case,))
    (row,) = result["cases"]
    assert row["exit_status"] == 0, row["message"]
    assert row["rows"] == 1200
    assert row["seconds"] > 0.0 and row["peak_mb"] > 10.0  # a Python process with NumPy
    assert "2 min at 10 Hz" in pipeline.pipeline_table(result)


def test_bench_fails_when_a_recording_is_refused(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # 3 s of drive cycle cannot be characterised (exit 3: no excitation); the bench reports
    # the table and the JSON, then fails with one line naming the case
    monkeypatch.setattr(pipeline, "uncertainty_cost", lambda: [])
    monkeypatch.setattr(pipeline, "PIPELINE_CASES",
                        (pipeline.PipelineCase("3 s at 10 Hz", 3.0, 10.0, 0.5, False),))
    target = tmp_path / "bench.json"
    status = main(["bench", "--section", "pipeline", "--json", str(target)])
    out, err = capsys.readouterr()
    assert status == 1
    assert "| 3 s at 10 Hz | 30 |" in out
    (line,) = err.strip().splitlines()
    assert line.startswith("error: bench pipeline: 3 s at 10 Hz: characterise exited 3 (error:")
    (row,) = json.loads(target.read_text())["pipeline"]["cases"]
    assert row["exit_status"] == 3
