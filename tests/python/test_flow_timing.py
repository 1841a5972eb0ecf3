"""The flow column's timing (dualprobe.estimation.flow_timing): held values interpolated
between refreshes, a shift in time, the delay profile's minimum."""

from __future__ import annotations

import math

import numpy as np

from dualprobe.estimation.flow import check_flow
from dualprobe.estimation.flow_timing import delay_profile, shifted
from dualprobe.models.held import unhold


def _smooth(n: int) -> np.ndarray:
    t = np.arange(n) * 0.1
    return 10.0 + 3.0 * np.sin(2 * math.pi * t / 37.0) + np.sin(2 * math.pi * t / 9.0)


def test_a_regular_refresh_is_interpolated_between_refreshes() -> None:
    truth = _smooth(3000)
    held = np.repeat(truth[::10], 10)[:truth.size]  # refreshed once a second at 10 Hz
    values, refresh = unhold(held, 0.1)
    assert refresh == 10
    np.testing.assert_array_equal(values[::10], truth[::10])  # the refreshes themselves
    # between them, linear interpolation: its error bound h^2/8 max|v''| = 0.072 for h = 1 s
    # (the staircase's: up to h max|v'| = 1.2)
    assert np.max(np.abs(values[:-10] - truth[:-10])) < 0.075
    assert np.max(np.abs(held - truth)) > 0.5
    # a logger whose refresh is not a whole number of rows: runs of 2 and 3
    rows = np.floor(np.arange(truth.size) / 2.5) * 2.5
    jittered = np.interp(np.ceil(rows), np.arange(truth.size), truth)
    assert unhold(jittered, 0.1)[1] in (2, 3)


def test_quantised_or_piecewise_constant_flows_are_left_alone() -> None:
    rng = np.random.default_rng(3)
    quantised = np.round(_smooth(3000) + 0.3 * rng.standard_normal(3000))  # irregular runs
    values, refresh = unhold(quantised, 0.1)
    assert refresh == 1 and np.array_equal(values, quantised)
    steps = np.repeat([10.0, 30.0, 20.0, 40.0, 15.0, 25.0, 35.0, 12.0, 22.0, 33.0],
                      [300, 120, 410, 90, 270, 330, 150, 220, 180, 230])  # a laboratory cycle
    assert unhold(steps, 0.1)[1] == 1
    assert unhold(_smooth(3000), 0.1)[1] == 1
    # a laboratory flow stepped every 60 s, exactly: regular, but no logger refreshes so slowly
    regular = np.repeat(10.0 + 5.0 * (np.arange(20) % 3), 600)
    values, refresh = unhold(regular, 0.1)
    assert refresh == 1 and np.array_equal(values, regular)


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
