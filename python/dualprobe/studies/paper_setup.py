"""The paper's set-up (section IV): its tables and study constants, the simulated
identification rig and the studies' settings (choices where the paper is silent: see
:mod:`dualprobe.studies.paper`), and the difference-equation engine studies A-C run."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dualprobe import _core
from dualprobe import simulate as sim

__all__ = [
    "CORE",
    "MARKED_A_P",
    "PAPER_TABLES",
    "PAPER_TAU_COOL",
    "PAPER_TAU_HEAT",
    "RIG",
    "SENSOR_LABELS",
    "STUDY",
    "STUDY_A_TAU1",
    "STUDY_A_TAU2",
    "STUDY_BC_TAU1",
    "STUDY_BC_TAU2",
    "DifferenceEngine",
    "RigSettings",
    "StudySettings",
    "estimate_pair",
    "finite_or_none",
    "progress_bar",
    "reconstruct_sensor1",
    "study_record",
    "sweep_values",
]


# The paper's numbers (Tables I and II, Figs. 15-16).
PAPER_TABLES: dict[str, dict[str, sim.SensorModel]] = {
    "pt100_1p5mm": {"order1": sim.PT100_1P5MM_FIRST, "order2": sim.PT100_1P5MM_SECOND},
    "pt100_4p5mm": {"order1": sim.PT100_4P5MM_FIRST, "order2": sim.PT100_4P5MM_SECOND},
}
SENSOR_LABELS = {
    "pt100_1p5mm": "1.5 mm Pt-100 (Table I)",
    "pt100_4p5mm": "4.5 mm Pt-100 (Table II)",
}
PAPER_TAU_HEAT = sim.PT100_1P5MM_TAU_HEAT
PAPER_TAU_COOL = sim.PT100_1P5MM_TAU_COOL
# Study constants from the paper (section IV).
STUDY_A_TAU1 = 12.48  # 1.5 mm Pt-100, first order (Table I)
STUDY_A_TAU2 = 28.95  # 4.5 mm Pt-100 dominant pole (Table II, first order)
STUDY_BC_TAU1 = (12.30, 0.17)  # Table I, second order
STUDY_BC_TAU2 = 25.72  # Table II, second order, dominant pole
MARKED_A_P = {"1.5 mm Pt-100": 0.17, "4.5 mm Pt-100": 1.08}


@dataclass(frozen=True)
class RigSettings:
    """Simulated identification experiment (reference thermocouple + Pt-100)."""

    ts: float = 0.01
    reference_tau: float = 0.025
    reference_noise: float = 0.1
    sensor_noise: float = 0.05
    low: float = 20.0
    high: float = 120.0
    t_step: float = 5.0037  # between samples on purpose: the rig does not know the grid
    duration_1p5mm: float = 100.0
    duration_4p5mm: float = 200.0
    hysteresis_hold: float = 200.0  # time between the heating and the cooling step

    def duration(self, sensor: str) -> float:
        return self.duration_1p5mm if sensor == "pt100_1p5mm" else self.duration_4p5mm


@dataclass(frozen=True)
class StudySettings:
    """Noise-free simulation studies A-C."""

    ts: float = 0.1
    duration: float = 200.0
    t_step: float = 10.0  # on the sample grid (ZOH assumption of eq. 9)
    low: float = 20.0
    high: float = 120.0
    method: str = "gtls"

    def profile(self) -> sim.GasProfile:
        steps = self.t_step / self.ts
        if abs(steps - round(steps)) > 1e-9:
            raise ValueError(f"StudySettings: t_step {self.t_step} is not on the sample grid")
        return sim.step_profile(self.t_step, self.low, self.high)


RIG = RigSettings()
STUDY = StudySettings()


def finite_or_none(value: float) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def progress_bar(
    values: Sequence[float], desc: str, enabled: bool, *, tty_only: bool = False
) -> Iterable[float]:
    """``values`` with a progress bar over a_p when ``enabled`` (``tty_only``: only on a
    terminal)."""
    if not enabled:
        return values
    from tqdm import tqdm

    if tty_only:
        return tqdm(values, desc=desc, unit="a_p", leave=False, disable=None)  # None: TTY only
    return tqdm(values, desc=desc, unit="a_p", leave=False)


# --------------------------------------------------------------------------------------------
# The difference-equation engine of studies A-C (paper eqs. 10-12 and the exact inverse)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class DifferenceEngine:
    """What studies A-C run: ``estimate(t1, t2, ts, method)`` returns a mapping with status,
    beta, b1, b2, tau1, tau2 (GTLS with equal white noise on both sensors: only the ratio
    matters); ``inverse(temps, tau, ts)`` is the exact first-order inverse (out[k-1] =
    Tg(k-1); the last value NaN). The studies use :data:`CORE`; the tests pass an engine made
    of the independent NumPy reference to check that it gives the same numbers."""

    name: str
    estimate: Callable[[np.ndarray, np.ndarray, float, str], Mapping[str, Any]]
    inverse: Callable[[np.ndarray, float, float], np.ndarray]


def _core_estimate(t1: np.ndarray, t2: np.ndarray, ts: float, method: str) -> dict[str, Any]:
    return dict(_core.estimate_difference(
        np.ascontiguousarray(t1, dtype=float),
        np.ascontiguousarray(t2, dtype=float),
        ts,
        method,
        1.0,
        1.0,
        1.0,
    ))


def _core_inverse(temps: np.ndarray, tau: float, ts: float) -> np.ndarray:
    return np.asarray(_core.reconstruct_inverse(np.ascontiguousarray(temps, dtype=float), tau, ts))


CORE = DifferenceEngine("core", _core_estimate, _core_inverse)  # C++ through the bindings


def _engine(estimator: str | DifferenceEngine) -> DifferenceEngine:
    if isinstance(estimator, DifferenceEngine):
        return estimator
    if estimator == "core":
        return CORE
    raise ValueError(f"estimator must be 'core' or a DifferenceEngine, got {estimator!r}")


def estimate_pair(
    t1: np.ndarray, t2: np.ndarray, ts: float, *, method: str = "gtls",
    estimator: str | DifferenceEngine = "core",
) -> dict[str, Any]:
    """The paper's difference-equation estimate (eqs. 10-12): status, beta, b1, b2, tau1, tau2.

    GTLS assumes equal white noise on both sensors (sigma1 = sigma2; only the ratio matters).
    """
    result = _engine(estimator).estimate(t1, t2, ts, method)
    return {k: result[k] for k in ("status", "beta", "b1", "b2", "tau1", "tau2")}


def reconstruct_sensor1(
    t1: np.ndarray, tau1: float, ts: float, *, estimator: str | DifferenceEngine = "core"
) -> np.ndarray:
    """Exact inverse of sensor 1 (out[k-1] = Tg(k-1); the last value is NaN)."""
    return _engine(estimator).inverse(t1, tau1, ts)


# --------------------------------------------------------------------------------------------
# The studies' records
# --------------------------------------------------------------------------------------------


def sweep_values(quick: bool) -> list[float]:
    """a_p values: log-spaced 1 ms .. 2 s plus the paper's marked values 0.001, 0.1, 0.17,
    1.08 and points around 0.17."""
    count = 10 if quick else 36
    grid = np.geomspace(1e-3, 2.0, count)
    marked = [0.001, 0.01, 0.1, 0.17, 1.08]
    # Resolve the equal-pole dip of study B around sensor 1's 0.17 s pole.
    near_equal = [0.15, 0.2] if quick else [0.12, 0.14, 0.15, 0.16, 0.18, 0.19, 0.2, 0.25]
    values = np.unique(np.round(np.concatenate([grid, marked, near_equal]), 12))
    return [float(v) for v in values]


def study_record(
    sensor1: sim.SensorModel, sensor2: sim.SensorModel, settings: StudySettings = STUDY
) -> sim.PairRecording:
    """Noise-free pair response to the study's gas step."""
    return sim.simulate_pair(
        settings.profile(), sensor1, sensor2, ts=settings.ts, duration=settings.duration
    )
