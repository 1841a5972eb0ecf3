"""A logger's held readings (dualprobe.models.held): a regular refresh detected (and not a
quantised or stepped signal), interpolated between refreshes (straight lines for the flow
column, a cubic for a sensor), and a sensor's noise counted once per refresh."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dualprobe.models.held import MAX_REFRESH, SENSOR_REFRESH, held_noise_std, is_held, unhold
from dualprobe.models.noise import ORDER_ESTIMATION, estimate_noise_std


def _smooth(n: int) -> np.ndarray:
    t = np.arange(n) * 0.1
    return 10.0 + 3.0 * np.sin(2 * math.pi * t / 37.0) + np.sin(2 * math.pi * t / 9.0)


def test_a_held_reading_is_interpolated_by_a_cubic() -> None:
    truth = _smooth(3000)
    held = np.repeat(truth[::10], 10)[:truth.size]  # refreshed once a second at 10 Hz
    cubic, refresh = unhold(held, 0.1, smooth=True)
    linear, _ = unhold(held, 0.1)
    assert refresh == 10
    np.testing.assert_allclose(cubic[::10], truth[::10], atol=1e-12)  # the refreshes
    inner = slice(20, -20)  # not-a-knot ends, and the open last run (held)
    # a cubic spline's error bound 5/384 h^4 max|v''''| = 0.0031 for h = 1 s; the straight
    # lines' h^2/8 max|v''| = 0.072 (they reach 0.06 here)
    assert np.max(np.abs(cubic[inner] - truth[inner])) < 0.0035
    assert np.max(np.abs(linear[inner] - truth[inner])) > 0.05
    np.testing.assert_array_equal(cubic[-5:], held[-5:])  # the last run is held


def test_a_sensor_held_longer_than_a_logger_raster_is_still_a_hold() -> None:
    """A sensor refreshed every 3 s at 1 Hz (a slow sensor's ECU): a sensor's reading lags the
    gas and so moves on every row, and a regular staircase in it is a hold up to
    ``SENSOR_REFRESH`` (5 s), where a flow column's is one up to ``MAX_REFRESH`` (2 s) only (a
    laboratory may step a flow)."""
    assert MAX_REFRESH < 3.0 <= SENSOR_REFRESH
    truth = _smooth(6000)[::10]  # 600 rows at 1 Hz
    held = np.repeat(truth[::3], 3)[:truth.size]
    assert unhold(held, 1.0)[1] == 1  # a flow's limit: left as it is
    cubic, refresh = unhold(held, 1.0, smooth=True, longest=SENSOR_REFRESH)
    assert refresh == 3 and is_held(held, 1.0, SENSOR_REFRESH)
    np.testing.assert_allclose(cubic[::3], truth[::3], atol=1e-12)
    slow = np.repeat(truth[::6], 6)[:truth.size]  # 6 s: beyond either
    assert unhold(slow, 1.0, smooth=True, longest=SENSOR_REFRESH)[1] == 1


def test_a_held_readings_noise_is_counted_once_per_refresh() -> None:
    rng = np.random.default_rng(5)
    sigma, rows = 0.1, 3
    readings = _smooth(9000) + sigma * rng.standard_normal(9000)
    held = np.repeat(readings[::rows], rows)[:readings.size]
    values, refresh = unhold(held, 0.1, smooth=True)
    assert refresh == rows
    # the refreshes are 3000 white readings: the MAD of their 4th differences has a relative
    # standard error of about 3 %; 10 % is three of those
    level = held_noise_std(held, 0.1, ORDER_ESTIMATION)
    assert abs(level / (sigma * math.sqrt(rows)) - 1.0) < 0.1
    # the interpolated rows' own differences show a fraction of it (why the refreshes count)
    assert estimate_noise_std(values, ORDER_ESTIMATION) < 0.5 * sigma
    # a noise-free ramp of one 0.1 K ADC step per refresh: its refreshes' differences are all
    # equal (no noise in them at all), yet each reading carries its rounding, q / sqrt(12)
    ramp = 0.1 * (np.arange(9000) // rows)
    floor = 0.1 / math.sqrt(12.0) * math.sqrt(rows)
    assert held_noise_std(ramp, 0.1, ORDER_ESTIMATION) == pytest.approx(floor, rel=1e-9)


def test_a_coarse_adc_that_repeats_a_refresh_still_shows_the_grid() -> None:
    """A coarse ADC on a slow signal repeats a value over two or three refreshes (runs of k, 2k,
    3k: under 80 % within a row of k), but every change falls on one row of every k; a
    quantised signal that is not held changes on any row."""
    rng = np.random.default_rng(8)
    truth = _smooth(6000)
    x = truth + 0.05 * rng.standard_normal(6000)
    held = np.round(np.repeat(x[1::3], 3)[:5999] / 0.25) * 0.25  # refreshes on rows 0 mod 3
    held = np.concatenate([[held[0]], held])  # ... shifted: the grid's phase is row 1
    runs = np.diff(np.flatnonzero(np.diff(held) != 0.0))
    assert np.mean(np.abs(runs - 3) <= 1) < 0.8
    values, refresh = unhold(held, 0.1, smooth=True)
    assert refresh == 3
    np.testing.assert_array_equal(values[1::3], held[1::3])  # the refresh grid, repeats too
    # between refreshes as close to the truth as a reading is (rounding and noise: RMS
    # sqrt(0.25^2 / 12 + 0.05^2) = 0.088; measured 0.084), the staircase not (0.118)
    inner = slice(30, -30)
    rms = float(np.sqrt(np.mean((values[inner] - truth[inner]) ** 2)))
    assert rms < math.sqrt(0.25**2 / 12 + 0.05**2)
    assert float(np.sqrt(np.mean((held[inner] - truth[inner]) ** 2))) > 1.3 * rms
    assert unhold(np.round(x / 0.25) * 0.25, 0.1)[1] == 1  # not held: left alone


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
