"""A freer tracked psi, kept where the data repeat it (no flow signal, first order).

The discrepancy principle (:func:`tracking.choose_penalty`) chooses one penalty for the whole
record: the stiffest psi whose misfit stays within the noise band of the record's. A stretch
where psi barely moves that misfit (the readings nearly coincide while gas and flow move
together, a cruise's speed wobble) is smoothed there as far as the whole record allows, and its
gas with it. So psi is tracked again at ``FREER`` times that penalty, on the whole record and on
its even and odd rows apart (the same gas and flow, independent noise); in each ``WINDOW``
(half overlapping) the share ``k = s / (s + n)`` of the freer psi's departure from the tracked
one is kept, ``s`` the mean product of the halves' departures (what both repeat: signal,
floored at 0) and ``n`` a quarter of their mean squared difference (the noise the whole
record's freer psi carries, each half having about twice its variance); ``k`` is interpolated
between window centres. The noise kept with it, ``k^2 n``, joins ``psi_noise`` in quadrature.

Measured in the product with and without this step (tests/python/adaptive_psi_study.py,
2026-12-03; 14 unsheathed pairs of both generators): 1.89x -> 1.35x the oracle, 1.64x -> 1.48x,
1.53x -> 1.40x, 1.24x -> 1.21x, 1.26x -> 1.24x, an unsheathed pair on a smooth gas (whose
tracked psi was 7 % RMS off in a cruise wobble) 4.39x -> 2.58x, the others within 0.02x; the
freer psi alone was worse than the tracked one on five of ten (up to 1.42x -> 1.55x). Where a
freer psi is not positive (rows at idle with nothing to pin it) those rows keep the tracked psi
and a window holding one keeps nothing (until 2026-12-04 nothing at all was kept then: u3 of the
study 1.74x -> 1.34x; three more pairs are now adapted but the engine's fit rejects the result,
the other ten unchanged within 0.02x).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualprobe.estimation import tracking
from dualprobe.estimation.engine import Fit

__all__ = ["FREER", "WINDOW", "Adapted", "Kept", "adapt", "keep_repeated"]

FREER = 0.1  # of the chosen penalty
WINDOW = 30.0  # s: a manoeuvre's length on a drive cycle (as workflows/undetermined.py)


@dataclass(frozen=True)
class Adapted:
    """``psi`` (N,) the adapted schedule (mean 1); ``share`` the mean share kept;
    ``noise`` the RMS of log psi's noise that the kept share brings (``sqrt(mean k^2 n)``)."""

    psi: np.ndarray
    share: float
    noise: float


def adapt(t1: np.ndarray, t2: np.ndarray, fit: Fit, tracked: tracking.Tracking,
          psi: np.ndarray, effective_rows: float) -> Adapted | None:
    """``psi`` (the tracked schedule) adapted as the module docstring says, with the tracking's
    static map and knots and the filter setting and noise of ``fit`` (the engine's fit on the
    tracked schedule, this try's order); None where a freer psi cannot be tracked or is
    positive nowhere."""
    n = t1.size
    def freer_track(a: np.ndarray, b: np.ndarray, ts: float, rows: float) -> np.ndarray:
        return tracking.track(a, b, ts, tf=fit.tf, order=1, sigma=fit.sigma,
                              effective_rows=rows, static=tracked.static,
                              spacing_of_tf=tracked.spacing_of_tf, penalty_share=FREER).psi

    try:
        full = freer_track(t1, t2, fit.ts, effective_rows)
        halves = [freer_track(t1[k::2], t2[k::2], 2.0 * fit.ts, 0.5 * effective_rows)
                  for k in (0, 1)]
    except tracking.TrackingError:
        return None
    rows = np.arange(n)
    logs = [_log(full, rows, rows), _log(halves[0], rows[0::2], rows),
            _log(halves[1], rows[1::2], rows), _log(psi, rows, rows)]
    # rows where a freer psi is not positive (at idle, nothing pins it) keep the tracked psi:
    # every log is centred over the rows where all are defined, and a window holding one of
    # the others keeps nothing
    defined = np.all(np.isfinite(logs), axis=0)
    if not np.any(defined):
        return None
    freer, even, odd, own = (x - float(np.mean(x[defined])) for x in logs)
    kept = keep_repeated(own, freer, even, odd, defined, max(2, round(WINDOW / fit.ts)))
    psi = np.exp(kept.log_psi)
    # mean 1, as the tracking's (tracking.solve_penalised): the reported time constants stay
    # those at the record's mean factor
    return Adapted(psi / float(np.mean(psi)), kept.share, kept.noise)


@dataclass(frozen=True)
class Kept:
    """``log_psi`` (N,) the tracked log psi with the kept share of the freer one's departure;
    ``share`` the mean share kept; ``noise`` the RMS of the log psi noise that share brings."""

    log_psi: np.ndarray
    share: float
    noise: float


def keep_repeated(own: np.ndarray, freer: np.ndarray, even: np.ndarray, odd: np.ndarray,
                  defined: np.ndarray, width: int) -> Kept:
    """The share of ``freer - own`` that the even and odd halves repeat (``even``, ``odd``:
    their freer log psi at every row), per window of ``width`` rows (half overlapping) and
    interpolated between window centres, as the module docstring says. All four are log psi
    (N,) centred alike; rows not ``defined`` keep ``own``, and a window holding one keeps
    nothing."""
    n = own.size
    de, do = even - own, odd - own
    centres, shares, noises = [], [], []
    for start in range(0, n, width // 2):
        stop = min(n, start + width)
        signal, noise = 0.0, 0.0
        if np.all(defined[start:stop]):
            signal = max(float(np.mean(de[start:stop] * do[start:stop])), 0.0)
            noise = float(np.mean((de[start:stop] - do[start:stop]) ** 2)) / 4.0
        share = signal / (signal + noise) if signal + noise > 0.0 else 0.0
        centres.append(0.5 * (start + stop - 1))
        shares.append(share)
        noises.append(share * share * noise)
    rows = np.arange(n)
    share_at = np.interp(rows, centres, shares)
    return Kept(own + share_at * np.where(defined, freer - own, 0.0), float(np.mean(share_at)),
                math.sqrt(float(np.mean(np.interp(rows, centres, noises)))))


def _log(psi: np.ndarray, at: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """log psi (given at the rows ``at``) at every row of ``rows``, linear between; NaN where
    psi is not positive (and between such a row and its neighbours)."""
    values = np.full(psi.size, np.nan)
    positive = psi > 0.0
    values[positive] = np.log(psi[positive])
    return np.interp(rows, at[: psi.size], values)
