"""Exact time-varying sensor data for the flow-scheduled SVF tests (design.md 1.5).

Independent of the estimators: the gas temperature and the gas velocity are smooth analytic
functions of time, each sensor is a chain of one or two first-order stages whose time
constants follow the flow, ``tau_j(t) = tau_j,ref (v(t)/v_ref)^-m``, and the stages are
integrated on a fine grid with the exact solution of a chain of lags driven by a linear input
(the time constants held at their mid-step values, the gas interpolated linearly over the
fine step). Halving the fine step changes the samples by far less than the tolerances of the
tests (checked in the test module).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SmoothSignal:
    """``level + sum_i size_i (1 + tanh((t - time_i)/width_i))/2 + sum_j amp_j sin(w_j t + p_j)``:
    smoothed steps plus slow oscillations, infinitely differentiable."""

    level: float
    step_times: np.ndarray
    step_sizes: np.ndarray
    step_widths: np.ndarray
    sine_amplitudes: np.ndarray
    sine_frequencies: np.ndarray  # rad/s
    sine_phases: np.ndarray

    def __call__(self, t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        out = np.full(t.shape, self.level)
        for time, size, width in zip(self.step_times, self.step_sizes, self.step_widths,
                                     strict=True):
            out += 0.5 * size * (1.0 + np.tanh((t - time) / width))
        for amp, freq, phase in zip(self.sine_amplitudes, self.sine_frequencies,
                                    self.sine_phases, strict=True):
            out += amp * np.sin(freq * t + phase)
        return out


def smooth_steps(duration: float, rng: np.random.Generator, *, level: float, span: float,
                 mean_hold: float, widths: tuple[float, float], sines: int = 3,
                 sine_amplitude: float = 0.0, sine_periods: tuple[float, float] = (5.0, 60.0),
                 ) -> SmoothSignal:
    """Steps at random times (holds ~ exponential with mean ``mean_hold``) to random levels
    within ``level +/- span/2``, each smoothed over a random width, plus ``sines`` sinusoids."""
    times, sizes = [], []
    current = level + span * (rng.uniform() - 0.5)
    start = current
    t = 0.0
    while True:
        t += mean_hold * (0.3 + rng.exponential(0.7))
        if t >= duration:
            break
        target = level + span * (rng.uniform() - 0.5)
        times.append(t)
        sizes.append(target - current)
        current = target
    n = len(times)
    periods = rng.uniform(*sine_periods, sines)
    return SmoothSignal(
        level=start, step_times=np.array(times), step_sizes=np.array(sizes),
        step_widths=rng.uniform(*widths, n),
        sine_amplitudes=sine_amplitude * rng.uniform(0.3, 1.0, sines),
        sine_frequencies=2.0 * math.pi / periods, sine_phases=rng.uniform(0, 2 * math.pi, sines),
    )


@dataclass(frozen=True)
class Flow:
    """Gas velocity ``v(t) = v_ref exp(half_log_range tanh(shape(t)) + centre)``: smooth and
    bounded in ``[v_ref e^(centre - r), v_ref e^(centre + r)]``."""

    v_ref: float
    shape: SmoothSignal
    centre: float
    half_log_range: float

    def __call__(self, t: np.ndarray) -> np.ndarray:
        return self.v_ref * np.exp(self.centre + self.half_log_range * np.tanh(self.shape(t)))


def drive_flow(duration: float, rng: np.random.Generator, *, v_ref: float = 20.0,
               low: float = 7.0, high: float = 60.0, mean_hold: float = 25.0) -> Flow:
    """A drive-cycle-like velocity between ``low`` and ``high`` m/s: accelerations and
    decelerations over 2-8 s, holds of ~``mean_hold`` s, a slow ripple."""
    shape = smooth_steps(duration, rng, level=0.0, span=3.0, mean_hold=mean_hold,
                         widths=(1.0, 4.0), sines=2, sine_amplitude=0.3,
                         sine_periods=(20.0, 90.0))
    lo, hi = math.log(low / v_ref), math.log(high / v_ref)
    return Flow(v_ref, shape, 0.5 * (lo + hi), 0.5 * (hi - lo))


@dataclass(frozen=True)
class Sensor:
    """Chain of first-order stages (gas -> stage 0 -> stage 1), time constants at v_ref;
    output ``gain * last stage + offset``. ``cool_factor`` (single stage): the time constant is
    that much longer while the sensor is above the gas (decided at the start of each fine
    step)."""

    taus_ref: tuple[float, ...]
    exponent: float = 0.5
    cool_factor: float = 1.0
    gain: float = 1.0
    offset: float = 0.0


@dataclass
class FieldRecord:
    t: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    t1_clean: np.ndarray
    t2_clean: np.ndarray
    gas: np.ndarray
    velocity: np.ndarray
    ts: float


def _chain_maps(taus: np.ndarray, u0: np.ndarray, u1: np.ndarray, dt: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Exact map x(t + dt) = M x(t) + f of a chain of lags (taus (S, n)) driven by the input
    that goes linearly from u0 to u1 (arrays over n intervals); M (n, S, S), f (n, S)."""
    s = (u1 - u0) / dt
    n = u0.size
    stages = taus.shape[0]
    m = np.zeros((n, stages, stages))
    # particular solution for a linear input u0 + s t: stage j lags by s * sum of taus so far
    lag = np.cumsum(taus, axis=0)
    p0 = u0[None, :] - s[None, :] * lag
    p1 = u1[None, :] - s[None, :] * lag
    ta = taus[0]
    m[:, 0, 0] = np.exp(-dt / ta)
    if stages == 2:
        tb = taus[1]
        eb = np.exp(-dt / tb)
        y = dt * (ta - tb) / (ta * tb)
        safe = np.where(y == 0.0, 1.0, y)
        rel = np.where(np.abs(y) < 1e-8, 1.0 + 0.5 * y, np.expm1(safe) / safe)
        m[:, 1, 1] = eb
        m[:, 1, 0] = eb * (dt / tb) * rel
    f = p1.T - np.einsum("nij,jn->ni", m, p0)
    return m, f


