"""The flow column's timing (dualprobe.estimation.flow_timing): a shift in time, the delay
profile's minimum (held values: test_held.py)."""

from __future__ import annotations

import math

import numpy as np

from dualprobe.estimation.flow import check_flow
from dualprobe.estimation.flow_timing import delay_profile, shifted


def test_shifted_is_the_flow_later_in_time() -> None:
    ts = 0.1
    ramp = 5.0 + 0.2 * np.arange(200)
    signal = check_flow(ramp, "mdot", ramp.size)
    later = shifted(signal, 0.25, ts)
    # v(t - 0.25 s): 2.5 rows earlier on the ramp; the ends held, the reference unchanged
    np.testing.assert_allclose(later.values[3:], ramp[3:] - 0.2 * 2.5, atol=1e-12)
    assert later.values[0] == ramp[0] and later.reference == signal.reference
    np.testing.assert_allclose(shifted(signal, -0.5, ts).values[:-5], ramp[:-5] + 1.0)
    assert shifted(signal, 0.0, ts) is signal


def test_the_delay_profile_finds_the_minimum_within_the_range() -> None:
    calls: list[float] = []

    def misfit(d: float) -> float:
        calls.append(d)
        return 1.0 + (d - 0.37) ** 2

    d, value = delay_profile(misfit, 0.1)
    assert abs(d - 0.37) < 0.01 and value < 1.0001
    assert len(calls) < 40  # the grid (17) and Brent, not a fine scan
    d, value = delay_profile(lambda d: 1.0 + (d + 0.83) ** 2, 0.1)
    assert abs(d + 0.83) < 0.01
    d, value = delay_profile(lambda d: math.inf, 0.1)
    assert math.isnan(d) and value == math.inf
