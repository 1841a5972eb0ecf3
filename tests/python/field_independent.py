"""Field recordings from a generator written apart from ``dualprobe.simulate`` (issue 11).

Nothing here comes from the product: its own drive trace (idle, accelerations, cruises with a
slow speed wobble, decelerations), its own engine (road load -> load, smoothed by 0.4 s), its own
gas (a fast 0.3 s and a slow 25 s path from the load, plus a 0.15 s band-limited 1.5 K
fluctuation) and its own exhaust: the mass flow follows the load, the gas velocity is mass flow
x T (ideal gas at a constant pressure). The sensors follow the VELOCITY, ``tau = tau_ref (v /
v_ref)^-m`` for the element and the optional sheath in front of it, integrated by classical RK4
on a 2 ms grid (not the product's exact exponential steps). The recording offers the MASS flow
as its flow column (what an ECU has), so a power law in that column alone is not the truth: the
time constants also follow the gas temperature. Logger effects: noise, ADC steps, sampling-
instant jitter, sensor 2 held for several rows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

DT = 0.002  # s: the integration grid


@dataclass(frozen=True)
class Recording:
    t: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    mass_flow: np.ndarray
    gas: np.ndarray  # true gas in sensor 1's calibration (gain 1 times the gas)
    tau1: np.ndarray  # elements' time constants in effect at the rows
    tau2: np.ndarray
    sheath1: np.ndarray  # zeros without a sheath
    sheath2: np.ndarray
    noise: float
    ts: float


def _lowpass(x: np.ndarray, tau: float) -> np.ndarray:
    a = math.exp(-DT / tau)
    return np.asarray(lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])[0])


def _speed(n: int, rng: np.random.Generator) -> np.ndarray:
    v = np.zeros(n)
    k, speed = 0, 0.0
    while k < n:
        kind = rng.choice(["idle", "accel", "cruise", "decel"], p=[0.15, 0.3, 0.35, 0.2])
        low, high = {"idle": (5, 40), "accel": (4, 20), "cruise": (10, 80), "decel": (3, 15)}[kind]
        steps = np.arange(int(rng.uniform(low, high) / DT)) * DT
        if kind == "idle":
            seg = np.zeros(steps.size)
        elif kind == "accel":
            seg = np.minimum(speed + rng.uniform(0.4, 2.5) * steps, 36.0)
        elif kind == "decel":
            seg = np.maximum(speed - rng.uniform(0.5, 3.0) * steps, 0.0)
        else:
            seg = np.maximum(speed + 0.6 * np.sin(2 * math.pi * steps / rng.uniform(5, 20)), 0.0)
        v[k:k + seg.size] = seg[:n - k]
        speed = float(seg[-1]) if seg.size else speed
        k += seg.size
    return v


def _sensor(gas: np.ndarray, psi: np.ndarray, tau: float, sheath: float,
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RK4 through gas -> sheath (optional) -> element, time constants ``tau / psi``."""
    tau_e = tau / psi
    tau_s = sheath / psi if sheath > 0 else None
    y = np.empty(gas.size)
    s = e = float(gas[0])
    for k in range(gas.size):
        y[k] = e
        if k == gas.size - 1:
            break
        u0, u1 = gas[k], gas[k + 1]
        um = 0.5 * (u0 + u1)
        te0, te1 = tau_e[k], tau_e[k + 1]
        tem = 0.5 * (te0 + te1)
        if tau_s is None:
            k1 = (u0 - e) / te0
            k2 = (um - e - 0.5 * DT * k1) / tem
            k3 = (um - e - 0.5 * DT * k2) / tem
            k4 = (u1 - e - DT * k3) / te1
            e += DT / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
            continue
        ts0, ts1 = tau_s[k], tau_s[k + 1]
        tsm = 0.5 * (ts0 + ts1)
        a1, b1 = (u0 - s) / ts0, (s - e) / te0
        a2, b2 = (um - s - 0.5 * DT * a1) / tsm, (s + 0.5 * DT * a1 - e - 0.5 * DT * b1) / tem
        a3, b3 = (um - s - 0.5 * DT * a2) / tsm, (s + 0.5 * DT * a2 - e - 0.5 * DT * b2) / tem
        a4, b4 = (u1 - s - DT * a3) / ts1, (s + DT * a3 - e - DT * b3) / te1
        s += DT / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
        e += DT / 6.0 * (b1 + 2 * b2 + 2 * b3 + b4)
    return y, tau_e, (tau_s if tau_s is not None else np.zeros(gas.size))


