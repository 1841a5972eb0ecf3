"""`dualprobe demo`: writes a report and a figure, and its numbers are right."""

from __future__ import annotations

from pathlib import Path

import pytest

from dualprobe.cli import main

pytest.importorskip("dualprobe.estimation", reason="estimation module not written yet")
pytest.importorskip("dualprobe.reconstruction", reason="reconstruction module not written yet")


@pytest.mark.slow
def test_demo_writes_report_and_figure(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from dualprobe.demo import run_demo

    out = tmp_path / "demo"
    status = main(["demo", "--out", str(out)])
    captured = capsys.readouterr()
    assert status == 0, captured.err
    report, figure = out / "report.md", out / "demo.png"
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    text = report.read_text()
    assert "demo.png" in text and "12.48" in text
    assert "tau" in captured.out and "reconstruction RMSE" in captured.out

    result = run_demo(tmp_path / "again")
    # 1200 s of 10 Hz data, gas steps of tens to hundreds of kelvin, 0.05 K noise: the issue's
    # acceptance for this kind of recording is 3 % on both time constants.
    assert abs(result.tau_errors[0]) < 0.03
    assert abs(result.tau_errors[1]) < 0.03
    # Issue 7: with steps the reconstruction must be far better than the fast sensor itself
    # (at most 6 % of its RMSE at 0.1 K noise; the demo has half that noise).
    assert result.rmse_reconstruction < 0.06 * result.rmse_fast_sensor
    assert result.seconds < 60.0  # the issue: under a minute
