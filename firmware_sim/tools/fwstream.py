"""Input and output streams of the dualprobe firmware (host and Cortex-M4F builds).

Input (little-endian): a 56-byte calibration block, then one (counts1, counts2) uint32 pair per
tick from the two Pt-100 ADC channels. Output: one text line per tick, ``T tick flags t1 t2
gas`` (version 2: ``... gas lagged``, the fixed-lag gas of tick - lag), plus ``S tick status
beta b1 b2 tau1 tau2 ratio`` after each solve, every float as the 8 hex digits of its IEEE-754
bits (exact, and identical on every target). See README.md.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MAGIC = b"DPFW"
VERSION = 1
HEADER = struct.Struct("<4sIIfIfffIIIfff")
VERSION_ROBUST = 2
HEADER2 = struct.Struct("<IIffffffIfffI")  # appended by version 2 (firmware.h)
ESTIMATORS = {"difference": 0, "svf": 1}
METHODS = {"ls": 0, "tls": 1, "gtls": 2}
SOURCES = {"sensor1": 0, "sensor2": 1, "weighted": 2}
STATUSES = ("ok", "insufficient_excitation", "infeasible", "non_finite_input",
            "invalid_argument", "not_ready")

# ADC front-end of firmware_sim/src/adc.h: 24-bit ratiometric against 400 ohm.
ADC_BITS = 24
ADC_FULL_SCALE = 1 << ADC_BITS
ADC_R_REF_OHM = 400.0
COUNTS_OPEN = ADC_FULL_SCALE - 1  # railed input: broken sensor wire
COUNTS_SHORT = 100  # 2.4 mohm: a shorted sensor

FLAG_CH1_OPEN = 0x01
FLAG_CH1_SHORT = 0x02
FLAG_CH2_OPEN = 0x04
FLAG_CH2_SHORT = 0x08
FLAG_PAUSED = 0x10
FLAG_GAS_VALID = 0x20
FLAG_TAUS_VALID = 0x40
FLAG_SOLVED = 0x80
FAULT_FLAGS = FLAG_CH1_OPEN | FLAG_CH1_SHORT | FLAG_CH2_OPEN | FLAG_CH2_SHORT


@dataclass(frozen=True)
class Calibration:
    """The firmware's calibration block (what an ECU would hold in its parameter flash)."""

    sample_interval: float
    method: str = "gtls"
    sigma1: float = 0.02
    sigma2: float = 0.02
    forgetting: float = 1.0
    solve_every: int = 100
    resume_after: int = 10
    source: str = "weighted"
    lowpass_tau: float = 0.0
    initial_tau1: float = 0.0
    initial_tau2: float = 0.0


@dataclass(frozen=True)
class Robust:
    """Version-2 calibration: the SVF estimator and the Kalman reconstruction (firmware.h)."""

    estimator: str = "svf"
    order: int = 1
    filter_time_constant: float = 0.5
    quantisation: float = 0.0
    flow_ref: float = 0.0  # 0: no flow channel
    exponent: float = 0.5
    max_eigenvalue_ratio: float = 0.1
    intensity: float = 1.0
    window: int = 8
    false_alarm: float = 1e-6
    tau_min: float = 0.01
    tau_max: float = 100.0
    lag: int = 0  # ticks of the fixed-lag output (0: none)


def ohm_to_counts(resistance_ohm: np.ndarray) -> np.ndarray:
    """The ADC model: round(R / R_ref * 2^24), clipped to the converter's range."""
    counts = np.rint(np.asarray(resistance_ohm, dtype=float) / ADC_R_REF_OHM * ADC_FULL_SCALE)
    return np.clip(counts, 0, ADC_FULL_SCALE - 1).astype(np.uint32)


def counts_to_ohm(counts: np.ndarray) -> np.ndarray:
    """Float32 resistance exactly as the firmware forms it (one rounding)."""
    scale = np.float32(ADC_R_REF_OHM / ADC_FULL_SCALE)  # 25 / 2^20: exact in float32
    return np.asarray(counts).astype(np.float32) * scale


def write_stream(
    path: str | Path, calibration: Calibration, counts1: np.ndarray, counts2: np.ndarray
) -> None:
    """Write the calibration block and the ADC counts of every tick."""
    c1 = np.asarray(counts1, dtype=np.uint32)
    c2 = np.asarray(counts2, dtype=np.uint32)
    if c1.shape != c2.shape or c1.ndim != 1:
        raise ValueError(f"counts must be 1-D of equal length, got {c1.shape} and {c2.shape}")
    cal = calibration
    header = HEADER.pack(
        MAGIC, VERSION, c1.size, cal.sample_interval, METHODS[cal.method], cal.sigma1,
        cal.sigma2, cal.forgetting, cal.solve_every, cal.resume_after, SOURCES[cal.source],
        cal.lowpass_tau, cal.initial_tau1, cal.initial_tau2,
    )
    pairs = np.column_stack([c1, c2]).astype("<u4")
    Path(path).write_bytes(header + pairs.tobytes())