def record(seed: int, *, duration: float = 1200.0, rate: float = 10.0, tau: float = 4.0,
           ratio: float = 3.0, m: float = 0.5, sheaths: tuple[float, float] = (0.0, 0.0),
           gains: tuple[float, float] = (1.0, 1.0), noise: float = 0.05, adc: float = 0.02,
           jitter: float = 0.0, hold: int = 1, common: float = 0.0) -> Recording:
    """A pair on a drive cycle (module docstring); ``jitter`` the sampling instants' standard
    deviation (s; the logged time stays nominal), ``hold`` rows per refresh of sensor 2.

    ``common`` (s at v_ref, at most the smaller sheath) moves that much of both sheaths into
    the gas: the gas is taken as seen through a stage of ``common / psi`` and each sheath
    shortens by it. The drive cycle, noise and everything else stay the same draws, so this
    is the same pair in another world whose readings differ only by the stage ordering of the
    shortened sheath (nothing when the sheaths were equal): a lag common to both sensors."""
    if not 0.0 <= common <= min(sheaths):
        raise ValueError("common must lie between 0 and the smaller sheath")
    rng = np.random.default_rng(seed)
    n = int(duration / DT)
    v = _speed(n, rng)
    acceleration = np.gradient(v, DT)
    power = v * (np.maximum(acceleration, -0.3) + 0.15 + 4e-4 * v * v)
    load = _lowpass(np.clip(0.08 + power / 60.0, 0.05, 1.0), 0.4)
    fluctuation = _lowpass(rng.standard_normal(n), 0.15)
    gas = (430.0 + 180.0 * _lowpass(load, 0.3) + 160.0 * _lowpass(load, 25.0)
           + 1.5 * fluctuation / np.std(fluctuation))
    mass_flow = 0.012 + 0.09 * _lowpass(load, 0.2) ** 1.1
    velocity = mass_flow * gas  # ideal gas at constant pressure: v ~ mdot T
    psi = (velocity / math.exp(float(np.mean(np.log(velocity))))) ** m
    if common > 0.0:  # the gas as the common stage passes it; the sheaths keep the rest
        gas = _sensor(gas, psi, common, 0.0)[0]
        sheaths = (sheaths[0] - common, sheaths[1] - common)
    y1, te1, ts1 = _sensor(gas, psi, tau, sheaths[0])
    y2, te2, ts2 = _sensor(gas, psi, tau * ratio, sheaths[1])
    idx = np.arange(0, n, round(1.0 / (rate * DT)))
    if jitter > 0:
        idx = np.clip(idx + np.round(rng.normal(0.0, jitter, idx.size) / DT).astype(int), 0, n - 1)
    r1 = gains[0] * y1[idx] + rng.normal(0.0, noise, idx.size)
    r2 = gains[1] * y2[idx] + rng.normal(0.0, noise, idx.size)
    if adc > 0:
        r1, r2 = np.round(r1 / adc) * adc, np.round(r2 / adc) * adc
    if hold > 1:
        r2 = np.repeat(r2[::hold], hold)[:r2.size]
    return Recording(np.arange(idx.size) / rate, r1, r2, mass_flow[idx], gains[0] * gas[idx],
                     te1[idx], te2[idx], ts1[idx], ts2[idx], noise, 1.0 / rate)
