"""Never a silently wrong number: results no physics allows are refused (EstimationError, exit 3)
with what and why, in terms a test engineer can act on.

A time constant longer than a third of the record (the record cannot determine it), a
dominant time constant whose standard uncertainty exceeds its value while the model misfits (no
number at all: a wrong model fitted to what it cannot explain; seen on a gain-mismatched,
sheathed pair whose time constants follow the flow, characterised without the flow: 207 +/- 332
s and a reconstruction 2,500 K off), a complex pole pair (oscillating dynamics, which no thermal
sensor has) while the model misfits (seen on a flow-following pair with a sheath on one sensor
and unequal gains, without the flow: "6.1, 6.1 s" and a reconstruction 69 K off the gas, its
residuals at the noise because the smoother fitted a gas to the wrong model), two order-2 sensors
sharing a time constant while the model misfits (a common factor, which no pair can determine:
47.6 / 50.1 s and a gas 218 K off on a flow-following pair without the flow), a reconstructed gas
that departs from both sensors by more than two lagging sensors allow while the model misfits
(``LAG_MARGIN``), or a reconstruction that predicts a sensor worse than the other sensor's raw
reading does (the model is worse than no model).
A reconstruction is refused, with where, when it departs from the faster sensor by far more
than that sensor lags (``SURGE_MARGIN``): a time constant the tracking made up at a fast change
of the gas put the gas 447 K off there; a slow sensor held for 3 s by a 1 Hz logger, 332 K.
An asked-for order 2 whose time constants the data do not determine is refused too.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.ndimage

from dualprobe.estimation import GAP_THRESHOLD, PairEstimate, still
from dualprobe.estimation.orders import COMPLEX_NOTE
from dualprobe.estimation.settings import RECORD_FRACTION, beyond_record, dip_beyond_record
from dualprobe.io import EstimationError
from dualprobe.workflows.checks import (
    absorbs_misfit,
    describe_stages,
    misfit,
    undetermined_stages,
)

__all__ = ["LAG_MARGIN", "SURGE_MARGIN", "in_first_scale", "refuse_departing_gas",
           "refuse_implausible", "refuse_opposed", "refuse_surging_gas", "refuse_undetermined",
           "surge"]

# Two sensors lagging the same gas: T_g - T_fast ~ tau_fast T' and T_slow - T_fast ~ (tau_slow -
# tau_fast) T', so the gas departs from the fast sensor by about tau_fast / (tau_slow - tau_fast)
# times the sensors' mutual disagreement (at least once: the unresolved fluctuation). Measured on
# drive cycles (ratios 2-3.7, 1 Hz fluctuation): 0.9-2.1 times that; a misfitting model whose gas
# departed 6.7 times (for 1.8 allowed) was 90 K off the truth. Three times covers the measured
# spread with margin.
LAG_MARGIN = 3.0

def refuse_undetermined(estimate: PairEstimate, columns: tuple[str, str]) -> None:
    """Raise EstimationError (exit 3) when an asked-for order 2 has time constants the data do
    not determine (:func:`undetermined_stages`): no number. A 2 Hz pair gave 4.15 +- 46 % and
    2.86 +- 77 % s, the model "adequate" at 0.9 times the noise and the gas 28.9 K off where
    the raw fast sensor is 13.2 K off."""
    loose = undetermined_stages(estimate)
    if loose and estimate.status == "ok":
        raise EstimationError(
            f"the data do not determine the second-order time constants "
            f"({describe_stages(loose, columns)}): the stages trade against each other; use "
            "the order chosen by evidence (--order auto) or --order 1")


def _advice(estimate: PairEstimate) -> str:
    """What to try when the model does not explain the signals (the flow when none was given)."""
    model = estimate.flow_model
    if model is not None and model.column is not None:
        return ("the time constants may follow more than the flow (the gas temperature, "
                "sheaths with their own exponents)")
    return "the time constants may follow the gas flow (give --flow)"


def refuse_opposed(static: tuple[float, float] | None, columns: tuple[str, str]) -> None:
    """Refuse (EstimationError) a gain of sensor 2 relative to sensor 1 that is not positive.
    The cross-relation is blind to the gain's sign: an inverted channel gave both time
    constants right, "ok", and no reconstruction."""
    if static is not None and not static[0] > 0.0:
        raise EstimationError(
            f"{columns[1]} moves against {columns[0]} (gain {static[0]:.3g} relative to it): "
            "two sensors in one gas rise and fall together, so one column has the wrong sign "
            "(an inverted channel, a reversed thermocouple) or is not a temperature")


# A gain ratio of the pair's static map beyond this (in log) is named in a tracked refusal:
# matched sensors agree within a few per mille (a Pt-100 of class B: 0.3 K + 0.5 % of the
# temperature in deg C), the drive cycles draw gains of 0.97-1.03 each. Why: two short
# no-flow records (logger_sweep.py 141007, 150007: true ratios 0.984, 0.969) were tracked on
# searched maps of 0.866 and 0.930 that fit as well as the true ones (the joint MAP of
# estimation/psi_map.py found 0.886 on the first), the time constant 4-46x its median at the
# record's start, and the refusal sent the user to check the channels there.
_UNEQUAL_GAINS = 0.03


def refuse_implausible(estimate: PairEstimate, duration: float, columns: tuple[str, str],
                       residuals: tuple[np.ndarray, np.ndarray] | None,
                       readings: tuple[np.ndarray, np.ndarray], gas: np.ndarray | None = None,
                       static: tuple[float, float] | None = None,
                       gas_std: np.ndarray | None = None) -> None:
    """Raise EstimationError (exit 3) for results no physics allows (module docstring).
    ``gas``: the reconstruction, in sensor 1's calibration, ``gas_std`` its standard
    uncertainty; ``static``: sensor 2's map onto it (g, o) under the affine static model."""
    model = estimate.flow_model
    psi = model.psi if model is not None else None
    tracked = model is not None and model.kind == "tracked"
    for i, column in enumerate(columns):
        taus = estimate.time_constants[i]
        least = float(np.min(psi)) if psi is not None else 1.0  # psi where it is least
        longest = max(taus) / least
        if tracked and psi is not None and dip_beyond_record(taus, psi, duration):
            # only the tracked schedule's dip is that long: one sensor drifting 3 K against
            # the other over 20 min was tracked as time constants varying 470-fold (1.3 s to
            # 616 s) and refused with "record longer", which the record did not need
            row = int(np.argmin(psi))
            at = row / max(psi.size - 1, 1) * duration
            reach = math.ceil(max(taus) / float(np.median(psi)) / duration * psi.size)
            moved = float(still.movement(readings, reach)[row])
            gain, offset = static if static is not None else (1.0, 0.0)
            if moved < still.STILL_RANGE * max(estimate.noise_std):
                cause = (f"the readings move by only {moved:.2g} K there: the gas stands "
                         "still, so nothing there determines a time constant; trim the record "
                         "to where the temperature changes (--window)")
            elif not gain > 0.0 or abs(math.log(gain)) > _UNEQUAL_GAINS:
                cause = (f"the tracking needed {columns[0]} = {gain:.4g} x {columns[1]} "
                         f"{offset:+.4g} K, a gain ratio far from equal sensors': a gain "
                         "difference and time constants that change with the temperature "
                         "explain these readings alike, and without the flow the data do not "
                         "tell them apart")
            else:
                cause = ("the tracking absorbed something the model lacks (one sensor "
                         "drifting against the other, a channel that stops following the "
                         "gas), not a time constant; check both channels there")
            raise EstimationError(
                f"{column}: the tracked time constant reaches {longest:.4g} s at {at:.0f} s "
                f"into the record ({float(np.median(psi) / np.min(psi)):.3g} times its "
                f"median), longer than a third of the record ({RECORD_FRACTION * duration:.4g} "
                f"s of {duration:.4g} s): {cause}, give --flow, or --track off for constant "
                "time constants (their misfit reported)")
        if beyond_record(taus, least, duration):
            raise EstimationError(
                f"{column}: time constant {longest:.4g} s is longer than a third of the record "
                f"({RECORD_FRACTION * duration:.4g} s of {duration:.4g} s): the record cannot "
                "determine it; record longer, or with "
                "larger and faster temperature changes"
                + (" (or use --order 1)" if len(taus) > 1 else ""))
    if gas is not None:
        refuse_surging_gas(estimate, gas, readings, static, duration, columns, gas_std)
    mu, statistic = misfit(estimate)
    misfits = math.isfinite(statistic) and statistic > GAP_THRESHOLD
    confidence = estimate.confidence
    if confidence is not None and misfits:
        for i, column in enumerate(columns):
            name = f"tau{i + 1}_0"  # the dominant time constant
            value = confidence.values.get(name, math.nan)
            std = confidence.std.get(name, math.nan)
            if std > abs(value):  # not even its sign is determined: no number at all
                raise EstimationError(
                    f"{column}: time constant {value:.3g} +/- {std:.2g} s: the data do not "
                    f"determine it and the model does not explain the signals (misfit {mu:.3g} "
                    f"x the noise); {_advice(estimate)}, or the sensors differ in a way the "
                    "model lacks (try --order 1, or dualprobe diagnose)")
    if misfits:
        notes = estimate.identifiability.get("notes", [])
        for i, column in enumerate(columns):
            if isinstance(notes, list) and f"sensor {i + 1}: {COMPLEX_NOTE}" in notes:
                raise EstimationError(
                    f"{column}: the fitted dynamics oscillate (a complex pole pair, which no "
                    f"thermal sensor has) and the model does not explain the signals (misfit "
                    f"{mu:.3g} x the noise): no reconstruction can be trusted; "
                    f"{_advice(estimate)}, or try --order 1 or dualprobe diagnose")
        shared = absorbs_misfit(estimate.time_constants)
        if shared is not None:
            raise EstimationError(
                f"both sensors' fitted dynamics share a time constant ({shared[0]:.3g} and "
                f"{shared[1]:.3g} s) and the model does not explain the signals (misfit "
                f"{mu:.3g} x the noise): a factor common to both sensors is invisible to a pair, "
                f"so the data do not determine it; {_advice(estimate)}, or try --order 1 or "
                "dualprobe diagnose")
        if gas is not None:
            refuse_departing_gas(estimate, gas, readings, static, mu)
    if residuals is None:
        return
    spread = float(np.sqrt(np.mean((readings[0] - readings[1]) ** 2)))
    for i, column in enumerate(columns):
        rms = float(np.sqrt(np.nanmean(residuals[i] ** 2)))
        if rms > spread:
            raise EstimationError(
                f"{column}: the identified model predicts this sensor worse ({rms:.3g} K RMS) "
                f"than the other sensor's raw reading does ({spread:.3g} K): the time constants "
                "do not describe these signals; check that both sensors see the same gas, or "
                "try --order 1 or --flow")


