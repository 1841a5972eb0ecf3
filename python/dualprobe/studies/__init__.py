"""The paper's studies and the studies beyond it (``dualprobe paper``).

:mod:`~dualprobe.studies.paper` reproduces the paper's section IV (set-up in
:mod:`~dualprobe.studies.paper_setup`, figures in :mod:`~dualprobe.studies.paper_figures`,
claims and report in :mod:`~dualprobe.studies.paper_report`);
:mod:`~dualprobe.studies.beyond` reruns its studies with the second-order and
hysteresis-aware estimation (figures and text in :mod:`~dualprobe.studies.beyond_report`);
:func:`run_paper` (:mod:`~dualprobe.studies.run`) runs both and writes the report.
"""

from __future__ import annotations

from dualprobe.studies.run import run_beyond, run_paper

__all__ = ["run_beyond", "run_paper"]
