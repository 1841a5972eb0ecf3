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


# The slowest files first (measured with --durations, 2026-12-06): xdist hands whole files out
# in collection order (`make pytest`: --dist loadfile --no-loadscope-reorder), and a slow file
# taken last leaves one core idle while the other finishes it. Ordered by their number of
# tests (xdist's default), the one-test 3-minute files came last: CI on 2026-12-06 spent 12 of
# its 21 pytest minutes on the last 5 % of the tests. Only the order changes, never a test.
_SLOWEST_FIRST = (
    "test_sheath_profile.py", "test_field_conditions.py", "test_sheathed_tracking.py",
    "test_field_independent.py", "test_sheathed_finer.py", "test_common_lag.py",
    "test_psi_level.py", "test_field_loggers.py", "test_tracked_fast_flow.py",
    "test_sheathed_found.py", "test_tracked_span.py", "test_sheathed_settled.py",
    "test_sheathed_noise_rule.py", "test_batch.py", "test_tracked_idle.py", "test_reuse.py",
)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    rank = {name: k for k, name in enumerate(_SLOWEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: within a file


@pytest.fixture
def rng() -> np.random.Generator:
    """A fixed-seed generator: tests are reproducible."""
    return np.random.default_rng(20240611)
