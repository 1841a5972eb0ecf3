"""Sampling jitter: a logger that takes each reading a little early or late but logs it at the
nominal instant (an ECU task of a 10 ms raster, a CAN frame's latency). A reading taken ``e``
late is off by ``x'(t) e``: white, like sensor noise, but proportional to how fast the sensor
moves, so it is large where the gas changes and absent where it rests. A smoother that counts
every row with one noise level takes those errors at the transients for the gas (25 Hz, 10 ms
jitter, a 3.1 / 12.6 s pair with the mass flow: the gas 3.21x the oracle, 1.06x without the
jitter, the identified time constants and exponent the same).

:func:`jitter_variance` measures it per sensor: the k-th differences of a signal that is smooth
on the sample grid are its noise, and with jitter their variance grows with the squared slope,
``sigma^2 + j^2 x'^2``. The characterisation then judges the sensor by the equivalent white
level (:func:`equivalent_noise_std`: the record's mean of that variance), and the smoother
(:mod:`dualprobe.reconstruction.smoother`) spreads that level over the rows by
:func:`row_noise_scale` (so the smoother's noise level must be the equivalent one, as the
characterisation gives it). Nothing is adopted unless the steepest rows' differences are
``_RATIO`` times as variable as the stillest rows', the differences of orders 3 and 6 give
the same noise level and the steepest rows' neighbouring differences correlate as white errors'
do (the signal is smooth on the grid: at 1-2 Hz a drive cycle's own motion shows in the
differences, steepest where the sensor moves fastest, and is no jitter), and no logger holds
the readings (a staircase's steps are steepest where the sensor moves, too).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.ndimage

from dualprobe.models.held import HELD_SHARE, held_share
from dualprobe.models.noise import estimate_noise_std

__all__ = ["equivalent_noise_std", "jitter_variance", "row_noise_scale", "slope"]

_ORDER = 4  # difference order: the signal's share is ~ (w Ts)^4, the jitter's a white term
_GAIN = math.comb(2 * _ORDER, _ORDER)  # a k-th difference of white noise: C(2k, k) sigma^2
_MEDIAN_CHI2 = 0.454936423119572  # median of chi-square with one degree of freedom
_BINS = 8  # slope classes (equal counts)
_MIN_ROWS = 400  # 50 rows per class: a class's median variance within ~20 %
# The steepest class's difference variance over the stillest class's before jitter is taken:
# 48 with 10 ms at 25 Hz on a drive cycle (14 K/s at the steepest eighth), 3.4 with 2 ms (whose
# effect on the gas was within 1 %), 1.0-1.4 without jitter at 10-25 Hz, 2.5 at 2 Hz where the
# signal itself shows (also excluded by the order test)
_RATIO = 4.0
_WHITE = 0.15  # orders 3 and 6 within 15 %: the differences are noise, not the signal
# Neighbouring 4th differences of white errors correlate at -56/70 = -0.8; a signal's own share
# is smooth and correlates positively. Measured in the steepest class: -0.79 to -0.81 with and
# without jitter at 10-50 Hz; -0.20 to -0.55 at 1-2 Hz, where the drive cycle shows (a 2 Hz
# pair with 2 ms was taken for 8.6 ms there and its gas went from 1.03x to 1.56x the oracle,
# and a 1 Hz staircase for 1.15 s)
_WHITE_CORRELATION = -0.7


def jitter_variance(x: np.ndarray, ts: float) -> float:
    """The variance of the sampling instants (s^2) that the slope-dependence of ``x``'s noise
    shows; 0 when it shows none (module docstring)."""
    v = np.asarray(x, dtype=float)
    if v.size < _MIN_ROWS or not np.all(np.isfinite(v)):
        return 0.0
    d = np.diff(v, n=_ORDER)
    d2 = d * d / _GAIN
    speed = slope(v, ts)[2:-2]  # at each difference's centre
    classes = np.array_split(np.argsort(np.abs(speed)), _BINS)
    variance = np.array([np.median(d2[c]) / _MEDIAN_CHI2 for c in classes])
    speed2 = np.array([np.median(speed[c] ** 2) for c in classes])
    if not (variance[0] > 0.0 and variance[-1] > _RATIO * variance[0]):
        return 0.0
    if held_share(v) > HELD_SHARE:
        return 0.0  # a staircase (a logger's hold) is steepest where the sensor moves, too
    low, high = estimate_noise_std(v, 3), estimate_noise_std(v, 6)
    if not (low > 0.0 and abs(high / low - 1.0) <= _WHITE):
        return 0.0
    steep = classes[-1][classes[-1] < d.size - 1]
    if not (steep.size > 2 and np.corrcoef(d[steep], d[steep + 1])[0, 1] < _WHITE_CORRELATION):
        return 0.0
    # least squares of the classes' excess variance on their excess squared slope, through
    # the stillest class (its variance is the noise's)
    excess, rise = variance - variance[0], speed2 - speed2[0]
    j2 = float(np.dot(excess, rise) / np.dot(rise, rise)) if np.dot(rise, rise) > 0.0 else 0.0
    # a reading over a row early or late is no jitter but a misplaced row
    return j2 if 0.0 < j2 < ts**2 else 0.0


def slope(x: np.ndarray, ts: float) -> np.ndarray:
    """The reading's slope (K/s), over 5 rows: the noise's own share is small beside the
    transients' slopes that jitter turns into errors."""
    return np.gradient(scipy.ndimage.uniform_filter1d(np.asarray(x, dtype=float), 5), ts)


def equivalent_noise_std(sigma: float, x: np.ndarray, ts: float, j2: float) -> float:
    """The white noise level whose variance is the record's mean of ``sigma^2 + j2 x'^2``:
    what a misfit over all rows is to be judged against."""
    return math.sqrt(sigma**2 + j2 * float(np.mean(slope(x, ts) ** 2)))


def row_noise_scale(y: np.ndarray, ts: float) -> np.ndarray | None:
    """(N, 2) each row's noise variance over the record's mean for that sensor, ``(s0 + j^2
    x'^2) / mean(s0 + j^2 x'^2)`` with the sensor's jitter variance j^2, smoothed slope x' and
    noise variance s0 (:func:`dualprobe.models.noise.estimate_noise_std`); None when neither
    sensor shows jitter. The noise levels it multiplies are the equivalent ones
    (:func:`equivalent_noise_std`), which the characterisation gives a jittered sensor."""
    y = np.asarray(y, dtype=float)
    scale = np.ones_like(y)
    found = False
    for i in range(y.shape[1]):
        j2 = jitter_variance(y[:, i], ts)
        if j2 > 0.0:
            row = estimate_noise_std(y[:, i], _ORDER) ** 2 + j2 * slope(y[:, i], ts) ** 2
            scale[:, i] = row / float(np.mean(row))
            found = True
    return scale if found else None