def _hysteretic(gas: SmoothSignal, flow: Flow, sensor: Sensor, t: np.ndarray, substeps: int,
                initial: float) -> np.ndarray:
    """Single stage whose time constant is ``cool_factor`` times longer while the sensor is
    above the gas: sequential fine steps (the direction depends on the state)."""
    if len(sensor.taus_ref) != 1:
        raise ValueError("cool_factor: single-stage sensors only")
    ts = t[1] - t[0]
    dt = ts / substeps
    fine = t[0] + dt * np.arange((t.size - 1) * substeps + 1)
    u = gas(fine).tolist()
    tau = (sensor.taus_ref[0] * (flow(fine[:-1] + 0.5 * dt) / flow.v_ref)
           ** (-sensor.exponent)).tolist()
    out = np.empty(t.size)
    y = initial
    out[0] = y
    for i in range(len(tau)):
        u0, u1 = u[i], u[i + 1]
        ta = tau[i] * (sensor.cool_factor if u0 < y else 1.0)
        s = (u1 - u0) / dt
        y = u1 - s * ta + (y - u0 + s * ta) * math.exp(-dt / ta)
        if (i + 1) % substeps == 0:
            out[(i + 1) // substeps] = y
    return out


def simulate(gas: SmoothSignal, flow: Flow, sensors: Sequence[Sensor], *, ts: float,
             duration: float, substeps: int = 20, noise_std: float = 0.0,
             rng: np.random.Generator | None = None, initial_offset: float = 0.0) -> FieldRecord:
    """Samples every ``ts`` of the sensors' outputs (``substeps`` exact fine steps a sample).
    The sensors start at rest at the gas temperature plus ``initial_offset`` (then the record
    starts in a transient)."""
    n = round(duration / ts) + 1
    t = ts * np.arange(n)
    dt = ts / substeps
    outputs = []
    for sensor in sensors:
        stages = len(sensor.taus_ref)
        taus_ref = np.asarray(sensor.taus_ref, dtype=float)[:, None]
        # compose the fine steps of each sample interval (vectorised over the intervals)
        big_m = np.broadcast_to(np.eye(stages), (n - 1, stages, stages)).copy()
        big_f = np.zeros((n - 1, stages))
        for j in range(substeps):
            a = t[:-1] + j * dt
            b = a + dt
            phi = (flow(a + 0.5 * dt) / flow.v_ref) ** (-sensor.exponent)
            m, f = _chain_maps(taus_ref * phi[None, :], gas(a), gas(b), dt)
            big_f = np.einsum("nij,nj->ni", m, big_f) + f
            big_m = np.einsum("nij,njk->nik", m, big_m)
        x = np.full(stages, float(gas(np.array([0.0]))[0]) + initial_offset)
        if sensor.cool_factor != 1.0:
            out = _hysteretic(gas, flow, sensor, t, substeps, float(x[0]))
        else:
            out = np.empty(n)
            out[0] = x[-1]
            mm = big_m.tolist()
            ff = big_f.tolist()
            for k in range(n - 1):  # sequential: the composed per-interval maps
                mk, fk = mm[k], ff[k]
                if stages == 1:
                    x = [mk[0][0] * x[0] + fk[0]]
                else:
                    x = [mk[0][0] * x[0] + mk[0][1] * x[1] + fk[0],
                         mk[1][0] * x[0] + mk[1][1] * x[1] + fk[1]]
                out[k + 1] = x[-1]
        outputs.append(sensor.gain * out + sensor.offset)
    rng = rng if rng is not None else np.random.default_rng(0)
    noisy = [o + noise_std * rng.standard_normal(n) if noise_std > 0 else o.copy()
             for o in outputs]
    return FieldRecord(t=t, t1=noisy[0], t2=noisy[1], t1_clean=outputs[0], t2_clean=outputs[1],
                       gas=gas(t), velocity=flow(t), ts=ts)
