"""A schedule psi from the joint MAP (:func:`psi_map.map_psi`) on a whole record, without a
flow signal: on the rows, or on block means where the record is long (:func:`block_means`),
each block's psi put back at every row; :meth:`MapSchedule.freed` frees it where the even and
odd blocks repeat a looser prior's psi. Used by the sheathed path
(:mod:`dualprobe.estimation.without_flow`) and by the rival schedule that tests whether the
data determine a tracked one (:mod:`dualprobe.estimation.rival`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dualprobe.estimation import adaptive, level, psi_map, tracking
from dualprobe.estimation.engine import Fit

__all__ = ["SHEATHED_MAX_ROWS", "MapSchedule", "block_means"]

# The joint MAP solves a banded system of up to 5 states per row (a 30 min, 10 Hz record:
# 18 000 rows, 3-6 s with SuperLU; by banded Cholesky, estimation/banded.py, a 20 min record's
# MAP took 15 s of CPU where SuperLU took 23; the whole sheathed characterisation 15-28 s and
# 281 MB peak); it grows about linearly, so longer records run it on block means (block_means;
# on 20 min at 50 Hz, blocks to 10 Hz were 1.6-2x faster but up to 1.2x further from the oracle
# than all rows, so records within the limit use every row).
SHEATHED_MAX_ROWS = 60_000
_SHEATHED_RATE = 10.0  # Hz: block means slower than this would blur the sheaths (0.1-0.8 s)
_PSI_STEP = 0.05  # prior sd of log psi over tf (from knot to knot with one knot per tf)
_FREER_STEP = 4.0  # times _PSI_STEP: the looser prior of MapSchedule.freed (studied: README)
_KNOTS_PER_TF = 8  # psi's knots: load steps move it by 2x within a second
_REWEIGHTINGS = 2  # heavy-tailed priors in the MAP (psi_map.map_psi)
_GAS_SAFETY = 4.0  # see gas_intensity


class MapSchedule:
    """The MAP's psi of one record with the constant fit ``fit`` (its filter time constant,
    noise levels and sample interval): :attr:`usable` False where block means would be slower
    than ``_SHEATHED_RATE``. :meth:`set_model` gives the static map and the gas prior before
    any solve."""

    def __init__(self, t1: np.ndarray, t2: np.ndarray, fit: Fit) -> None:
        self.rows = t1.size
        self.fit = fit
        self.a, self.b, self.size = block_means(t1, t2, fit.ts)
        self.ts = fit.ts * self.size
        # (a resampled interval's rounding)
        self.usable = not (self.size > 1 and self.ts > (1.0 + 1e-6) / _SHEATHED_RATE)
        # a mean of `size` rows of white noise has 1/sqrt(size) of its standard deviation
        root = math.sqrt(self.size)
        self.sigma = (fit.sigma[0] / root, fit.sigma[1] / root)
        # knots every tf / _KNOTS_PER_TF (map_log scales the prior step to keep its variance
        # per second)
        self.spacing = max(1, round(fit.tf / self.ts / _KNOTS_PER_TF))
        self.centres = (np.arange(self.a.size) * self.size + 0.5 * (self.size - 1)) * fit.ts
        self.static = (1.0, 0.0)
        self.q = math.nan
        # map_log's results by (stages, rows, looser): the sheathed path asks for the same
        # MAP up to three times (schedule, psi_noise, freed's own); it is deterministic
        self._logs: dict[tuple[object, ...], np.ndarray | None] = {}
        self._patterns = psi_map.PatternStore()  # this record's MAPs share their patterns

    def set_model(self, static: tuple[float, float], tau: float) -> None:
        """``static``: (gain, offset) of sensor 1 on sensor 2, ``T1 = gain T2 + offset`` (the
        cross-relation's and the tracking's convention); ``tau``: sensor 1's dominant time
        constant at psi = 1, which sizes the gas prior (:func:`gas_intensity`). Raises
        ValueError where the gas prior cannot be formed."""
        self.static = static
        self.q = gas_intensity(self.a, self.ts, self.fit.tf, tau)
        self._logs.clear()

    def solve(self, stages: Sequence[tuple[float, ...]], rows: slice = slice(None),
              looser: float = 1.0) -> psi_map.PsiMap | None:
        """The MAP of these block rows, knots every ``spacing`` blocks' time; ``looser`` times
        the prior's knot steps."""
        step = rows.step or 1
        knots = max(1, round(self.spacing / step))
        y1, y2 = self.a[rows], self.b[rows]
        gain, offset = self.static
        try:
            with psi_map.sharing(self._patterns):
                return psi_map.map_psi(
                    np.arange(y1.size) * self.ts * step, y1, y2, stages[0], stages[1],
                    (1.0 / gain, -offset / gain), self.sigma, self.q, knots,
                    looser * _PSI_STEP * math.sqrt(knots * step * self.ts / self.fit.tf),
                    reweightings=_REWEIGHTINGS)
        except (ValueError, np.linalg.LinAlgError, RuntimeError):
            return None

    def map_log(self, stages: Sequence[tuple[float, ...]], rows: slice = slice(None),
                looser: float = 1.0) -> np.ndarray | None:
        """The MAP log psi of these block rows (mean 0)."""
        key = (tuple(tuple(pair) for pair in stages), rows.start, rows.stop, rows.step, looser)
        if key not in self._logs:
            found = self.solve(stages, rows, looser)
            log_psi = np.log(found.psi) if found is not None else None
            self._logs[key] = (log_psi - float(np.mean(log_psi)) if log_psi is not None
                               and np.all(np.isfinite(log_psi)) else None)
        cached = self._logs[key]
        return None if cached is None else cached.copy()

    def schedule(self, stages: Sequence[tuple[float, ...]]) -> np.ndarray | None:
        """The MAP psi at every row (each block's at its centre, linear between), mean log 0."""
        log_psi = self.map_log(stages)
        return None if log_psi is None else self._at_rows(log_psi)

    def _at_rows(self, log_psi: np.ndarray) -> np.ndarray:
        """psi at every row from log psi at the blocks (linear between centres), mean log 0."""
        out = np.interp(np.arange(self.rows) * self.fit.ts, self.centres, log_psi)
        return np.exp(out - float(np.mean(out)))

    def freed(self, stages: Sequence[tuple[float, ...]]) -> tuple[np.ndarray, float, float] | None:
        """The schedule with the share of a looser prior's departure from it that the even and
        odd blocks repeat (:func:`adaptive.keep_repeated`, windows of ``adaptive.WINDOW``):
        psi at every row (mean log 0), the mean share kept and the log psi noise it brings;
        None where a MAP fails.

        Why: the prior's knot steps (``_PSI_STEP``, heavy-tailed up to psi_map's cap) hold psi
        back where the load swings fast. Where the load went 500-580 K every 5.5 s the true
        psi swung 0.8-1.7 and the MAP's 1.0-1.3 (pair 30603 of field_sweep_independent.py,
        2.50x the oracle; ``_FREER_STEP`` times the step everywhere: 1.88x, but another pair
        2.11x -> 2.85x, README), so a looser psi is kept only where the data repeat it."""
        own = self.map_log(stages)
        freer = self.map_log(stages, looser=_FREER_STEP)
        halves = [self.map_log(stages, slice(k, None, 2), _FREER_STEP) for k in (0, 1)]
        if own is None or freer is None or halves[0] is None or halves[1] is None:
            return None
        blocks = np.arange(own.size)
        even, odd = (np.interp(blocks, blocks[k::2][:half.size], half)
                     for k, half in ((0, halves[0]), (1, halves[1])))
        logs = [x - float(np.mean(x)) for x in (own, freer, even, odd)]
        kept = adaptive.keep_repeated(*logs, np.ones(own.size, bool),
                                      max(2, round(adaptive.WINDOW / self.ts)))
        return self._at_rows(kept.log_psi), kept.share, kept.noise

    def psi_noise(self, stages: Sequence[tuple[float, ...]]) -> float:
        """How much of the MAP psi follows the noise, as tracking.split_noise measures the
        first-order one: the even and the odd blocks apart (the same gas and flow, independent
        noise), half the RMS difference of their log psi; NaN when a half fails."""
        halves = [self.map_log(stages, slice(k, None, 2)) for k in (0, 1)]
        return (tracking.half_difference(halves[0], halves[1])
                if halves[0] is not None and halves[1] is not None else math.nan)


