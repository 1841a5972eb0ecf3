"""Test data with hidden effects beyond the issue-5 catalogue (issue 14): field conditions,
time constants that follow the flow or the temperature level, drift, logger effects, and
misfits that no catalogue entry describes.

Written independently of ``dualprobe.diagnose`` (never imported here), like
``hidden_effects.py`` whose laboratory gas it reuses. The sensors are simulated by
``dualprobe.simulate.drive_cycle`` (exact per 5-ms step for a time constant that follows the
gas velocity and the gas temperature, checked against LSODA in test_drive_cycle.py), the
conditions are either

* ``drive``: a vehicle drive cycle (``simulate.drive_cycle.drive_cycle``): exhaust gas 187-427
  degC following the engine load, through the manifold wall, with a 1 Hz band-limited
  fluctuation; gas velocity 7-60 m/s; or
* ``lab``: the laboratory gas of ``hidden_effects.random_gas`` (off-grid steps, ramps,
  fluctuations, 60-340 degC) at a constant velocity of 20 m/s; or
* ``plunge``: a thermocouple plunged between air at ~22 degC and a bath at ~52 degC every
  4-10 s (a real logger's record).

The reference is a fine thermocouple following the velocity with m = 0.5 (10-30 ms at 20 m/s;
2-6 ms in the drive cycle, whose gas changes within 0.3 s; 1-3 ms for a plunge at 15 ms rows);
the sensor under test is first order with, by the effects asked for:

* ``flow_dependence``: ``tau = tau_ref (v / 20 m/s)^-m``, m = 0.35-0.7 (paper eq. 1);
* ``level_dependence``: ``tau = tau_ref (Tg / 473.15 K)^-n``, n = 0.4-1.0 (gas properties and
  radiation: faster at high temperature);
* ``drift``: the reading drifts linearly from 0 at the start by 0.5-2 K over the record;
* ``sample_and_hold``: the logger refreshes the reading every 2-6 rows;
* ``quantisation``: both readings on a grid of 0.1-0.5 K, over 0.01-0.03 K of analogue noise.

Out-of-catalogue misfits (no catalogue effect describes them):

* ``pickup``: intermittent 0.4 Hz interference on the reading, bursts of 20-60 s (Hann envelope,
  peak 10-20 times the reading's noise, 0.3-1.6 K) over about a quarter of the record (2-4 times
  the noise in RMS over the record; the issue's case was 8 times);
* ``sticking``: the reading freezes for 2-6 s, about once a minute, while the sensor moves.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from dualprobe.simulate.drive_cycle import DriveCycle, FieldSensor, drive_cycle, simulate_field_pair
from hidden_effects import GasSegments, random_gas

FIELD_EFFECTS = ("flow_dependence", "level_dependence", "drift", "sample_and_hold", "quantisation")
MISFITS = ("pickup", "sticking")
KELVIN = 273.15
V_REF = 20.0  # m/s
LEVEL_REFERENCE = 473.15  # K
FINE_STEP = 0.005  # s


@dataclass
class FieldCase:
    """A recording: `reference` is the input column, `measured` the output, `flow` the gas
    velocity (m/s), `gas` the true gas temperature (degC)."""

    t: np.ndarray
    ts: float
    reference: np.ndarray
    measured: np.ndarray
    flow: np.ndarray
    gas: np.ndarray
    effects: tuple[str, ...]
    conditions: str
    truth: dict[str, float] = field(default_factory=dict)


def _conditions_from_gas(gas: GasSegments, duration: float) -> DriveCycle:
    """Laboratory conditions on the fine grid: the gas (K) at a constant velocity."""
    t = np.arange(0.0, duration + 1.0, FINE_STEP)
    zeros = np.zeros(t.size)
    velocity = np.full(t.size, V_REF)
    return DriveCycle(t, zeros, zeros, zeros, zeros, gas(t) + KELVIN, velocity)


def _plunge_gas(rng: np.random.Generator, duration: float) -> GasSegments:
    """Air at 21-23 degC and a bath at 50-54 degC, alternating every 4-10 s (off-grid)."""
    starts, levels = [0.0], [rng.uniform(21.0, 23.0)]
    now = rng.uniform(2.0, 4.0)
    while now < duration + 1.0:
        starts.append(now)
        levels.append(rng.uniform(50.0, 54.0) if len(levels) % 2 else rng.uniform(21.0, 23.0))
        now += rng.uniform(4.0, 10.0)
    start = np.array(starts)
    end = np.concatenate((start[1:], [1e6]))
    value = np.array(levels)
    return GasSegments(start, end, value, value.copy())


def _bursts(
    rng: np.random.Generator, t: np.ndarray, share: float, length: tuple[float, float]
) -> list[tuple[int, int]]:
    """Random non-overlapping index ranges covering about `share` of the record."""
    ts = float(t[1] - t[0])
    out: list[tuple[int, int]] = []
    covered = 0.0
    total = float(t[-1] - t[0])
    tries = 0
    while covered < share * total and tries < 1000:
        tries += 1
        span = rng.uniform(*length)
        begin = rng.uniform(t[0], t[-1] - span)
        i, j = int(begin / ts), int((begin + span) / ts)
        if any(i < b + 10 and j > a - 10 for a, b in out):
            continue
        out.append((i, j))
        covered += span
    return out


def _pickup(
    rng: np.random.Generator, t: np.ndarray, sigma: float, truth: dict[str, float]
) -> np.ndarray:
    amplitude = float(rng.uniform(10.0, 20.0) * sigma)
    truth["pickup_amplitude"] = amplitude
    out = np.zeros(t.size)
    for i, j in _bursts(rng, t, 0.25, (20.0, 60.0)):
        phase = rng.uniform(0.0, 2.0 * np.pi)
        envelope = np.hanning(j - i)
        out[i:j] = amplitude * envelope * np.sin(2.0 * np.pi * 0.4 * t[i:j] + phase)
    return out


def _stick(
    rng: np.random.Generator, reading: np.ndarray, clean: np.ndarray, ts: float
) -> tuple[np.ndarray, int]:
    """Freeze the reading for 2-6 s about once a minute, starting where the sensor moves."""
    rate = np.abs(np.gradient(clean, ts))
    moving = np.flatnonzero(rate > 0.2)
    out = reading.copy()
    count = max(1, round(reading.size * ts / 60.0))
    if moving.size == 0:
        return out, 0
    stuck = 0
    for start in np.sort(rng.choice(moving, size=min(count, moving.size), replace=False)):
        length = round(rng.uniform(2.0, 6.0) / ts)
        out[start : start + length] = out[start]
        stuck += 1
    return out, stuck


def make_field_case(
    effects: Sequence[str],
    seed: int,
    *,
    conditions: str | None = None,
    duration: float = 1200.0,
    ts: float = 0.1,
    misfit: str | None = None,
) -> FieldCase:
    """Recording of a sensor with the hidden `effects` (names from FIELD_EFFECTS) and an
    optional out-of-catalogue `misfit` (from MISFITS), random parameters of realistic size
    drawn from `seed`. Conditions: ``drive`` for flow_dependence, else ``lab``, unless given."""
    unknown = set(effects) - set(FIELD_EFFECTS)
    if unknown or (misfit is not None and misfit not in MISFITS):
        raise ValueError(f"make_field_case: unknown effects {sorted(unknown)} / misfit {misfit}")
    rng = np.random.default_rng(seed)
    where = conditions or ("drive" if "flow_dependence" in effects else "lab")
    tau = float(np.exp(rng.uniform(np.log(2.0), np.log(10.0))))
    if where == "plunge":
        tau = float(rng.uniform(0.4, 1.5))
    truth: dict[str, float] = {"tau_ref": tau}
    quantised = "quantisation" in effects
    sigma_ref, sigma_out = rng.uniform(0.01, 0.03, 2) if quantised else rng.uniform(0.03, 0.08, 2)
    truth["noise_reference"], truth["noise_measured"] = float(sigma_ref), float(sigma_out)
    exponent = float(rng.uniform(0.35, 0.7)) if "flow_dependence" in effects else 0.0
    level = float(rng.uniform(0.4, 1.0)) if "level_dependence" in effects else 0.0
    truth["flow_exponent"], truth["level_exponent"] = exponent, level
    if where == "drive":
        cycle = drive_cycle(duration + 1.0, rng, dt=FINE_STEP)
    elif where == "lab":
        cycle = _conditions_from_gas(random_gas(rng, duration, tau), duration)
    else:
        cycle = _conditions_from_gas(_plunge_gas(rng, duration), duration)
    sensor = FieldSensor(
        tau,
        exponent,
        level_exponent=level,
        level_reference=LEVEL_REFERENCE,
        noise_std=float(sigma_out),
    )
    # Drive-cycle gas changes within 0.3 s: a reference that lags by tens of ms would leave a
    # structured misfit of its own (2x the noise at 27 ms); a 25-um wire follows in 2-6 ms. A
    # plunge at 15 ms rows needs one faster than a row (a 13-um wire, 1-3 ms).
    fast_range = {"drive": (0.002, 0.006), "lab": (0.01, 0.03), "plunge": (0.001, 0.003)}[where]
    tau_fast = float(rng.uniform(*fast_range))
    truth["tau_reference"] = tau_fast
    fast = FieldSensor(tau_fast, 0.5, noise_std=float(sigma_ref))
    rec = simulate_field_pair(cycle, fast, sensor, sample_rate=1.0 / ts, v_ref=V_REF, rng=rng)
    t = rec.t
    reference = rec.t1 - KELVIN
    measured = rec.t2 - KELVIN
    clean = rec.t2_clean - KELVIN
    truth["tau_min"], truth["tau_max"] = float(rec.tau2.min()), float(rec.tau2.max())
    if "drift" in effects:
        total = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 2.0))
        truth["drift_total"] = total
        measured = measured + total * (t - t[0]) / (t[-1] - t[0])
    if misfit == "pickup":
        measured = measured + _pickup(rng, t, float(sigma_out), truth)
    if quantised:
        step = float(rng.choice([0.1, 0.2, 0.25, 0.5]))
        truth["quantisation_step"] = step
        reference = np.round(reference / step) * step
        measured = np.round(measured / step) * step
    if misfit == "sticking":
        measured, stuck = _stick(rng, measured, clean, ts)
        truth["sticks"] = float(stuck)
    if "sample_and_hold" in effects:
        hold = int(rng.integers(2, 7))
        phase = int(rng.integers(0, hold))
        truth["hold_samples"], truth["hold_phase"] = float(hold), float(phase)
        latest = np.clip(phase + ((np.arange(t.size) - phase) // hold) * hold, 0, None)
        measured = measured[latest]
    return FieldCase(
        t=t,
        ts=ts,
        reference=reference,
        measured=measured,
        flow=rec.flow,
        gas=rec.tg - KELVIN,
        effects=tuple(effects),
        conditions=where,
        truth=truth,
    )


def make_logger_case(seed: int, *, duration: float = 120.0) -> FieldCase:
    """A thermocouple plunge record from a logger: 15 ms rows, both readings on a 0.25 K grid,
    the sensor's reading refreshed every 5 rows (held 75 ms)."""
    rng = np.random.default_rng(seed)
    case = make_field_case((), seed, conditions="plunge", duration=duration, ts=0.015)
    hold = 5
    phase = int(rng.integers(0, hold))
    latest = np.clip(phase + ((np.arange(case.t.size) - phase) // hold) * hold, 0, None)
    reference = np.round(case.reference / 0.25) * 0.25
    measured = (np.round(case.measured / 0.25) * 0.25)[latest]
    truth = {**case.truth, "quantisation_step": 0.25, "hold_samples": 5.0, "hold_phase": phase}
    return FieldCase(
        case.t,
        case.ts,
        reference,
        measured,
        case.flow,
        case.gas,
        ("quantisation", "sample_and_hold"),
        "plunge",
        truth,
    )
