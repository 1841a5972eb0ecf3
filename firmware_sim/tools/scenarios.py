"""Sample data for the firmware, produced by the Python simulator (dualprobe.simulate).

A scenario is a simulated Pt-100 pair seeing a gas-temperature profile, converted to ADC counts
by the front-end model of firmware_sim/src/adc.h, with optional sensor faults (open or
shorted channel) injected over tick ranges, and the firmware calibration to run it with.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from fwstream import COUNTS_OPEN, COUNTS_SHORT, Calibration, Robust, ohm_to_counts

from dualprobe import simulate


@dataclass
class Scenario:
    name: str
    calibration: Calibration
    counts1: np.ndarray
    counts2: np.ndarray
    recording: simulate.PairRecording
    taus: tuple[float, float]  # true time constants (s)
    # (channel 1 or 2, "open" or "short", first tick, end tick) of each injected fault
    faults: list[tuple[int, str, int, int]] = field(default_factory=list)


def _counts(temps: np.ndarray) -> np.ndarray:
    return ohm_to_counts(np.asarray(simulate.pt100_resistance(temps)))


def pt100_pair(
    *,
    ts: float = 0.1,
    duration: float = 600.0,
    taus: tuple[float, float] = (12.48, 28.95),
    noise_std: float = 0.02,
    forgetting: float = 1.0,
    solve_every: int = 100,
    lowpass_tau: float = 0.0,
    faults: list[tuple[int, str, int, int]] | None = None,
    seed: int = 1,
    name: str = "pt100_pair",
) -> Scenario:
    """A 1.5 mm / 4.5 mm Pt-100 pair (first-order, unit gain: the model the firmware
    estimates) on a multistep gas profile of 100..300 C with jumps off the sample grid."""
    rng = np.random.default_rng(seed)
    profile = simulate.multistep_profile(
        duration, mean=200.0, amplitude=100.0, mean_hold=4.0 * taus[1], rng=rng
    )
    recording = simulate.simulate_pair(
        profile,
        simulate.SensorModel((taus[0],)),
        simulate.SensorModel((taus[1],)),
        ts=ts,
        duration=duration,
        noise_std=noise_std,
        rng=rng,
    )
    counts1 = _counts(recording.t1)
    counts2 = _counts(recording.t2)
    for channel, kind, first, end in faults or []:
        target = counts1 if channel == 1 else counts2
        target[first:end] = COUNTS_OPEN if kind == "open" else COUNTS_SHORT
    calibration = Calibration(
        sample_interval=ts,
        method="gtls",
        sigma1=noise_std,
        sigma2=noise_std,
        forgetting=forgetting,
        solve_every=solve_every,
        resume_after=10,
        lowpass_tau=lowpass_tau,
    )
    return Scenario(name, calibration, counts1, counts2, recording, taus, list(faults or []))


def ecu_100hz(*, seed: int = 1, faults: list[tuple[int, str, int, int]] | None = None) -> Scenario:
    """The report's scenario: a 100 Hz ECU tick, a fast thin-film Pt-100 pair (1.248 s and
    2.895 s: the paper's 1.5/4.5 mm pair scaled to a fast gas stream, same Ts/tau as that pair
    at 10 Hz), 60 s, forgetting with a memory of 2000 ticks (about 7 tau2), a solve every
    second."""
    return pt100_pair(ts=0.01, duration=60.0, taus=(1.248, 2.895), forgetting=0.9995,
                      solve_every=100, faults=faults, seed=seed, name="ecu_100hz")


# ---- issue 13: the noise-robust loop ------------------------------------------------------

@dataclass
class RobustScenario:
    """A version-2 stream (flow channel) and its truth: the gas temperature (C) at every tick
    and the time constants at the reference flow, largest first per sensor (order 2: element
    and sheath; order 1: the element)."""

    name: str
    calibration: Calibration
    robust: Robust
    counts1: np.ndarray
    counts2: np.ndarray
    flow: np.ndarray
    gas: np.ndarray
    t1_clean: np.ndarray
    t2_clean: np.ndarray
    taus1: tuple[float, ...]
    taus2: tuple[float, ...]
    true_taus1: np.ndarray = field(default=None)  # (ticks, stages) in effect, element first
    true_taus2: np.ndarray = field(default=None)
    faults: list[tuple[int, str, int, int]] = field(default_factory=list)


def _inject(counts1, counts2, faults):
    for channel, kind, first, end in faults:
        target = counts1 if channel == 1 else counts2
        target[first:end] = COUNTS_OPEN if kind == "open" else COUNTS_SHORT


# The fixed-lag output of the drive cycle: 0.2 s, a sixth of the faster element's time constant
# at the reference flow (the largest lag the C API holds, DP_KALMAN_MAX_LAG).
DRIVE_CYCLE_LAG = 20


def drive_cycle_100hz(*, seed: int = 3, duration: float = 300.0, order: int = 2,
                      faults: list[tuple[int, str, int, int]] | None = None) -> RobustScenario:
    """The drive cycle of dualprobe.simulate.drive_cycle seen at 100 Hz by a pair of sheathed
    Pt-100s whose time constants follow the gas velocity (tau = tau_ref (v/v_ref)^-0.5 for
    sheath and element alike, v_ref = 20 m/s), 0.02 K noise, read as ADC counts, with the
    velocity as the flow channel."""
    rng = np.random.default_rng(seed)
    conditions = simulate.drive_cycle(duration + 1.0, rng)
    s1 = simulate.FieldSensor(tau_ref=1.2, exponent=0.5, sheath_tau_ref=0.15, noise_std=0.02)
    s2 = simulate.FieldSensor(tau_ref=3.0, exponent=0.5, sheath_tau_ref=0.3, noise_std=0.02)
    rec = simulate.simulate_field_pair(conditions, s1, s2, sample_rate=100.0, v_ref=20.0,
                                       rng=rng)
    n = round(duration * 100.0)
    to_c = 273.15
    counts1 = _counts(rec.t1[:n] - to_c)
    counts2 = _counts(rec.t2[:n] - to_c)
    _inject(counts1, counts2, faults or [])
    flow = rec.flow[:n].astype(np.float32)
    gas = rec.tg[:n] - to_c
    ts = 0.01
    # The gas random-walk intensity of the Kalman: the simulated gas's own increment variance
    # per second (what a calibration engineer would fit on a logged cycle).
    intensity = float(np.var(np.diff(gas)) / ts)
    calibration = Calibration(sample_interval=ts, sigma1=0.02, sigma2=0.02, forgetting=1.0,
                              solve_every=500, resume_after=10)
    robust = Robust(order=order, filter_time_constant=0.6, quantisation=6e-5, flow_ref=20.0,
                    exponent=0.5, max_eigenvalue_ratio=0.1, intensity=intensity, window=8,
                    tau_min=0.02, tau_max=30.0, lag=DRIVE_CYCLE_LAG)
    taus1 = (1.2, 0.15) if order == 2 else (1.35,)
    taus2 = (3.0, 0.3) if order == 2 else (3.3,)
    return RobustScenario("drive_cycle", calibration, robust, counts1, counts2, flow, gas,
                          rec.t1_clean[:n] - to_c, rec.t2_clean[:n] - to_c, taus1, taus2,
                          np.column_stack([rec.tau1[:n], rec.sheath1[:n]]),
                          np.column_stack([rec.tau2[:n], rec.sheath2[:n]]), list(faults or []))


def small_excitation_100hz(*, seed: int = 5, duration: float = 150.0) -> RobustScenario:
    """A constant 400 C for 30 s, then +/-2 K of slow wiggle, then constant again for the last
    30 s; first-order pair 1.248 / 2.895 s, 0.02 K, no flow channel (tracking with forgetting,
    a memory of 2000 ticks), initial time constants from the calibration. The truth taus are
    what a solve may publish; without excitation it must publish nothing."""
    rng = np.random.default_rng(seed)
    ts = 0.01
    n = round(duration / ts)
    t = np.arange(n) * ts
    # A slow random wiggle bounded to +/-2 K: the sum of a few sines of random phase.
    freqs = np.array([0.013, 0.031, 0.057, 0.11])
    phases = rng.uniform(0, 2 * np.pi, freqs.size)
    wiggle = np.sum(np.sin(2 * np.pi * freqs[:, None] * t[None, :] + phases[:, None]), axis=0)
    # No excitation at all for the first and last 30 s (noise only: nothing to identify), the
    # +/-2 K wiggle in between, faded in and out over 5 s.
    envelope = np.clip(np.minimum(t - 30.0, duration - 30.0 - t) / 5.0, 0.0, 1.0)
    gas = 400.0 + 2.0 * envelope * wiggle / np.max(np.abs(wiggle))
    taus = (1.248, 2.895)

    def lag(x, tau):
        a = np.exp(-ts / tau)
        y = np.empty_like(x)
        y[0] = x[0]
        for k in range(1, x.size):
            y[k] = a * y[k - 1] + (1 - a) * 0.5 * (x[k] + x[k - 1])
        return y

    c1 = lag(gas, taus[0])
    c2 = lag(gas, taus[1])
    t1 = c1 + 0.02 * rng.standard_normal(n)
    t2 = c2 + 0.02 * rng.standard_normal(n)
    calibration = Calibration(sample_interval=ts, sigma1=0.02, sigma2=0.02, forgetting=0.9995,
                              solve_every=100, resume_after=10, initial_tau1=1.1,
                              initial_tau2=3.2)
    robust = Robust(order=1, filter_time_constant=0.6, quantisation=6e-5, flow_ref=0.0,
                    max_eigenvalue_ratio=0.1, intensity=0.05, window=8, tau_min=0.02,
                    tau_max=30.0)
    return RobustScenario("small_excitation", calibration, robust, _counts(t1), _counts(t2),
                          np.zeros(n, dtype=np.float32), gas, c1, c2, (taus[0],), (taus[1],))
