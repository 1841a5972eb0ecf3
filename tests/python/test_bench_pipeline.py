"""`dualprobe bench --section pipeline` machinery on a small case: the child process runs the
real `dualprobe characterise`, its wall time and peak memory are measured (the figures
themselves are the bench's business, not a test's)."""

from __future__ import annotations

import pytest

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
