"""Settings of the SVF characterisation that the data choose: the filter time constant, the
noise floor of exact data, and the evidence threshold every model selection shares."""

from __future__ import annotations

import math

import numpy as np
import scipy.ndimage

from dualprobe.estimation import engine

__all__ = [
    "DIRECTION_TOLERANCE",
    "GAP_THRESHOLD",
    "KAPPA",
    "PSI_NOISE_LIMIT",
    "RECORD_FRACTION",
    "RESOLUTION_FLOOR",
    "SHARED_FACTOR",
    "SHEATHED_SCHEDULE_ERROR",
    "beyond_record",
    "choose_filter_time_constant",
    "dip_beyond_record",
    "discretisation_noise_std",
    "gap_statistics",
]


# An eigenvalue counts as "noise only" when its excess over the noise band is below this many
# standard deviations of the noise-only spread: exact common factors gave 0-2.5 (25 simulated
# records, 10-100 Hz, 0.01-0.1 K); distinct poles 0.17 s / 0.19 s at 100 Hz, 0.01 K gave
# >= 160 (and were estimated to 2 %).
GAP_THRESHOLD = 10.0
# A tracked schedule (no flow column) whose noise part alone moves the per-row time constants by
# more than this, RMS: ``psi_noise`` (the even and odd rows tracked apart), a lower bound on
# psi's error. Measured on drive cycles (2-50 Hz): 0.013-0.024 on first-order tracked pairs
# 2.7-10 % off; 0.055 and 0.076 on a 50 Hz and a 2 Hz pair whose sheaths the first-order
# tracking absorbed (38 % and 28 % off, the gas 5.9x and 3.3x the oracle, their misfits at the
# noise). The limit keeps well-tracked pairs at half of it or less. Beyond it the model check
# doubts the schedule, and the tracking tries the sheathed path.
PSI_NOISE_LIMIT = 0.05
RECORD_FRACTION = 1.0 / 3.0  # time constants longer than this share of the record: implausible
# Two time constants, one per sensor, closer than this (relative) count as one shared factor: a
# factor common to both transfer functions cancels from the cross-relation (it multiplies both
# sides), so a pair cannot determine it. Seen: 47.6 and 50.1 s for true 4.7 / 9.4 s elements.
SHARED_FACTOR = 0.2
KAPPA = {1: 0.5, 2: 0.25}  # tf / tau_fast, see dualprobe.reference.svf
RESOLUTION_FLOOR = 1e-6  # noise std used at least this fraction of the signal's std
DIRECTION_TOLERANCE = 0.01  # slope noise / RMS slope for the heating/cooling classification
# The sheathed path's schedule error in log psi (RMS per row) beyond what follows the noise:
# psi tracked through sheath stages without a flow signal swings too little with the load's
# fast swings (log tau's slope on the truth 0.89 on pair 30108) and wanders with the stages it
# is solved with, a bias the even/odd split (psi_noise, 1.0-1.5 %) cannot see. Measured on the
# separate generator (`field_sweep_independent.py 301 10`, the 9 pairs the sheathed path took):
# 3.9-13.7 % RMS per row, 8.2 % over all 9. Carried into T_g_std as a type-B uncertainty (from
# the method's validation, not from this record), the gas error below the bandwidth over
# T_g_std had an RMS of 1.14-5.55 without it and 0.51-2.07 with it on five of them (1.1x-4.0x
# the oracle; 30108, 3.1x, is the 2.07).
SHEATHED_SCHEDULE_ERROR = 0.08


def beyond_record(taus: tuple[float, ...], psi_at: float, duration: float) -> bool:
    """Whether a sensor's longest time constant at psi = ``psi_at`` (``taus`` at psi = 1; the
    refusal tests psi's least) is longer than ``RECORD_FRACTION`` of the record, or not
    finite."""
    longest = max(taus) / psi_at
    return not (math.isfinite(longest) and longest <= RECORD_FRACTION * duration)


def dip_beyond_record(taus: tuple[float, ...], psi: np.ndarray, duration: float) -> bool:
    """Whether only a schedule's dip makes a sensor's time constants implausible: the longest
    within ``RECORD_FRACTION`` of the record at psi = 1 (``taus``), beyond it (but finite) at
    psi's least: :func:`beyond_record` at both."""
    least = float(np.min(psi))
    return (math.isfinite(max(taus) / least) and not beyond_record(taus, 1.0, duration)
            and beyond_record(taus, least, duration))


