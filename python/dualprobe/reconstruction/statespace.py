"""The state-space model of a sensor pair as the reconstruction uses it, discretised by the
compiled core (the same routine the ECU's Kalman filter runs, ``kalman_discretise.hpp``).

State ``x = [g, (g'), sensor 1 stages, sensor 2 stages]``: the gas a random walk (``rw``) or
an integrated random walk (``irw``) of intensity q, each sensor a chain of first-order stages
of unit gain, the outputs the last stages (docs: :mod:`dualprobe.reference.kalman` section 1,
the independent check). The discretisation is exact (Van Loan, computed by a scaled Taylor
series and doublings in the core) and comes in *slices*: one per hysteresis mode (a stage
cooling while its input is below its state), and, for time constants that follow the gas flow
(a schedule: the time constants of interval k are ``taus * schedule[k]``), one per level of
the schedule. The schedule is quantised to ``SCHEDULE_STEP`` (0.1 %) relative levels, so a
30-minute or a six-hour record needs only as many slices as the flow has distinct levels (a
few hundred), not one per sample: the time constants err by at most 0.05 %.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dualprobe import _core

__all__ = [
    "FLOOR_DYN",
    "FLOOR_REL",
    "GAS_MODELS",
    "SCHEDULE_STEP",
    "PairModel",
    "causal_filter",
    "continuous_matrix",
    "pair_model",
    "process_floor",
]

GAS_MODELS = ("rw", "irw")
FLOOR_REL = 1e-8  # model-error variance per stage per sample / sigma^2 (kalman.hpp kFloorRel)
FLOOR_DYN = 1.0  # share of a stage's within-interval variance (kalman.hpp kFloorDyn)
SCHEDULE_STEP = 1e-3  # relative quantisation of a schedule's levels

Taus = tuple[float, ...]


@dataclass(frozen=True, eq=False)
class PairModel:
    """Discretised model of a sensor pair seeing one gas temperature.

    ``phi``/``q_unit`` (S, n, n) hold one slice per (schedule level, hysteresis mode);
    ``stage_taus`` (S, stages) the stage time constants of each slice; ``levels`` (N-1,) the
    schedule level of each interval (None without a schedule); ``stage_input[j]`` and
    ``stage_state[j]`` index the input and state of stage j in x.
    """

    ts: float
    gas: str
    taus_heat: tuple[Taus, Taus]
    taus_cool: tuple[Taus, Taus]
    phi: np.ndarray
    q_unit: np.ndarray
    stage_taus: np.ndarray
    h: np.ndarray
    stage_input: np.ndarray
    stage_state: np.ndarray
    stage_sensor: np.ndarray
    mode_count: int
    levels: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.h.shape[1])

    @property
    def n_gas(self) -> int:
        return 2 if self.gas == "irw" else 1

    @property
    def hysteretic(self) -> bool:
        return self.mode_count > 1

    @property
    def scheduled(self) -> bool:
        return self.levels is not None

    def slices(self, modes: np.ndarray) -> np.ndarray:
        """Slice of each interval from its hysteresis mode (and its schedule level)."""
        modes = np.asarray(modes, dtype=np.intp)
        if self.levels is None:
            return modes
        return self.levels * self.mode_count + modes

    def modes(self, x: np.ndarray) -> np.ndarray:
        """Hysteresis mode of each state in ``x`` (..., n): bit j set when stage j cools."""
        x = np.asarray(x, dtype=float)
        if not self.hysteretic:
            return np.zeros(x.shape[:-1], dtype=np.intp)
        cooling = x[..., self.stage_input] < x[..., self.stage_state]
        return np.sum(cooling * (1 << np.arange(self.stage_state.size)), axis=-1).astype(np.intp)


def _layout(
    gas: str, sizes: Sequence[int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """H, stage inputs, stage states and stage sensors of the state layout."""
    n_gas = 2 if gas == "irw" else 1
    n = n_gas + sum(sizes)
    h = np.zeros((2, n))
    inputs, states, sensors = [], [], []
    index = n_gas
    for sensor, count in enumerate(sizes):
        source = 0
        for _ in range(count):
            inputs.append(source)
            states.append(index)
            sensors.append(sensor)
            source = index
            index += 1
        h[sensor, source] = 1.0
    return h, np.array(inputs), np.array(states), np.array(sensors)


def _check_taus(name: str, taus: Sequence[float]) -> Taus:
    values = tuple(float(t) for t in taus)
    if len(values) not in (1, 2):
        raise ValueError(f"{name}: need 1 or 2 time constants per sensor, got {len(values)}")
    if not all(math.isfinite(t) and t > 0.0 for t in values):
        raise ValueError(f"{name}: time constants must be finite and > 0, got {values}")
    return values


def quantise_schedule(schedule: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(levels (N-1,), values (L,)): each interval's schedule rounded to a relative grid of
    ``SCHEDULE_STEP`` and the distinct values used."""
    s = np.asarray(schedule, dtype=float)
    if s.ndim != 1 or not np.all(np.isfinite(s)) or np.any(s <= 0.0):
        raise ValueError("pair_model: the schedule must be finite and > 0 on every interval")
    steps = np.round(np.log(s) / math.log1p(SCHEDULE_STEP)).astype(np.int64)
    unique, levels = np.unique(steps, return_inverse=True)
    return levels.astype(np.intp), np.exp(unique * math.log1p(SCHEDULE_STEP))