def write_stream2(
    path: str | Path, calibration: Calibration, robust: Robust, counts1: np.ndarray,
    counts2: np.ndarray, flow: np.ndarray,
) -> None:
    """Version 2: both calibration blocks, then (counts1, counts2, flow as float32) per tick."""
    c1 = np.asarray(counts1, dtype=np.uint32)
    c2 = np.asarray(counts2, dtype=np.uint32)
    f = np.asarray(flow, dtype=np.float32)
    if not (c1.shape == c2.shape == f.shape) or c1.ndim != 1:
        raise ValueError("counts and flow must be 1-D of equal length")
    cal, rob = calibration, robust
    header = HEADER.pack(
        MAGIC, VERSION_ROBUST, c1.size, cal.sample_interval, METHODS[cal.method], cal.sigma1,
        cal.sigma2, cal.forgetting, cal.solve_every, cal.resume_after, SOURCES[cal.source],
        cal.lowpass_tau, cal.initial_tau1, cal.initial_tau2,
    ) + HEADER2.pack(
        ESTIMATORS[rob.estimator], rob.order, rob.filter_time_constant, rob.quantisation,
        rob.flow_ref, rob.exponent, rob.max_eigenvalue_ratio, rob.intensity, rob.window,
        rob.false_alarm, rob.tau_min, rob.tau_max, rob.lag,
    )
    rows = np.empty((c1.size, 3), dtype="<u4")
    rows[:, 0] = c1
    rows[:, 1] = c2
    rows[:, 2] = f.astype("<f4").view("<u4")
    Path(path).write_bytes(header + rows.tobytes())


@dataclass
class FirmwareOutput:
    """Parsed firmware output: per tick (``flags``, ``t1``, ``t2``, ``gas``) and per solve."""

    flags: np.ndarray  # uint32 per tick
    t1: np.ndarray  # float32 degC, NaN when faulted
    t2: np.ndarray
    gas: np.ndarray  # float32 degC, NaN unless FLAG_GAS_VALID
    gas_lagged: np.ndarray  # float32 degC: the gas of tick - lag; NaN when not ready or absent
    solve_ticks: np.ndarray  # tick index of each solve
    solve_status: np.ndarray  # dualprobe status code of each solve
    solve_values: np.ndarray  # float32 (n_solves, 6): beta, b1, b2, tau1, tau2, ratio
    # SVF solves ("R" lines): published flag, and (tau1a, tau1b, tau2a, tau2b, m, ratio)
    solve_published: np.ndarray | None = None

    @property
    def ticks(self) -> int:
        return int(self.flags.size)


def _floats(words: Sequence[str]) -> np.ndarray:
    return np.array([int(w, 16) for w in words], dtype=np.uint32).view(np.float32)


def parse_output(text: str) -> FirmwareOutput:
    """Parse the firmware's stdout; raises ValueError on any malformed line."""
    ticks: list[tuple[int, int, list[str]]] = []
    solves: list[tuple[int, int, list[str]]] = []
    published: list[int] = []
    for number, line in enumerate(text.splitlines(), start=1):
        words = line.split()
        if len(words) in (6, 7) and words[0] == "T":
            floats = words[3:] if len(words) == 7 else [*words[3:], "7fc00000"]
            ticks.append((int(words[1]), int(words[2], 16), floats))
        elif len(words) == 9 and words[0] == "S":
            solves.append((int(words[1]), int(words[2]), words[3:]))
        elif len(words) == 10 and words[0] == "R":
            solves.append((int(words[1]), int(words[2]), words[4:]))
            published.append(int(words[3]))
        else:
            raise ValueError(f"firmware output line {number} is malformed: {line[:60]!r}")
    if [t[0] for t in ticks] != list(range(len(ticks))):
        raise ValueError("firmware output: tick numbers are not 0, 1, 2, ...")
    tick_floats = _floats([w for t in ticks for w in t[2]]).reshape(-1, 4)
    solve_floats = _floats([w for s in solves for w in s[2]]).reshape(-1, 6)
    return FirmwareOutput(
        flags=np.array([t[1] for t in ticks], dtype=np.uint32),
        t1=tick_floats[:, 0],
        t2=tick_floats[:, 1],
        gas=tick_floats[:, 2],
        gas_lagged=tick_floats[:, 3],
        solve_ticks=np.array([s[0] for s in solves], dtype=np.int64),
        solve_status=np.array([s[1] for s in solves], dtype=np.int64),
        solve_values=solve_floats,
        solve_published=np.array(published, dtype=np.int64) if published else None,
    )


def compare_outputs(host: FirmwareOutput, target: FirmwareOutput, rtol: float) -> float:
    """Max abs difference between two runs over every float field; raises ValueError if the
    flags, tick count or solve statuses differ, or a float differs by more than
    ``rtol * max(1, |host value|)`` (NaN must match NaN)."""
    if host.ticks != target.ticks or not np.array_equal(host.flags, target.flags):
        raise ValueError("flags or tick count differ")
    if not (np.array_equal(host.solve_ticks, target.solve_ticks)
            and np.array_equal(host.solve_status, target.solve_status)):
        raise ValueError("solve ticks or statuses differ")
    worst = 0.0
    for name, a, b in (("t1", host.t1, target.t1), ("t2", host.t2, target.t2),
                       ("gas", host.gas, target.gas),
                       ("gas_lagged", host.gas_lagged, target.gas_lagged),
                       ("solve", host.solve_values, target.solve_values)):
        a64 = a.astype(np.float64)
        b64 = b.astype(np.float64)
        if not np.array_equal(np.isnan(a64), np.isnan(b64)):
            raise ValueError(f"{name}: NaN positions differ")
        both = ~np.isnan(a64)
        if not np.any(both):
            continue
        diff = np.abs(a64[both] - b64[both])
        bound = rtol * np.maximum(1.0, np.abs(a64[both]))
        if np.any(diff > bound):
            raise ValueError(f"{name}: differs by {diff.max():.3g} (> rtol {rtol:g})")
        worst = max(worst, float(diff.max()))
    return worst
