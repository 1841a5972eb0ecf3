"""A tracked schedule held where the gas stands still (dualprobe.estimation.still), on
hand-made readings whose still rows are known."""

from __future__ import annotations

import numpy as np
import pytest

from dualprobe.estimation import still


def _readings(rows: int, still_rows: slice) -> tuple[np.ndarray, np.ndarray]:
    """A ramp of 1 K per row, flat over ``still_rows``."""
    slope = np.ones(rows)
    slope[still_rows] = 0.0
    t1 = np.cumsum(slope)
    return t1, 0.5 * t1


def test_the_end_is_held_at_the_last_moving_rows_value() -> None:
    t1, t2 = _readings(400, slice(300, None))
    psi = np.exp(np.linspace(0.0, 1.0, 400))  # drifts on through the still end
    found = still.hold_still(psi, (t1, t2), reach=10, noise=0.01)
    assert found is not None
    held, share = found
    # the readings are flat from row 299 (the last step's end) on, so the range over +-10
    # rows is 0 from row 309 (1 K per row elsewhere: 100 noise deviations)
    assert share == pytest.approx(91 / 400)
    assert np.all(held[309:] == held[308])
    # the moving rows keep their shape (one common factor: the mean is restored)
    ratio = held[:309] / psi[:309]
    assert np.allclose(ratio, ratio[0], rtol=1e-12)
    assert float(np.mean(held)) == pytest.approx(float(np.mean(psi)))


def test_a_still_stretch_inside_is_linear_in_log_psi_between_its_edges() -> None:
    t1, t2 = _readings(400, slice(100, 200))
    rng = np.random.default_rng(1)
    psi = np.exp(rng.normal(0.0, 0.2, 400))
    found = still.hold_still(psi, (t1, t2), reach=5, noise=0.01)
    assert found is not None
    held, _ = found
    log_held = np.log(held)
    # flat over rows 99-199: still over +-5 rows from 104 to 194, moving at 103 and 195
    inside = np.arange(104, 195)
    line = np.interp(inside, [103, 195], log_held[[103, 195]])
    assert np.allclose(log_held[inside], line, atol=1e-12)
    # the edges keep their own value (up to the common factor)
    ratio = held[[103, 195]] / psi[[103, 195]]
    assert ratio[0] == pytest.approx(ratio[1], rel=1e-12)


def test_nothing_still_or_everything_still_holds_nothing() -> None:
    t1, t2 = _readings(200, slice(0, 0))
    assert still.hold_still(np.ones(200), (t1, t2), reach=5, noise=0.01) is None
    flat = np.full(200, 500.0)
    assert still.hold_still(np.ones(200), (flat, flat), reach=5, noise=0.01) is None


def test_the_range_is_the_larger_of_the_two_readings() -> None:
    t1 = np.zeros(50)
    t2 = np.zeros(50)
    t2[25] = 3.0
    moved = still.movement((t1, t2), reach=2)
    assert np.all(moved[23:28] == 3.0)
    assert moved[22] == 0.0 and moved[28] == 0.0
