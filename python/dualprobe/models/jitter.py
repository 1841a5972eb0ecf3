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
``_RATIO`` times as variable as the stillest rows' and the steepest rows' neighbouring
differences correlate as white errors' do (the signal is smooth on the grid: at 1-2 Hz a drive
cycle's own motion shows in the differences, steepest where the sensor moves fastest, and is
no jitter), and no logger holds the readings (a staircase's steps are steepest where the
sensor moves, too).

A class's variance is a mean of its squared differences, robust to the few rows where the
signal is not smooth on the grid (a sensor faster than the rows at a gas step): first over
the lower 90 % of each class, then over the rows within the 99 % bound of the variance the
fit gives each row, three times, each mean scaled for what the bound leaves out of a normal
variable's. Not a median: on quantised readings (0.1 K ADC steps) the differences take a few
lattice values, the stillest class's median was 0 and the jitter was never found (10 ms at
25 Hz: the gas 2.63x the oracle, 1.02x with the jitter counted), and a median of a class
whose rows' variances differ (the steepest, over slopes spanning ten-fold) is below its
mean: 10 ms was missed on the slower sensor. On the separate generator (1 200 s, 0.02 K
noise, unquantised, 0.02 and 0.1 K steps, 5-50 Hz): 10 ms measured as 8.8-11.4 ms, 5 ms as
4.8-6.8 ms (or not found on the slower sensor), none found without jitter or with 2 ms
(steepest over stillest 0.9-3.8), nor on a 0.3 s sensor stepped through 60 K at 10-100 Hz.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.ndimage
import scipy.stats

from dualprobe.models.held import HELD_SHARE, held_share
from dualprobe.models.noise import estimate_noise_std

__all__ = ["equivalent_noise_std", "jitter_variance", "row_noise_scale", "slope"]

_ORDER = 4  # difference order: the signal's share is ~ (w Ts)^4, the jitter's a white term
_GAIN = math.comb(2 * _ORDER, _ORDER)  # a k-th difference of white noise: C(2k, k) sigma^2
_BINS = 8  # slope classes (equal counts)
_MIN_ROWS = 400  # 50 rows per class: a class's variance within ~20 %
# The robust means (module docstring): the share of a class kept at first, the share of a
# normal variable a row's bound keeps after, and the reweighting passes (converged by the
# third: the estimates above moved by under 1 % in a fourth).
_FIRST_KEEP = 0.9
_KEEP = 0.99
_PASSES = 3
# The steepest class's difference variance over the stillest class's before jitter is taken.
# Measured (separate generator, 1 200 s, 5-50 Hz, unquantised, 0.02 and 0.1 K steps): 8-34
# with 10 ms, 4.5-11 with 5 ms (or below, on the slower sensor), 0.9-3.8 with 2 ms (whose
# effect on the gas was within 1 %) and 0.9-3.2 without jitter (the most with 0.1 K steps);
# 2.1-4.0 at 2 Hz, where the signal itself shows (excluded by the correlation below)
_RATIO = 4.0
# Neighbouring 4th differences of white errors correlate at -56/70 = -0.8; a signal's own share
# is smooth and correlates positively. Measured in the steepest class: -0.72 to -0.84 with and
# without jitter at 5-50 Hz; -0.20 to -0.55 at 1-2 Hz, where the drive cycle shows (a 2 Hz
# pair with 2 ms was taken for 8.6 ms there and its gas went from 1.03x to 1.56x the oracle,
# and a 1 Hz staircase for 1.15 s)
_WHITE_CORRELATION = -0.7


def _normal_share(keep: float) -> float:
    """E[z^2 | z within its central ``keep`` share] for a standard normal z: what a mean of
    squares over the rows a bound keeps is of the variance."""
    c = float(scipy.stats.norm.ppf(0.5 + keep / 2.0))
    return (keep - 2.0 * c * float(scipy.stats.norm.pdf(c))) / keep


def _class_fit(d2: np.ndarray, speed2: np.ndarray, classes: list[np.ndarray],
               keep: np.ndarray, share: float) -> tuple[np.ndarray, float]:
    """(each class's variance, j^2): the means over the kept rows, the variance scaled by the
    normal ``share`` the keeping leaves, and j^2 the least squares of the classes' excess
    variance on their excess mean squared slope through the stillest class (its variance is
    the noise's)."""
    # (a class with no row kept, which no bound above its own variance leaves, keeps them all)
    kept = [c[keep[c]] if np.any(keep[c]) else c for c in classes]
    variance = np.array([np.mean(d2[rows]) for rows in kept]) / share
    slopes = np.array([np.mean(speed2[rows]) for rows in kept])
    excess, rise = variance - variance[0], slopes - slopes[0]
    j2 = float(np.dot(excess, rise) / np.dot(rise, rise)) if np.dot(rise, rise) > 0.0 else 0.0
    return variance, max(j2, 0.0)


def jitter_variance(x: np.ndarray, ts: float) -> float:
    """The variance of the sampling instants (s^2) that the slope-dependence of ``x``'s noise
    shows; 0 when it shows none (module docstring)."""
    v = np.asarray(x, dtype=float)
    if v.size < _MIN_ROWS or not np.all(np.isfinite(v)):
        return 0.0
    d = np.diff(v, n=_ORDER)
    d2 = d * d / _GAIN
    speed2 = slope(v, ts)[2:-2] ** 2  # at each difference's centre
    classes = np.array_split(np.argsort(speed2), _BINS)
    keep = np.zeros(d.size, dtype=bool)
    for c in classes:
        keep[c] = d2[c] <= np.quantile(d2[c], _FIRST_KEEP)
    variance, j2 = _class_fit(d2, speed2, classes, keep, _normal_share(_FIRST_KEEP))
    bound = float(scipy.stats.chi2.ppf(_KEEP, 1))
    for _ in range(_PASSES):
        keep = d2 <= bound * (variance[0] + j2 * speed2)
        variance, j2 = _class_fit(d2, speed2, classes, keep, _normal_share(_KEEP))
    if not (variance[0] > 0.0 and variance[-1] > _RATIO * variance[0]):
        return 0.0
    if held_share(v) > HELD_SHARE:
        return 0.0  # a staircase (a logger's hold) is steepest where the sensor moves, too
    steep = classes[-1][classes[-1] < d.size - 1]
    if not (steep.size > 2 and np.corrcoef(d[steep], d[steep + 1])[0, 1] < _WHITE_CORRELATION):
        return 0.0
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
