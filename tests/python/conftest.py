"""Shared pytest fixtures (keep this file small)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

# Run from a source checkout before `pip install -e .`: only then put python/ on the path,
# so an installed package (with its compiled dualprobe._core) is never shadowed.
if importlib.util.find_spec("dualprobe") is None:
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "python"))


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator: tests are reproducible."""
    return np.random.default_rng(20240611)
