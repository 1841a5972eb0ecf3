"""How fast a gas the reconstruction resolves: the smoother's bandwidth (:func:`bandwidth`).

The smoother weighs the gas prior against the sensors' noise. In steady state (constant time
constants, a long record) it is the non-causal Wiener filter of its own model: a gas component
at angular frequency w passes with the gain ``W = S / (1 + S)``, where ``S(w) = P(w) sum_i
|h_i(jw)|^2 / (sigma_i^2 Ts)`` is the signal-to-noise ratio of the model: ``P = q / w^2`` (rw)
or ``q / w^4`` (irw) the prior's gas spectrum, ``h_i`` sensor i's chain of first-order stages,
``sigma_i^2 Ts`` its sampled white noise as a density. The bandwidth is where ``W = 1/2``.

Why report it: ``T_g_std`` is the posterior of the gas given the model and its prior. Below the
bandwidth the data decide; above it the estimate follows the prior, which cannot know how much
faster fluctuation the gas carries (the sensors pass too little of it to see it in their noise).
Measured on simulated drive cycles with the flow (2-50 Hz, 0.05-0.15 K; a 1 Hz or a 0.15 s
fluctuation): bandwidths of 0.5-1.1 Hz, the error below them 0.31-0.88 K and covered by
``T_g_std`` (its RMS 0.61-1.04 standard deviations), the error above them 0.68-1.13 K and not:
over the whole error ``T_g_std`` was 1.7-2.6 times too small. So the summary states the
bandwidth beside the uncertainty.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dualprobe.reconstruction.statespace import PairModel, process_floor

__all__ = ["Bandwidth", "bandwidth", "wiener_gain"]

_BISECTIONS = 40  # on log w: 2^-40 of a factor-100 bracket, 4e-12 relative
_BRACKETS = 12  # decades of 100 below Nyquist searched for S >= 1 (24 decades)


@dataclass(frozen=True)
class Bandwidth:
    """The smoother's bandwidth in Hz: at the median row's time constants, and the range over
    the record's rows (5 % and 95 % of the intervals; all three equal at constant time
    constants). ``limited`` when it reaches the Nyquist frequency (the samples, not the
    sensors, limit it). ``steps_sharp``: the heavy-tailed (Student-t) smoother, whose
    bandwidth is that of the gas's ordinary motion while a step stays a step."""

    hz: float
    low_hz: float
    high_hz: float
    limited: bool
    steps_sharp: bool = False

    def to_json_dict(self) -> dict[str, object]:
        return {"bandwidth_hz": self.hz, "bandwidth_range_hz": [self.low_hz, self.high_hz],
                "nyquist_limited": self.limited, "steps_kept_sharp": self.steps_sharp}

    def summary(self) -> str:
        spread = ("" if self.high_hz <= self.low_hz * 1.01
                  else f" ({self.low_hz:.3g}-{self.high_hz:.3g} Hz as the time constants vary)")
        limit = " (the sampling rate's limit)" if self.limited else ""
        what = "the gas's ordinary motion (steps stay sharp)" if self.steps_sharp else "the gas"
        # a lag common to both sensors cancels from the pair's cross-relation, so no pair
        # identifies it (equal sheaths: 3.5x the oracle with the residuals at the noise)
        return (f"the reconstruction resolves {what} up to {self.hz:.3g} Hz{spread}{limit}; "
                "T_g_std covers the gas to that bandwidth, not faster fluctuation, and not "
                "a lag common to both sensors (e.g. equal sheaths), which a pair cannot see")


def _snr(w: np.ndarray, stage_taus: np.ndarray, floor: np.ndarray, model: PairModel,
         sigma: np.ndarray, q: float) -> np.ndarray:
    """The model's signal-to-noise ratio S(w) (module docstring), elementwise over slices:
    ``w`` (L,), ``stage_taus`` and ``floor`` (L, stages). ``floor``: the smoother's model-error
    variance per interval on each stage (:func:`~dualprobe.reconstruction.statespace.
    process_floor`), white noise of density floor / Ts driving that stage, which reaches the
    output through the stages after it."""
    w = np.asarray(w, dtype=float)
    ts = model.ts
    total = np.zeros(w.shape)
    for i in range(2):
        chain = np.flatnonzero(model.stage_sensor == i)  # in chain order: gas first
        gains = 1.0 / (1.0 + np.square(w[:, None] * stage_taus[:, chain]))  # |1/(1 + jw tau)|^2
        noise = np.full(w.shape, sigma[i] ** 2 * ts)
        for p, stage in enumerate(chain):
            after = np.prod(gains[:, p + 1:], axis=1)
            noise = noise + (floor[:, stage] / ts * stage_taus[:, stage] ** 2 * gains[:, p]
                             * after)
        total = total + np.prod(gains, axis=1) / noise
    return q / w ** (2 * _power(model)) * total


