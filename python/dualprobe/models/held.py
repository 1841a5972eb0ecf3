"""Readings a logger holds: a channel logged slower than the rows repeats its value until the
next refresh (CSV exports of mixed-rate loggers, a slow sensor's ECU). The staircase lags the
signal by half a refresh on average and, to a model of the sensor, looks like an extra stage.

:func:`unhold` puts each refreshed value at its refresh row and interpolates between them
(straight lines, as the MDF4 reader does for a channel of another rate, or a cubic for a
sensor's smooth reading); the one implementation for the flow column
(:mod:`dualprobe.estimation.flow_timing`) and the sensors' readings
(:mod:`dualprobe.workflows.characterise`). :func:`held_noise_std` is the white-equivalent noise
of such an interpolated sensor: each refresh is one reading, carried over k rows.
:func:`held_share` measures an irregular hold (exact repeats where the reading moves), which
the model check names; :func:`is_held` says whether a channel is held either way.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.interpolate

from dualprobe.models.noise import estimate_noise_std, quantisation_floor

__all__ = ["HELD_SHARE", "MAX_REFRESH", "SENSOR_REFRESH", "held_noise_std", "held_share",
           "is_held", "refreshes", "unhold"]

_REGULAR_SHARE = 0.8  # share of runs within one row of the modal length for a refresh pattern
_GRID_SHARE = 0.9  # share of the changes on one row of every k for a refresh grid
MAX_REFRESH = 2.0  # s: the slowest logger refresh taken as a hold (rasters: 10 ms - 1 s)
# s: the same for a sensor's reading, which lags the gas and so moves on every row while the gas
# moves: a regular staircase in it is a logger's however slow, where a stepped flow may be a
# laboratory's. A 1 Hz pair, the slow sensor held for 3 rows (3 s), was left as a staircase
# at 2 s: the gas 8.7x the oracle with a 332 K dip (exit 0, warned); interpolated 2.0x.
SENSOR_REFRESH = 5.0
# Held readings: above this share of exact repeats among the moving rows. A hold of k rows
# repeats (k-1)/k of them (50 % for two); ADC steps with noise, none (0 % on drive cycles with
# 0.02-0.1 K steps at 2-50 Hz).
HELD_SHARE = 0.1


def refreshes(v: np.ndarray, ts: float, longest: float) -> tuple[np.ndarray, int]:
    """(the refresh rows, rows per refresh k) of a held signal; (the rows where the value
    changes, 1) when it is not held. Held: the modal run of equal values k >= 2 is at most
    ``longest`` s long, and most runs are within a row of it (a refresh that is no whole
    number of rows: runs of 2 and 3) or the changes fall on one row of every k (a coarse ADC
    repeats a value over two refreshes: runs of k, 2k, 3k); then the refresh rows are that
    grid, repeated values included. A quantised signal's runs are irregular and its changes
    fall on every row alike."""
    starts = np.concatenate([[0], np.flatnonzero(np.diff(v) != 0.0) + 1])
    runs = np.diff(starts)  # the last run is open-ended: not counted
    if runs.size < 8:
        return starts, 1
    lengths, counts = np.unique(runs, return_counts=True)
    k = int(lengths[np.argmax(counts)])
    if k < 2 or k * ts > longest:
        return starts, 1
    residues = np.bincount(starts[1:] % k, minlength=k)
    phase = int(np.argmax(residues))
    if residues[phase] >= _GRID_SHARE * (starts.size - 1):
        grid = np.arange(phase, v.size, k)
        return (np.concatenate([[0], grid]) if phase > 0 else grid), k
    if np.count_nonzero(np.abs(runs - k) <= 1) >= _REGULAR_SHARE * runs.size:
        return starts, k
    return starts, 1


def unhold(values: np.ndarray, ts: float, *, smooth: bool = False,
           longest: float = MAX_REFRESH) -> tuple[np.ndarray, int]:
    """(the signal with held values interpolated between refresh rows, rows per refresh; 1:
    not held, values unchanged). It acts only on a regular refresh pattern (:func:`refreshes`),
    not on a quantised or piecewise-constant signal, whose runs are irregular. A refresh slower
    than ``longest`` (s: ``MAX_REFRESH``; ``SENSOR_REFRESH`` for a sensor) is no logger's: a
    laboratory flow stepped at regular intervals (every 60 s) keeps its steps. ``smooth``: a
    cubic spline through the refreshes instead of straight lines, for a sensor's reading
    (smooth: it lags the gas), where the straight line's error, an eighth of the refresh
    interval squared times the curvature, is tenths of a kelvin at 1 s refreshes on a drive
    cycle."""
    v = np.asarray(values, dtype=float)
    points, k = refreshes(v, ts, longest)
    if k == 1:
        return v, 1
    rows = np.arange(v.size, dtype=float)
    if smooth:
        spline = scipy.interpolate.CubicSpline(points.astype(float), v[points])
        inside = np.minimum(rows, float(points[-1]))  # the last run: held, not extrapolated
        return np.asarray(spline(inside)), k
    return np.interp(rows, points.astype(float), v[points]), k


def held_noise_std(values: np.ndarray, ts: float, order: int,
                   longest: float = MAX_REFRESH) -> float:
    """The white-equivalent noise level of a held signal interpolated by :func:`unhold`: the
    refreshes' own noise (:func:`estimate_noise_std` of the refreshed values, difference order
    ``order``) times sqrt(rows per refresh); :func:`estimate_noise_std` of the values when they
    are not held. Why: at the frequencies a fit resolves, k rows interpolated from one reading
    carry that reading's noise k times over (a power density k times that of white noise of
    the same level), and the rows' own differences, being smooth between refreshes, show
    almost none of it. Never below the quantisation floor of the readings."""
    v = np.asarray(values, dtype=float)
    points, k = refreshes(v, ts, longest)
    if k == 1:
        return estimate_noise_std(v, order)
    # never below the readings' rounding (q / sqrt(12)): noise-free quantised refreshes can
    # show no noise in their differences, and a level of 0 is no sensor's
    return max(estimate_noise_std(v[points], order), quantisation_floor(v)) * math.sqrt(k)


def held_share(x: np.ndarray) -> float:
    """Share of the moving rows whose reading repeats the previous one exactly: a logger that
    holds readings (refreshes slower than the rows). Moving rows: the change over two rows is
    in the upper half of the record's and above 4 times the smallest nonzero step (ADC steps
    and noise alone give no exact repeat inside such a change); NaN when too few move."""
    x = np.asarray(x, dtype=float)
    if x.size < 8:
        return math.nan
    step = np.abs(np.diff(x))
    nonzero = step[step > 0.0]
    if nonzero.size == 0:
        return math.nan
    span = np.abs(x[2:] - x[:-2])
    moving = (span > np.median(span)) & (span > 4.0 * float(np.min(nonzero)))
    if np.count_nonzero(moving) < 20:
        return math.nan
    return float(np.mean(step[:-1][moving] == 0.0))


def is_held(values: np.ndarray, ts: float, longest: float = MAX_REFRESH) -> bool:
    """A logger holds these readings: a regular refresh (:func:`unhold` interpolates it) or an
    irregular one (exact repeats on over ``HELD_SHARE`` of the moving rows: :func:`held_share`)."""
    v = np.asarray(values, dtype=float)
    return refreshes(v, ts, longest)[1] > 1 or held_share(v) > HELD_SHARE
