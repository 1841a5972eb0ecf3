"""Readings that no lagging sensor can give: spikes and short dropouts.

A thermocouple or RTD is a low-pass element: between two rows its reading moves towards the
gas, smoothly. One to ``MAX_RUN`` rows that jump away from both neighbours and straight back
(ignition or EMI pickup on the leads, a bit error, an open circuit read as 0) are not
temperature. Left in, three 30 K spikes in 12 000 rows (separate generator, 10 Hz, with the
flow) took the gas from 1.07x the oracle to 10.1x; twenty were refused as a reconstruction
that departs from both sensors, with no word of why.

Detection (:func:`find_spikes`): a run of ``L <= MAX_RUN`` rows is a spike when the step into
it and the step out of it are both larger than the threshold and of opposite direction, every
row of it lies beyond the threshold on the same side of the straight line between the rows
that bracket it, and its first and last rows lie beyond the threshold off the trend of the
two rows before and after it. A corner of a lagging sensor's response (the gas stepped)
changes the slope but does not come back; at a sharp load peak the sensor's first row still
continues the slope that led into it; a sensor whose own reading left both trends and came
back would need a gas pulse of a row or two far larger than the record's curvature there.
Threshold: ``SPIKE_SCALES`` local robust scales (a running median over ``WINDOW`` rows) of the
rows' departure from their neighbours' mean, which holds the noise and the curvature of the
record there, and never below ``SPIKE_SCALES`` ADC steps (a 1-LSB flicker of a quiet sensor
is not a spike).

Replacement (:func:`despike`): the straight line between the bracketing rows. More than
``MAX_SHARE`` of the rows flagged means the rule does not describe this sensor (it may be
faster than the rows): nothing is replaced, and the caller says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from dualprobe.models.noise import MAD_TO_STD

__all__ = ["MAX_RUN", "MAX_SHARE", "SPIKE_SCALES", "Spikes", "despike", "find_spikes",
           "thresholds"]

MAX_RUN = 3  # rows: a spike or dropout; longer excursions are left to the model check
# robust scales: the departure of Gaussian noise and curvature beyond 12 MAD-sigmas has a
# probability of ~1e-32 per row; what exceeds it is not noise
SPIKE_SCALES = 12.0
MAX_SHARE = 0.01  # of the rows: beyond it the rule does not fit the sensor (nothing replaced)
WINDOW = 51  # rows of the running median: local, yet the spikes (<= 1 %) cannot move it


@dataclass(frozen=True)
class Spikes:
    """What :func:`despike` found: ``rows`` replaced (sorted), ``sizes`` the largest departure
    of each run from its bracketing line (K, signed), ``starts`` each run's first row,
    ``threshold`` (K), ``replaced`` False when too many were flagged to trust the rule."""

    rows: np.ndarray
    starts: np.ndarray
    sizes: np.ndarray
    threshold: float
    replaced: bool

    def __len__(self) -> int:
        return int(self.starts.size)


def thresholds(x: np.ndarray) -> np.ndarray:
    """Per row: ``SPIKE_SCALES`` times the local robust scale of the rows' departure from
    their neighbours' mean (a running median over ``WINDOW`` rows: a drive cycle's curvature
    at idle and under load differ by orders of magnitude, and one scale for the record took
    genuine reversals under load for spikes), never below ``SPIKE_SCALES`` ADC steps."""
    departure = np.abs(x[1:-1] - 0.5 * (x[:-2] + x[2:]))
    half = WINDOW // 2
    if departure.size > WINDOW:
        local = ndimage.median_filter(departure, size=WINDOW, mode="nearest")
        # the first and last full windows' medians at the ends: padding with the end value
        # made it the median there (a scale of 1 mK at the start of a 0.05 K noisy record)
        local[:half], local[-half:] = local[half], local[-half - 1]
    else:
        local = np.full(departure.size, float(np.median(departure)))
    local = MAD_TO_STD * local
    steps = np.abs(np.diff(x))
    moving = steps[steps > 0.0]
    adc = float(np.min(moving)) if moving.size else 0.0
    scale = np.maximum(np.concatenate(([local[0]], local, [local[-1]])), adc)
    return SPIKE_SCALES * scale


def find_spikes(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """(starts, lengths, median threshold) of the runs of 1..``MAX_RUN`` rows that jump away from
    both neighbours and back (module docstring); runs do not overlap, shorter runs first."""
    x = np.asarray(x, dtype=float)
    n = x.size
    if n < MAX_RUN + 4:
        return np.zeros(0, np.intp), np.zeros(0, np.intp), 0.0
    limits = thresholds(x)
    threshold = float(np.median(limits))
    if not np.any(limits > 0.0):
        return np.zeros(0, np.intp), np.zeros(0, np.intp), threshold
    taken = np.zeros(n, dtype=bool)
    starts: list[int] = []
    lengths: list[int] = []
    step = np.diff(x)  # step[k] = x[k+1] - x[k]
    for length in range(1, MAX_RUN + 1):
        # run rows k .. k+length-1, brackets k-1 and k+length, two rows of trend each side
        k = np.arange(2, n - length - 1)
        into = step[k - 1]
        out = step[k + length - 1]
        limit = limits[k - 1]  # the bracketing row's: the spike itself does not raise it
        ok = (np.abs(into) > limit) & (np.abs(out) > limit) & (into * out < 0.0)
        # off the trend on both sides: a lagging sensor's peak continues the slope that led
        # into it for the row in which the gas turned (a sharp but smooth load peak otherwise
        # passes every other test)
        ahead = x[k] - (2.0 * x[k - 1] - x[k - 2])
        behind = x[k + length - 1] - (2.0 * x[k + length] - x[k + length + 1])
        ok &= (np.abs(ahead) > limit) & (ahead * into > 0.0)
        ok &= (np.abs(behind) > limit) & (behind * into > 0.0)
        left, right = x[k - 1], x[k + length]
        for j in range(length):
            chord = left + (right - left) * (j + 1) / (length + 1)
            departure = x[k + j] - chord
            ok &= (np.abs(departure) > limit) & (departure * into > 0.0)
        for start in k[ok]:
            span = slice(start - 1, start + length + 1)  # the brackets stay real readings
            if not taken[span].any():
                taken[start : start + length] = True
                starts.append(int(start))
                lengths.append(length)
    order = np.argsort(starts)
    return (np.asarray(starts, np.intp)[order], np.asarray(lengths, np.intp)[order],
            threshold)


def despike(x: np.ndarray) -> tuple[np.ndarray, Spikes]:
    """``x`` with each spike replaced by the straight line between the rows that bracket it
    (unchanged when none, or when more than ``MAX_SHARE`` of the rows are flagged)."""
    x = np.asarray(x, dtype=float)
    starts, lengths, threshold = find_spikes(x)
    rows = (np.concatenate([np.arange(s, s + m) for s, m in zip(starts, lengths, strict=True)])
            if starts.size else np.zeros(0, np.intp))
    replaced = rows.size <= MAX_SHARE * x.size
    sizes = np.zeros(starts.size)
    cleaned = x.copy()
    for i, (start, length) in enumerate(zip(starts, lengths, strict=True)):
        left, right = x[start - 1], x[start + length]
        chord = left + (right - left) * np.arange(1, length + 1) / (length + 1)
        departure = x[start : start + length] - chord
        sizes[i] = departure[int(np.argmax(np.abs(departure)))]
        if replaced:
            cleaned[start : start + length] = chord
    return cleaned, Spikes(rows, starts, sizes, threshold, replaced)