def pair_model(
    taus1: Sequence[float],
    taus2: Sequence[float],
    ts: float,
    *,
    gas: str = "rw",
    taus1_cool: Sequence[float] | None = None,
    taus2_cool: Sequence[float] | None = None,
    schedule: np.ndarray | None = None,
) -> PairModel:
    """Build and discretise the model: one slice per hysteresis mode, times one per level of
    ``schedule`` (N-1,) (the time constants of interval k are multiplied by schedule[k])."""
    if not (math.isfinite(ts) and ts > 0.0):
        raise ValueError(f"pair_model: ts must be finite and > 0, got {ts}")
    if gas not in GAS_MODELS:
        raise ValueError(f"pair_model: gas must be one of {GAS_MODELS}, got {gas!r}")
    heat = (_check_taus("taus1", taus1), _check_taus("taus2", taus2))
    cool = tuple(
        heat[i] if c is None else _check_taus(f"taus{i + 1}_cool", c)
        for i, c in enumerate((taus1_cool, taus2_cool))
    )
    for i in range(2):
        if len(cool[i]) != len(heat[i]):
            raise ValueError(f"taus{i + 1}_cool: need {len(heat[i])} time constants like "
                             f"taus{i + 1}, got {len(cool[i])}")
    flat_heat = np.array(heat[0] + heat[1])
    flat_cool = np.array(cool[0] + cool[1])
    stages = flat_heat.size
    mode_count = 1 << stages if np.any(flat_heat != flat_cool) else 1
    bits = (np.arange(mode_count)[:, None] >> np.arange(stages)[None, :]) & 1
    mode_taus = np.where(bits == 1, flat_cool[None, :], flat_heat[None, :])  # (M, stages)
    levels = None
    if schedule is not None:
        levels, values = quantise_schedule(schedule)
        slice_taus = (values[:, None, None] * mode_taus[None, :, :]).reshape(-1, stages)
    else:
        slice_taus = mode_taus
    sizes = (len(heat[0]), len(heat[1]))
    phi, q_unit = _core.discretise_intervals(
        np.ascontiguousarray(slice_taus[:, : sizes[0]]),
        np.ascontiguousarray(slice_taus[:, sizes[0] :]), float(ts), gas)
    h, inputs, states, sensors = _layout(gas, sizes)
    return PairModel(
        ts=float(ts), gas=gas, taus_heat=(heat[0], heat[1]), taus_cool=(cool[0], cool[1]),
        phi=np.asarray(phi), q_unit=0.5 * (np.asarray(q_unit) + np.swapaxes(q_unit, 1, 2)),
        stage_taus=slice_taus, h=h, stage_input=inputs, stage_state=states,
        stage_sensor=sensors, mode_count=mode_count, levels=levels,
    )


def process_floor(model: PairModel, sigma: Sequence[float] | np.ndarray, q: float) -> np.ndarray:
    """The smoother's model-error floor on the sensor stages, per slice (S, n, n): a tiny
    share of each sensor's noise variance plus the exact fraction of a gas move that reaches a
    stage within one interval, ``1 - exp(-Ts/tau)`` (for a stage faster than Ts the floor
    saturates at the gas step's own variance / 12 instead of growing as (Ts/tau)^2 and cutting
    the sensor off from the gas)."""
    gas_step = q * model.q_unit[:, 0, 0]  # (S,) variance of one gas increment
    noise = FLOOR_REL * np.square(np.asarray(sigma, dtype=float))[model.stage_sensor]
    # the heating time constants of each slice's level (the floor is not mode-dependent)
    heating = (np.arange(model.phi.shape[0]) // model.mode_count) * model.mode_count
    reach = -np.expm1(-model.ts / model.stage_taus[heating])  # (S, stages)
    floor = np.zeros(model.phi.shape)
    floor[:, model.stage_state, model.stage_state] = (
        noise[None, :] + FLOOR_DYN * gas_step[:, None] * reach**2 / 12.0)
    return floor


def continuous_matrix(model: PairModel) -> np.ndarray:
    """F of the continuous-time model with the heating time constants at schedule 1."""
    n = model.n
    f = np.zeros((n, n))
    if model.gas == "irw":
        f[0, 1] = 1.0
    taus = np.array(model.taus_heat[0] + model.taus_heat[1])
    f[model.stage_state, model.stage_input] += 1.0 / taus
    f[model.stage_state, model.stage_state] -= 1.0 / taus
    return f


def causal_filter(y: np.ndarray, model: PairModel, q: float, sigma: Sequence[float],
                  schedule: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The causal reconstruction (as on the ECU): the core's Kalman filter with GLR jump
    detection on ``y`` (N, 2) with this model's time constants, gas model, intensity and noise.
    ``schedule`` (N,): time constants times ``schedule[k]`` at sample k (flow-scheduled: the
    core retunes the filter as the level moves; no jump detection). Returns the filtered gas
    temperature at each sample and its variance (the filter's own, given the model)."""
    cool = (model.taus_cool[0], model.taus_cool[1]) if model.hysteretic else (None, None)
    result = _core.kalman_filter(
        np.ascontiguousarray(y[:, 0]), np.ascontiguousarray(y[:, 1]), model.ts,
        list(model.taus_heat[0]), list(model.taus_heat[1]), [float(s) for s in sigma], float(q),
        gas=model.gas, taus1_cool=None if cool[0] is None else list(cool[0]),
        taus2_cool=None if cool[1] is None else list(cool[1]), schedule=schedule)
    return (np.asarray(result["gas"], dtype=float),
            np.asarray(result["gas_variance"], dtype=float))