def _power(model: PairModel) -> int:
    return 2 if model.gas == "irw" else 1


def _slices(model: PairModel, sigma: np.ndarray, q: float, slices: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """Stage time constants and the smoother's floor on each stage, (L, stages) each."""
    floor = process_floor(model, sigma, q)[slices]
    return model.stage_taus[slices], floor[:, model.stage_state, model.stage_state]


def wiener_gain(model: PairModel, q: float, sigma: tuple[float, float],
                frequency_hz: float | np.ndarray, slice_index: int = 0) -> np.ndarray:
    """The gain ``W = S / (1 + S)`` of the model with gas intensity ``q`` and noise levels
    ``sigma`` at ``frequency_hz`` (one slice of time constants; slice 0: the heating ones at
    schedule level 0)."""
    noise = np.asarray(sigma, dtype=float)
    w = 2.0 * math.pi * np.atleast_1d(np.asarray(frequency_hz, dtype=float))
    taus, floor = _slices(model, noise, q, np.full(w.size, slice_index))
    s = _snr(w, taus, floor, model, noise, q)
    return np.asarray(s / (1.0 + s)).reshape(np.shape(frequency_hz))


def _crossings(model: PairModel, q: float, sigma: np.ndarray, slices: np.ndarray
               ) -> np.ndarray:
    """Angular frequency where S = 1 for each slice, capped at Nyquist. S falls
    monotonically in w: the prior's spectrum and every stage's gain fall, and the floor's
    noise at the output falls no faster than the gas's part."""
    taus, floor = _slices(model, sigma, q, slices)

    def above(w: np.ndarray) -> np.ndarray:
        return np.asarray(_snr(w, taus, floor, model, sigma, q) >= 1.0)

    nyquist = math.pi / model.ts
    high = np.full(slices.size, nyquist)
    capped = above(high)
    low = high.copy()
    for _ in range(_BRACKETS):  # down by decades until S >= 1
        below = ~above(low)
        if not np.any(below):
            break
        low = np.where(below, low * 1e-2, low)
    high = np.minimum(low * 1e2, nyquist)
    for _ in range(_BISECTIONS):
        mid = np.sqrt(low * high)
        up = above(mid)
        low, high = np.where(up, mid, low), np.where(up, high, mid)
    return np.where(capped, nyquist, np.sqrt(low * high))


def bandwidth(model: PairModel, q: float, sigma: tuple[float, float], *,
              steps_sharp: bool = False) -> Bandwidth:
    """The smoother's bandwidth (module docstring) over the record's intervals: the heating
    time constants of each interval's schedule level (hysteretic sensors: the heating ones).
    ``q``: the gas intensity of the ordinary motion (the Student-t smoother's
    ``background_q``), ``sigma``: the noise levels the smoother used, ``steps_sharp``: the
    Student-t smoother's (:class:`Bandwidth`)."""
    noise = np.asarray(sigma, dtype=float)
    levels = model.levels if model.levels is not None else np.zeros(1, dtype=np.intp)
    used, counts = np.unique(levels, return_counts=True)
    values = _crossings(model, q, noise, used * model.mode_count) / (2.0 * math.pi)
    order = np.argsort(values)
    cumulative = np.cumsum(counts[order]) / float(np.sum(counts))

    def quantile(p: float) -> float:
        return float(values[order][min(int(np.searchsorted(cumulative, p)), used.size - 1)])

    hz = quantile(0.5)
    return Bandwidth(hz, quantile(0.05), quantile(0.95), hz >= (0.5 / model.ts) * (1.0 - 1e-12),
                     steps_sharp)
