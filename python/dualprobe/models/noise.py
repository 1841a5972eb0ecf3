"""The white-noise level of a sampled signal: the one estimator of the package.

Estimation, reconstruction, identification and diagnosis all call :func:`estimate_noise_std`,
each with the difference order that suits its signals (:data:`ORDER_ESTIMATION` and so on).
"""

from __future__ import annotations

import math

import numpy as np

from dualprobe.io import InputError

__all__ = [
    "MAD_TO_STD",
    "ORDER_DIAGNOSE",
    "ORDER_ESTIMATION",
    "ORDER_IDENTIFY",
    "ORDER_RECONSTRUCTION",
    "estimate_noise_std",
    "quantisation_floor",
]

MAD_TO_STD = 1.482602218505602  # 1 / Phi^-1(3/4): median absolute deviation -> Gaussian std

# The difference order each caller uses. Higher orders suppress more of the smooth signal (its
# share of a k-th difference is ~ (w Ts)^k) but let a kink spoil k + 1 differences instead of
# 2 and raise the noise gain sqrt(C(2k, k)). Sensor signals (smooth, with kinks where the gas
# steps): 4 for the pair estimation, 3 for the reconstruction. Reference measurements of the
# gas (identify's input, diagnose's reference and output), with fast steps that a wide
# difference would smear over many samples: 2.
ORDER_ESTIMATION = 4
ORDER_RECONSTRUCTION = 3
ORDER_IDENTIFY = 2
ORDER_DIAGNOSE = 2


def estimate_noise_std(x: np.ndarray, order: int) -> float:
    """Standard deviation of the white noise on a sampled signal.

    Robust scale (MAD) of the ``order``-th differences divided by their noise gain
    ``sqrt(C(2 order, order))``. The signal is smooth on the sample grid, so its differences
    are far below the noise; the few beside a kink (an off-grid gas step) are outliers the
    median ignores. If more than half of the differences are equal (coarse ADC quantisation,
    noise-free data: the MAD is 0) the RMS of the differences is used instead (0 for an exactly
    constant or polynomial signal), unless under 5 % of them differ from zero: noise-free data
    whose only differences are its kinks and steps, noise 0.

    Quantisation floor: when most of the signal's first differences are exactly zero (an ADC
    of coarse resolution on a slow signal, or a logger that holds its last value), the samples
    carry at least the rounding noise of the converter, uniform over one step ``q``:
    ``q / sqrt(12)``, with ``q`` the smallest non-zero ``|x(k+1) - x(k)|`` (the ADC step). The
    estimate is never below it (:func:`quantisation_floor`), so such data never get a noise
    level of 0. A signal that never moves has no step and no floor.

    Raises :class:`~dualprobe.io.InputError` (a ValueError) for fewer than ``order + 2``
    samples or a non-finite sample.
    """
    k = int(order)
    if k < 1:
        raise ValueError(f"estimate_noise_std: order must be >= 1, got {order!r}")
    arr = np.asarray(x, dtype=float)
    if arr.ndim != 1 or arr.size < k + 2:
        raise InputError(f"estimate_noise_std: need a 1-D array of >= {k + 2} samples")
    if not np.all(np.isfinite(arr)):
        bad = int(np.flatnonzero(~np.isfinite(arr))[0])
        raise InputError(f"estimate_noise_std: sample {bad} is not finite")
    d = np.diff(arr - arr[0], n=k)
    gain = math.sqrt(math.comb(2 * k, k))
    mad = float(np.median(np.abs(d - np.median(d))))
    if mad > 0.0:
        estimate = MAD_TO_STD * mad / gain
    elif np.count_nonzero(d) < _KINK_SHARE * d.size:
        # noise-free data: the few differences that are not zero sit at kinks and steps (a
        # clean 60 K step gave 2 K of "noise"); a quantised record has its floor below
        estimate = 0.0
    else:
        estimate = float(np.sqrt(np.mean(d * d))) / gain
    return max(estimate, quantisation_floor(arr))


# Below this share of non-zero differences (with most of them exactly zero) a record is
# noise-free with a few kinks or steps, not noisy.
_KINK_SHARE = 0.05
# A converter's step is small against what the signal spans: a record spanning fewer steps of
# its smallest change is a clean step profile (a reference switched between a few levels, whose
# "smallest step" is the step itself: a 60 K step was taken for 17 K of noise and identify
# refused the record as unexcited). 8 steps keep a +-1 K record through a 0.1 K ADC quantised.
_MIN_LEVELS = 8


def quantisation_floor(x: np.ndarray) -> float:
    """``q / sqrt(12)`` when most first differences of ``x`` are exactly zero (quantised or
    held data), or when the readings lie on the lattice of ``q`` and their steps take a few
    lattice values (quantised data that move on most rows: a plunge through 0.1 K steps at
    several steps a row left second differences of float rounding only, and a noise level of
    3e-14 K); ``q`` the smallest non-zero step, and the record spanning at least
    ``_MIN_LEVELS`` of it. Else 0: a smooth signal can lie on a lattice too (k^2 h^2), but its
    steps are all different; a straight line has one step, no rounding; a clean step profile
    spans a few of its steps.
    """
    arr = np.asarray(x, dtype=float)
    steps = np.abs(np.diff(arr))
    moving = steps[steps > 0.0]
    if steps.size == 0 or moving.size == 0:
        return 0.0
    q = float(np.min(moving))
    if float(np.ptp(arr)) < _MIN_LEVELS * q:
        return 0.0  # a few big steps: a clean step profile, not an ADC
    if 2 * moving.size < steps.size:
        return q / math.sqrt(12.0)
    lattice = (arr - arr[0]) / q
    # 1e-3 of a step: far above float rounding of k q for any k a record holds, far below the
    # spread of unquantised readings, whose smallest step is itself a chance value
    if float(np.max(np.abs(lattice - np.rint(lattice)))) >= 1e-3:
        return 0.0
    kinds = np.unique(np.rint(np.diff(lattice))).size
    return q / math.sqrt(12.0) if 2 <= kinds <= max(8, steps.size // 20) else 0.0
