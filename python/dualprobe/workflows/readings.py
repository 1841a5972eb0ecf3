"""The sensors' readings as the estimation needs them: a stuck channel refused by name
(:mod:`dualprobe.models.stuck`), held readings interpolated between their refreshes
(:mod:`dualprobe.models.held`), spikes replaced (:mod:`dualprobe.models.spikes`), a jittered
sampling clock named (:mod:`dualprobe.models.jitter`), each said in a note."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dualprobe.io import EstimationError, InputError
from dualprobe.models.held import SENSOR_REFRESH, held_noise_std, is_held, unhold
from dualprobe.models.jitter import equivalent_noise_std, jitter_variance
from dualprobe.models.noise import ORDER_ESTIMATION
from dualprobe.models.spikes import MAX_RUN, MAX_SHARE, Spikes, despike
from dualprobe.models.stuck import refuse_stuck

__all__ = ["check_excitation", "parse_noise_std", "prepare_readings"]

_LISTED = 3  # spikes named in a note


def _spike_note(column: str, spikes: Spikes, time: np.ndarray) -> str:
    where = ", ".join(f"{spikes.sizes[i]:+.3g} K at t = {time[spikes.starts[i]]:.6g} s"
                      for i in np.argsort(-np.abs(spikes.sizes))[:_LISTED])
    more = f" and {len(spikes) - _LISTED} more" if len(spikes) > _LISTED else ""
    what = (f"{column}: {len(spikes)} run{'s' if len(spikes) > 1 else ''} of 1-{MAX_RUN} "
            f"readings that jump away from both neighbours and back by over "
            f"{spikes.threshold:.3g} K, which no lagging sensor can do ({where}{more}; "
            "pickup on the leads, bit errors, dropouts)")
    if spikes.replaced:
        return what + ": replaced by straight lines between their neighbours"
    return (what + f": over {MAX_SHARE:.0%} of the rows, so the rule may not fit this sensor; "
            "left as they are")


def prepare_readings(
    t1: np.ndarray, t2: np.ndarray, ts: float, sigma: tuple[float, float] | None,
    columns: tuple[str, str], time: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, tuple[float, float] | None, tuple[str, ...], bool]:
    """(t1, t2, noise levels, notes, whether a sensor was interpolated between its logger's
    refreshes); an :class:`InputError` naming a stuck channel
    (:func:`dualprobe.models.stuck.find_stuck`) and the longest stretch without one.

    A sensor whose logger holds its readings (:func:`dualprobe.models.held.unhold`) is
    interpolated between its refreshes, and its noise counted once per refresh
    (:func:`dualprobe.models.held.held_noise_std`; a given level times sqrt(rows)). Why: the
    staircase is a delay no sensor model has, and the time constants absorbed it. Separate
    generator, the slow sensor held: 5 Hz for 3 rows, 10.8x the oracle with the flow (12.5x
    without), interpolated 1.12x (1.47x); 2 Hz for 2 rows, the fast sensor's per-row time
    constant 31 % off and 2.6x, interpolated 1.1 % and 0.90x.

    A sensor that is not held, regularly or not, has its spikes replaced
    (:func:`dualprobe.models.spikes.despike`: three 30 K spikes in 12 000 rows took the gas
    from 1.07x the oracle to 10.1x). Unchanged, with no notes, when neither is held nor
    spiked."""
    stamps = (np.asarray(time, dtype=float) if time is not None and np.shape(time) == t1.shape
              else np.arange(t1.size) * ts)
    held = [unhold(x, ts, smooth=True, longest=SENSOR_REFRESH) for x in (t1, t2)]
    refuse_stuck([(columns[0], t1, columns[1], t2), (columns[1], t2, columns[0], t1)], ts,
                 stamps)
    values, notes = [], []
    for raw, (x, _), column in zip((t1, t2), held, columns, strict=True):
        if not is_held(raw, ts, SENSOR_REFRESH):
            # an irregular hold (left to the model check, which names it) is a staircase: its
            # curvature scale is zero between refreshes and each turn looked like a spike
            x, spikes = despike(x)
            if len(spikes):
                notes.append(_spike_note(column, spikes, stamps))
        values.append(x)
    jitters = [jitter_variance(x, ts) for x in values]
    for j2, column in zip(jitters, columns, strict=True):
        if j2 > 0.0:
            notes.append(f"{column}: its noise grows with its slope, as readings taken about "
                         f"{1e3 * math.sqrt(j2):.2g} ms early or late and logged at the nominal "
                         "instant make it (a jittered sampling clock): judged by its mean over "
                         "the record, and each row's noise counted as its slope makes it in the "
                         "reconstruction")
    if all(rows == 1 for _, rows in held) and not any(jitters):
        return values[0], values[1], sigma, tuple(notes), False  # noise: by the estimation
    levels = []
    for index, (x, (_, rows), column) in enumerate(zip((t1, t2), held, columns, strict=True)):
        # held_noise_std is estimate_noise_std on a sensor that is not held
        level = (held_noise_std(x, ts, ORDER_ESTIMATION, SENSOR_REFRESH) if sigma is None
                 else sigma[index] * math.sqrt(rows))
        if jitters[index] > 0.0:
            # the white level a misfit over all rows is judged by (the reconstruction spreads
            # it over the rows by their slopes: models/jitter.py); a given level is the
            # sensor's own noise, and the jitter adds to it
            level = equivalent_noise_std(level, values[index], ts, jitters[index])
        levels.append(level)
        if rows > 1:
            notes.append(f"{column} holds its readings for {rows} rows per refresh (a logger "
                         "refreshing slower than the rows): interpolated between its refreshes, "
                         f"its noise ({level / math.sqrt(rows):.3g} K per reading) counted once "
                         f"per refresh ({level:.3g} K per row in the noise std)")
    refreshed = any(rows > 1 for _, rows in held)
    return values[0], values[1], (levels[0], levels[1]), tuple(notes), refreshed


def parse_noise_std(noise_std: float | Sequence[float] | None) -> tuple[float, float] | None:
    """A --noise-std argument: one value for both sensors or one each, finite and >= 0."""
    if noise_std is None:
        return None
    values = (
        [float(noise_std)] * 2
        if isinstance(noise_std, (int, float, np.floating))
        else [float(v) for v in noise_std]
    )
    if len(values) == 1:
        values *= 2
    if len(values) != 2:
        raise InputError(f"noise std: expected one or two values, got {len(values)}")
    for value in values:
        if not math.isfinite(value) or value < 0.0:
            raise InputError(f"noise std: must be finite and >= 0, got {value!r}")
    return values[0], values[1]


def check_excitation(t1: np.ndarray, t2: np.ndarray, columns: tuple[str, str]) -> None:
    """A constant column is refused: nothing in it can determine a time constant."""
    for column, values in zip(columns, (t1, t2), strict=True):
        if np.ptp(values) == 0.0:
            raise EstimationError(
                f"no excitation: column {column!r} is constant ({values[0]:.6g}); the time "
                "constants need a recording in which the temperature changes"
            )
