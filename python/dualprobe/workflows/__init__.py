"""The pipelines the command line runs: :mod:`~dualprobe.workflows.characterise` (load,
estimate, reconstruct, report), :mod:`~dualprobe.workflows.demo` (simulate and characterise a
Pt-100 pair) and :mod:`~dualprobe.workflows.bench` (throughput and the noise study)."""

from __future__ import annotations
