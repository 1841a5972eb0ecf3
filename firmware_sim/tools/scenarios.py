"""Sample data for the firmware, produced by the Python simulator (dualprobe.simulate).

A scenario is a simulated Pt-100 pair seeing a gas-temperature profile, converted to ADC counts
by the front-end model of firmware_sim/src/adc.h, with optional sensor faults (open or
shorted channel) injected over tick ranges, and the firmware calibration to run it with.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from fwstream import COUNTS_OPEN, COUNTS_SHORT, Calibration, ohm_to_counts

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
