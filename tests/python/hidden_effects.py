"""Test-data generator with hidden sensor effects, for the discrepancy workflow (issue 5).

Written independently of ``dualprobe.diagnose`` and ``dualprobe.simulate`` and deliberately
*richer* than the diagnose catalogue, so that the workflow never sees its own model structure:

* ``extra_pole``: a 2- or 3-node lumped heat-conduction chain inside the sensor (sheath, filler,
  element; the element is the innermost node), not a clean second pole;
* ``hysteresis``: the convective conductance gas -> sheath depends on the direction of heat flow;
* ``dead_time``: a continuous transport delay of the gas reaching the sensor (off the grid);
* ``gain`` / ``offset``: amplifier gain error and a constant bias (self-heating) of the element;
* ``nonlinearity``: the element is a Pt-100 (IEC 60751 Callendar-Van Dusen) read through the
  linear alpha = 0.00385 /K conversion.

The gas temperature is piecewise linear (steps at continuous, off-grid times, ramps and
fluctuating stretches) between 60 and 340 degC. The reference column is the gas seen through a
fine thermocouple (time constant 10-40 ms) plus noise; both channels carry white noise of
0.05-0.1 K. The sensor is integrated exactly (matrix exponential of the state augmented with the
piecewise-linear gas); a heat-flow reversal inside a sample interval is located to 1/32 of it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

CATALOGUE = ("extra_pole", "hysteresis", "dead_time", "gain", "offset", "nonlinearity")

# IEC 60751 Callendar-Van Dusen coefficients (T >= 0 degC) and the linear conversion's alpha.
CVD_A = 3.9083e-3
CVD_B = -5.775e-7
LINEAR_ALPHA = 0.00385

LEVEL_RANGE = (60.0, 340.0)


@dataclass(frozen=True)
class GasSegments:
    """Piecewise-linear gas temperature: segment i runs from (start[i], v0[i]) to (end[i], v1[i]).

    Segments are contiguous in time (end[i] == start[i+1]); the value may jump between them.
    """

    start: np.ndarray
    end: np.ndarray
    v0: np.ndarray
    v1: np.ndarray

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        index = np.clip(np.searchsorted(self.end, t, side="right"), 0, self.start.size - 1)
        span = self.end[index] - self.start[index]
        frac = np.clip((t - self.start[index]) / span, 0.0, 1.0)
        return self.v0[index] + frac * (self.v1[index] - self.v0[index])

    def shifted(self, delay: float) -> GasSegments:
        """The same gas arriving `delay` seconds later (held at the first value before)."""
        start = np.concatenate(([self.start[0]], self.start + delay))
        end = np.concatenate(([self.start[0] + delay], self.end + delay))
        v0 = np.concatenate(([self.v0[0]], self.v0))
        v1 = np.concatenate(([self.v0[0]], self.v1))
        return GasSegments(start, end, v0, v1)


@dataclass(frozen=True)
class Sensor:
    """Linear heat-conduction chain: dx/dt = A x + b_dir * g, element = last node.

    `a_heat`/`b_heat` apply while the gas is hotter than the outer node (heat flows in),
    `a_cool`/`b_cool` otherwise (identical when there is no direction dependence).
    """

    a_heat: np.ndarray
    b_heat: np.ndarray
    a_cool: np.ndarray
    b_cool: np.ndarray

    @property
    def nodes(self) -> int:
        return int(self.a_heat.shape[0])

    @property
    def directional(self) -> bool:
        return not (
            np.array_equal(self.a_heat, self.a_cool) and np.array_equal(self.b_heat, self.b_cool)
        )

    def time_constants(self, direction: str = "heat") -> np.ndarray:
        """Time constants (s) of the chain, largest first."""
        a = self.a_heat if direction == "heat" else self.a_cool
        rates = -np.linalg.eigvals(a).real
        return np.sort(1.0 / rates)[::-1]


def conduction_chain(
    capacities: Sequence[float],
    conductances: Sequence[float],
    convection_heat: float,
    convection_cool: float | None = None,
) -> Sensor:
    """Chain gas -> node 0 -> node 1 -> ... -> node n-1 (element), lumped capacities (J/K)
    and conductances (W/K) between neighbouring nodes; convection to node 0 by direction."""
    c = np.asarray(capacities, dtype=float)
    k = np.asarray(conductances, dtype=float)
    n = c.size
    if k.size != n - 1:
        raise ValueError("conduction_chain: need one conductance between each pair of nodes")

    def matrices(h: float) -> tuple[np.ndarray, np.ndarray]:
        a = np.zeros((n, n))
        a[0, 0] -= h
        for i in range(n - 1):
            a[i, i] -= k[i]
            a[i + 1, i + 1] -= k[i]
            a[i, i + 1] += k[i]
            a[i + 1, i] += k[i]
        b = np.zeros(n)
        b[0] = h
        return a / c[:, None], b / c

    a_h, b_h = matrices(convection_heat)
    a_c, b_c = matrices(convection_heat if convection_cool is None else convection_cool)
    return Sensor(a_h, b_h, a_c, b_c)


class _Transitions:
    """Cached transition matrices of the state augmented with gas value and gas slope.

    Closed form in the eigenbasis of A (a conduction chain is similar to a symmetric matrix,
    so its eigenvalues are real and negative): over dt with g(r) = g0 + s r,
    x(dt) = e^{A dt} x0 + (e^{A dt} - I) A^-1 b g0 + (e^{A dt} - I - A dt) A^-2 b s.
    """

    def __init__(self, sensor: Sensor) -> None:
        self._n = sensor.nodes
        self._modes = {}
        for key, a, b in (
            ("heat", sensor.a_heat, sensor.b_heat),
            ("cool", sensor.a_cool, sensor.b_cool),
        ):
            rates, vectors = np.linalg.eig(a)
            rates = rates.real
            vectors = vectors.real
            inverse = np.linalg.inv(vectors)
            self._modes[key] = (rates, vectors, inverse, inverse @ b)
        self._cache: dict[tuple[str, float], np.ndarray] = {}

    def _matrix(self, direction: str, dt: float) -> np.ndarray:
        rates, vectors, inverse, b_modal = self._modes[direction]
        n = self._n
        decay = np.exp(rates * dt)
        first = np.expm1(rates * dt) / rates
        second = (np.expm1(rates * dt) - rates * dt) / rates**2
        m = np.zeros((n + 2, n + 2))
        m[:n, :n] = (vectors * decay) @ inverse
        m[:n, n] = vectors @ (first * b_modal)
        m[:n, n + 1] = vectors @ (second * b_modal)
        m[n, n] = 1.0
        m[n, n + 1] = dt
        m[n + 1, n + 1] = 1.0
        return m

    def __call__(self, direction: str, dt: float) -> np.ndarray:
        key = (direction, round(dt, 12))
        matrix = self._cache.get(key)
        if matrix is None:
            matrix = self._matrix(direction, dt)
            if len(self._cache) < 4096:
                self._cache[key] = matrix
        return matrix


def simulate_chain(sensor: Sensor, gas: GasSegments, t: np.ndarray, initial: float) -> np.ndarray:
    """Element (last node) temperature at the times `t`, starting at rest at `initial`.

    Exact for piecewise-linear gas; with direction-dependent convection the direction is taken
    at the start of each interval, and an interval in which the heat flow reverses is redone
    in 32 sub-steps.
    """
    n = sensor.nodes
    transitions = _Transitions(sensor)
    directional = sensor.directional
    state = np.empty(n + 2)
    state[:n] = initial
    out = np.empty(t.size)
    seg = 0
    t_now = float(t[0])
    seg = int(np.clip(np.searchsorted(gas.end, t_now, side="right"), 0, gas.start.size - 1))

    def gas_state(i: int, at: float) -> tuple[float, float]:
        span = gas.end[i] - gas.start[i]
        slope = (gas.v1[i] - gas.v0[i]) / span if span > 0 else 0.0
        return gas.v0[i] + slope * (at - gas.start[i]), slope

    state[n], state[n + 1] = gas_state(seg, t_now)

    def advance(st: np.ndarray, dt: float) -> np.ndarray:
        if dt <= 0.0:
            return st
        direction = "heat" if st[n] > st[0] else "cool"
        new = transitions(direction, dt) @ st
        if directional and (("heat" if new[n] > new[0] else "cool") != direction):
            sub = dt / 32.0
            new = st
            for _ in range(32):
                d = "heat" if new[n] > new[0] else "cool"
                new = transitions(d, sub) @ new
        return new

    last_seg = gas.start.size - 1
    for i, target in enumerate(t):
        while seg < last_seg and gas.end[seg] <= target:
            state = advance(state, gas.end[seg] - t_now)
            t_now = float(gas.end[seg])
            seg += 1
            state[n], state[n + 1] = gas_state(seg, t_now)
        state = advance(state, float(target) - t_now)
        t_now = float(target)
        out[i] = state[n - 1]
    return out


def cvd_linear_reading(temp_c: np.ndarray) -> np.ndarray:
    """Temperature read from a Pt-100 through the linear alpha conversion (T >= 0 degC)."""
    ratio = 1.0 + CVD_A * temp_c + CVD_B * temp_c**2
    return (ratio - 1.0) / LINEAR_ALPHA


def random_gas(
    rng: np.random.Generator, duration: float, tau: float, start_level: float | None = None
) -> GasSegments:
    """Steps at continuous (off-grid) times, ramps and fluctuating stretches, 60-340 degC.

    Holds last 3-8 main time constants so the sensor settles between most changes.
    """
    lo, hi = LEVEL_RANGE
    level = rng.uniform(lo, hi) if start_level is None else start_level
    starts: list[float] = []
    ends: list[float] = []
    v0s: list[float] = []
    v1s: list[float] = []

    def add(t0: float, t1: float, a: float, b: float) -> None:
        starts.append(t0)
        ends.append(t1)
        v0s.append(a)
        v1s.append(b)

    now = 0.0
    first = rng.uniform(2.0, 4.0) * tau
    add(now, first, level, level)
    now = first
    while now < duration:
        while True:
            new_level = rng.uniform(lo, hi)
            if abs(new_level - level) >= 20.0:
                break
        kind = rng.choice(["step", "step", "step", "ramp", "fluctuation"])
        if kind == "ramp":
            length = rng.uniform(0.5, 2.5) * tau
            add(now, now + length, level, new_level)
            now += length
        hold = rng.uniform(3.0, 8.0) * tau
        if kind == "fluctuation":
            # Random piecewise-linear wander of a few kelvin around the new level.
            t_knot = now
            value = new_level
            while t_knot < now + hold:
                step = rng.uniform(0.3, 2.0)
                target = new_level + rng.normal(0.0, 3.0)
                add(t_knot, t_knot + step, value, target)
                t_knot += step
                value = target
            add(t_knot, t_knot + 2.0 * tau, value, new_level)
            now = t_knot + 2.0 * tau
        else:
            add(now, now + hold, new_level, new_level)
            now += hold
        level = new_level
    add(now, now + 1e6, level, level)
    return GasSegments(np.array(starts), np.array(ends), np.array(v0s), np.array(v1s))


@dataclass
class HiddenCase:
    """A recording with hidden effects: `reference` is the input column, `measured` the output."""

    t: np.ndarray
    ts: float
    reference: np.ndarray
    measured: np.ndarray
    gas: np.ndarray
    effects: tuple[str, ...]
    truth: dict[str, float] = field(default_factory=dict)


def _random_chain(
    rng: np.random.Generator, tau: float, nodes: int
) -> tuple[list[float], list[float], float]:
    """Capacities, conductances and heating convection of a chain whose dominant time constant
    is `tau`, whose second one is 8-30 % of it and whose third (if any) is at most 40 % of the
    second, so that one extra pole dominates the higher-order dynamics (rejection sampling)."""
    while True:
        capacities = list(rng.uniform(0.3, 1.0, size=nodes))
        conductances = list(np.exp(rng.uniform(np.log(0.3), np.log(8.0), size=nodes - 1)))
        h = float(np.exp(rng.uniform(np.log(0.2), np.log(2.0))))
        taus = conduction_chain(capacities, conductances, h).time_constants()
        ratio = taus[1] / taus[0]
        if 0.08 <= ratio <= 0.30 and (nodes < 3 or taus[2] <= 0.4 * taus[1]):
            scale = taus[0] / tau  # time scales with 1/conductance: rescale to dominant = tau
            return capacities, [g * scale for g in conductances], h * scale


def make_case(
    effects: Sequence[str],
    seed: int,
    *,
    duration: float = 1800.0,
    ts: float = 0.1,
    noise: tuple[float, float] | None = None,
    tau: float | None = None,
) -> HiddenCase:
    """Recording of a sensor with the hidden `effects` (names from CATALOGUE), random parameters
    of realistic size drawn from `seed`."""
    unknown = set(effects) - set(CATALOGUE)
    if unknown:
        raise ValueError(f"make_case: unknown effects {sorted(unknown)}")
    rng = np.random.default_rng(seed)
    tau = float(np.exp(rng.uniform(np.log(3.0), np.log(25.0)))) if tau is None else tau
    truth: dict[str, float] = {"tau": tau}
    sigma_ref, sigma_out = noise if noise is not None else tuple(rng.uniform(0.05, 0.1, size=2))
    truth["noise_reference"] = float(sigma_ref)
    truth["noise_measured"] = float(sigma_out)

    if "extra_pole" in effects:
        nodes = int(rng.choice([2, 3]))
        capacities, conductances, h = _random_chain(rng, tau, nodes)
    else:
        capacities, conductances, h = [1.0], [], 1.0 / tau
    h_cool = h
    if "hysteresis" in effects:
        ratio = float(np.exp(rng.uniform(np.log(1.3), np.log(1.7))))
        h_cool = h / ratio if rng.random() < 0.5 else h * ratio
        truth["convection_ratio_heat_over_cool"] = float(h / h_cool)
    sensor = conduction_chain(capacities, conductances, h, h_cool)
    truth["tau_heat"] = float(sensor.time_constants("heat")[0])
    truth["tau_cool"] = float(sensor.time_constants("cool")[0])
    if sensor.nodes > 1:
        taus = sensor.time_constants()
        truth["tau2_over_tau"] = float(taus[1] / taus[0])
        if sensor.nodes > 2:
            truth["tau3_over_tau"] = float(taus[2] / taus[0])

    n = round(duration / ts) + 1
    t = np.arange(n) * ts
    gas_segments = random_gas(rng, duration, max(truth["tau_heat"], truth["tau_cool"]))
    arriving = gas_segments
    if "dead_time" in effects:
        delay = float(rng.uniform(0.12, 0.3) * tau)
        truth["delay"] = delay
        arriving = gas_segments.shifted(delay)
    initial = float(gas_segments.v0[0])
    element = simulate_chain(sensor, arriving, t, initial)

    if "offset" in effects:
        offset = float(rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 2.0))
        truth["offset"] = offset
        element = element + offset  # e.g. self-heating of the element
    reading = cvd_linear_reading(element) if "nonlinearity" in effects else element
    if "gain" in effects:
        gain = float(1.0 + rng.choice([-1.0, 1.0]) * rng.uniform(0.02, 0.05))
        truth["gain"] = gain
        reading = gain * reading

    tau_ref = float(rng.uniform(0.01, 0.04))  # fine bare-wire thermocouple as reference
    truth["tau_reference"] = tau_ref
    reference_sensor = conduction_chain([1.0], [], 1.0 / tau_ref)
    reference = simulate_chain(reference_sensor, gas_segments, t, initial)
    reference = reference + rng.normal(0.0, sigma_ref, size=n)
    measured = reading + rng.normal(0.0, sigma_out, size=n)
    return HiddenCase(
        t=t,
        ts=ts,
        reference=reference,
        measured=measured,
        gas=gas_segments(t),
        effects=tuple(effects),
        truth=truth,
    )