_KINK_MEDIAN_WINDOW = 11  # running median of the second differences: kinks are 2 samples wide
_KINK_THRESHOLD = 8.0  # kink spikes: beyond 8 noise standard deviations of a second difference


def discretisation_noise_std(x: np.ndarray, noise_std: float = 0.0) -> float:
    """White noise equivalent to the first-order-hold error at the kinks of a sampled signal.

    The SVF sees the straight-line interpolation of the samples. On smooth stretches its error
    acts as the common operator ``1 - (Ts s)^2/12`` on both sensors and cancels from the
    cross-relation; at a kink (slope jump D, a gas step seen by a first-order sensor) it leaves
    an impulse of area up to ``Ts^2 D / 12``. The kink shows as a spike of about ``Ts D`` in the
    second differences above their running median (``r``), so the impulses' energy ``sum A^2``
    equals that of white noise of variance ``sum r^2 / (144 N)`` over the N samples. Only
    spikes above 8 noise standard deviations count (below, the noise hides them). Measured on
    the paper's noise-free study A (Ts = 0.1 s, 100 K step on the grid): 1.5e-3 K for the
    first-order sensor, where the fits' residuals then sit at 0.001-0.6 of this noise band.
    """
    d = np.diff(np.asarray(x, dtype=float), 2)
    if d.size < _KINK_MEDIAN_WINDOW:
        return 0.0
    spikes = d - scipy.ndimage.median_filter(d, size=_KINK_MEDIAN_WINDOW, mode="nearest")
    spikes = spikes[np.abs(spikes) > _KINK_THRESHOLD * math.sqrt(6.0) * noise_std]
    return math.sqrt(float(np.sum(spikes * spikes)) / (144.0 * (d.size + 2)))


def choose_filter_time_constant(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    order: int,
    sigma: tuple[float, float],
    static: str = "affine",
) -> tuple[float, list[float]]:
    """Filter time constant from the data: ``tf = kappa * tau_fast`` at its fixed point.

    A geometric scan (factor 4) from 2 Ts to a tenth of the record gives first-order fits
    (``static`` model; affine by default so that a gain mismatch cannot mislead the scan);
    the scan point closest to its own fixed point starts up to four refinement steps.
    Returns (tf, the tf values visited after the scan).
    """
    kappa = KAPPA[order]
    duration = (t1.size - 1) * ts
    tf_min = ts
    tf_max = max(tf_min, duration / 10.0)
    grid = [2.0 * ts * 4.0**j for j in range(64) if 2.0 * ts * 4.0**j <= tf_max] or [tf_max]

    def fast_at(tf: float) -> float:
        res = engine.fit(t1, t2, ts, tf=tf, order=1, sigma=sigma, static=static)
        return math.nan if res is None else res.fast_time_constant()

    best: tuple[float, float] | None = None  # (log mismatch, tf)
    for tf in grid:
        fast = fast_at(tf)
        if math.isfinite(fast):
            mismatch = abs(math.log(tf / (kappa * fast)))
            if best is None or mismatch < best[0]:
                best = (mismatch, tf)
    if best is None:
        return grid[len(grid) // 2], []
    tf = best[1]
    history = [tf]
    for _ in range(4):
        fast = fast_at(tf)
        if not math.isfinite(fast):
            break
        new = min(max(kappa * fast, tf_min), tf_max)
        history.append(new)
        converged = abs(new / tf - 1.0) < 0.05
        tf = new
        if converged:
            break
    return tf, history


def gap_statistics(mu: np.ndarray, n_eff: float) -> np.ndarray:
    """Excess of each generalised eigenvalue over the noise band, in noise standard deviations.

    The band sits at mu = 1 when the noise model is right; a larger smallest eigenvalue
    (model error) raises it, a smaller one (noise overestimated, e.g. the resolution floor
    on exact data) does not lower it.
    """
    mu = np.asarray(mu, dtype=float)
    reference = max(float(mu[0]), 1.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        gaps = (mu / reference - 1.0) * math.sqrt(n_eff / 2.0)
    gaps = np.where(np.isfinite(gaps), gaps, np.inf)
    gaps[0] = 0.0
    return gaps