def in_first_scale(readings: tuple[np.ndarray, np.ndarray], static: tuple[float, float] | None,
                   sensor: int) -> np.ndarray:
    """A sensor's readings in sensor 1's calibration, the reconstruction's (sensor 2 through
    the affine static map (g, o) when it holds)."""
    if sensor == 0 or static is None:
        return readings[sensor]
    return static[0] * readings[1] + static[1]


def refuse_departing_gas(estimate: PairEstimate, gas: np.ndarray,
                          readings: tuple[np.ndarray, np.ndarray],
                          static: tuple[float, float] | None, mu: float) -> None:
    """Refuse (the model misfits) a gas that departs from both sensors by more than
    ``LAG_MARGIN`` times what two lagging sensors allow (module docstring)."""
    u1, u2 = (in_first_scale(readings, static, i) for i in (0, 1))
    ok = np.isfinite(gas)
    if not np.any(ok):
        return
    spread = float(np.sqrt(np.mean((u1[ok] - u2[ok]) ** 2)))
    departure = min(float(np.sqrt(np.mean((gas[ok] - u[ok]) ** 2))) for u in (u1, u2))
    fast, slow = sorted((estimate.time_constants[0][0], estimate.time_constants[1][0]))
    if not (math.isfinite(fast) and math.isfinite(slow) and slow > fast):
        return  # equal time constants: no lag relation to judge by
    allowed = max(1.0, fast / (slow - fast))
    if departure > LAG_MARGIN * allowed * spread:
        raise EstimationError(
            f"the reconstructed gas departs from both sensors by {departure:.3g} K RMS, "
            f"{departure / spread:.2g} times their mutual disagreement ({spread:.3g} K) where "
            f"sensors lagging with these time constants allow about {allowed:.2g} times, and the "
            f"model does not explain the signals (misfit {mu:.3g} x the noise): the "
            f"reconstruction cannot be trusted; {_advice(estimate)}, or try --order 1 or "
            "dualprobe diagnose")