def block_means(t1: np.ndarray, t2: np.ndarray, ts: float
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """Both sensors as means of blocks of ``size`` rows: the fewest that bring a record over
    ``SHEATHED_MAX_ROWS`` within it (``size`` 1: the rows themselves, the usual case). A mean
    over a block is a filter common to both sensors, so it cancels from the cross-relation and
    the MAP takes it for part of the gas; the rows left over at the end are dropped."""
    size = max(1, math.ceil(t1.size / SHEATHED_MAX_ROWS))
    if size == 1:
        return t1, t2, 1
    rows = (t1.size // size) * size
    return (t1[:rows].reshape(-1, size).mean(axis=1), t2[:rows].reshape(-1, size).mean(axis=1),
            size)


def gas_intensity(t1: np.ndarray, ts: float, tf: float, tau: float) -> float:
    """The gas random walk's intensity (K^2/s) for :func:`psi_map.map_psi`: ``_GAS_SAFETY``
    times the increments of sensor 1's first-order inverse (:func:`level.gas_level` at the
    constant fit's time constant; about 0.7 of the oracle's q on drive cycles). Given the TRUE
    stages a weaker prior is better (1.23x, 3.01x, 1.59x the oracle with the oracle's q; 1.11x,
    2.27x, 1.33x with 100 times it), but with the estimated stages psi then absorbs their
    errors (a drive cycle at 2.30x went to 3.32x with 100 times), so the factor stays at 4 (the
    sweeps in the README); a tenth of the oracle's q was worse in both (1.25x -> 1.43x)."""
    gas = level.gas_level(t1, np.full(t1.size, tau), ts, tf)
    return max(_GAS_SAFETY * float(np.mean(np.diff(gas) ** 2)) / ts, 1e-6)