# A reconstruction may depart from the faster sensor by at most this many times what that
# sensor lags by: its time constants (all stages, at the schedule's median) times its steepest
# change within the slower sensor's time constant either side, plus its largest change over one
# row, plus 10 noise standard deviations. Measured (2026-12-04; the first three before the
# one-row term, which only adds allowance): 0.72-1.74 on the 36 tracked sweep pairs
# (field_sweep.py 1 8 / 7 12 noflow, field_sweep_independent.py 53 8 / 50 8; 1.1-5.6x the
# oracle), 0.63-2.30 on the other 31 runs of logger_sweep.py 81 8 / 82 8 short (1-50 Hz, jitter,
# holds; tracked 0.67-1.93); 7.07 on the one that put the gas 447 K off with exit 0 (a tracked
# time constant at 6.9 times its median within 1.5 s of a 160 K drop of the gas, 2 Hz, 400 s;
# test_surge.py). Every schedule: 0.15-2.12 on 14 laboratory step records (0.01-1 s rows),
# 0.55-1.92 on the 16 runs of logger_sweep.py 84 8 short, 1.13-1.31 on field_sweep.py 1 8 flow;
# 6.07 on a 1 Hz slow sensor held 3 s left as a staircase (a 332 K dip; test_surge.py).
SURGE_MARGIN = 4.0
_SURGE_FLOOR = 10.0  # noise standard deviations: a still gas's departure is noise


def surge(estimate: PairEstimate, gas: np.ndarray, readings: tuple[np.ndarray, np.ndarray],
          static: tuple[float, float] | None, ts: float, gas_std: np.ndarray | None = None
          ) -> tuple[float, int, int, float]:
    """(the largest departure of ``gas`` from the faster sensor over what that sensor lags by
    allows, the row where, the faster sensor's index, the departure there in K):
    ``SURGE_MARGIN``. Within the slower lag of either end of the record the reconstruction's
    own standard uncertainty ``gas_std`` is allowed too: there the smoother sees one side
    only. A pair at 1.03x the oracle (5 Hz, 0.1 K ADC steps) was refused for its last row,
    10.3 K from a fast sensor quantised flat where the gas had risen 4 K in two rows (the
    reconstruction 7.9 K off, its standard uncertainty 5.8 K). Not elsewhere: a surge inside
    the record comes with a wide uncertainty of its own (a tracked time constant at 7 times
    its median put the gas 447 K off within its uncertainty), and is refused."""
    psi = estimate.flow_model.psi if estimate.flow_model is not None else None
    scale = float(np.median(psi)) if psi is not None else 1.0
    lags = [sum(taus) / scale for taus in estimate.time_constants]
    fast = int(np.argmin(lags))
    u = in_first_scale(readings, static, fast)
    reach = max(1, round(max(lags) / ts))
    steps = np.abs(np.diff(u, prepend=u[0]))
    slope = scipy.ndimage.maximum_filter1d(np.abs(np.gradient(u, ts)), 2 * reach + 1)
    # plus the largest change over one row: a sensor faster than the rows has jumped by
    # that much between two readings where its time constant times the slope is less
    step = scipy.ndimage.maximum_filter1d(steps, 2 * reach + 1)
    allowed = lags[fast] * slope + step + _SURGE_FLOOR * max(estimate.noise_std)
    if gas_std is not None:
        edges = np.zeros(gas.size, dtype=bool)
        edges[:reach] = edges[-reach:] = True
        allowed = allowed + np.where(edges & np.isfinite(gas_std), gas_std, 0.0)
    departure = np.abs(gas - u)
    # no allowance (noise-free readings standing still, --noise-std 0): no judgement there
    ratio = np.divide(departure, allowed, out=np.zeros_like(departure),
                      where=np.isfinite(departure) & (allowed > 0.0))
    row = int(np.argmax(ratio))
    return float(ratio[row]), row, fast, float(departure[row])


def refuse_surging_gas(estimate: PairEstimate, gas: np.ndarray,
                       readings: tuple[np.ndarray, np.ndarray],
                       static: tuple[float, float] | None, duration: float,
                       columns: tuple[str, str], gas_std: np.ndarray | None = None) -> None:
    """Refuse a reconstruction that departs from the faster sensor by more than
    ``SURGE_MARGIN`` times what that sensor lags by (:func:`surge`)."""
    ts = duration / max(readings[0].size - 1, 1)
    ratio, row, fast, departure = surge(estimate, gas, readings, static, ts, gas_std)
    if not ratio > SURGE_MARGIN:
        return
    model = estimate.flow_model
    where = (f"the reconstructed gas departs from {columns[fast]} by {departure:.4g} K at "
             f"{row * ts:.0f} s into the record, {ratio:.3g} times what a sensor lagging with "
             "its time constants allows")
    if model is not None and model.kind == "tracked":
        raise EstimationError(
            f"{where} (the tracked time constant there "
            f"{float(np.median(model.psi) / model.psi[row]):.3g} times its median): the "
            "tracking absorbed something the model lacks there, not a time constant; give "
            "--flow, trim the record (--window), or --track off for constant time constants "
            "(their misfit reported)")
    raise EstimationError(
        f"{where}: the model lacks something the readings show there (a channel held, "
        "stuck or resampled by its logger, a sensor of higher order, a delay); check both "
        "channels there, trim the record (--window), or run dualprobe diagnose")
