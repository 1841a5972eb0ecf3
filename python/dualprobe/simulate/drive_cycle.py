"""Field conditions: a vehicle drive cycle seen by a pair of sheathed, flow-dependent sensors.

The chain is the one in an exhaust (Hung et al.'s setting, paper eq. 1): a vehicle speed trace
(idle, accelerations, cruises with road-grade changes, decelerations with fuel cut-off) sets the
engine load and speed; these set the exhaust mass flow and the exhaust gas temperature, which
responds fast through combustion and slowly through the manifold walls, plus a small
band-limited fluctuation; the gas velocity follows the mass flow and the gas density.

Each sensor is a chain: an optional sheath stage (time constant ``sheath_tau_ref``) in front of
the element (the dominant stage, ``tau_ref``), both following the gas velocity,
``tau(t) = tau_ref (v(t)/v_ref)^-m`` (paper eq. 1, 0.3 <= m <= 0.7; the sheath may have its
own exponent), optionally slower while cooling (``cooling_factor``) and slower at high gas
temperature (``level_exponent``: gas properties, ``(Tg/T_ref)^-n``), with a static gain and
offset, white noise, ADC quantisation, a logger that holds readings and a jittering clock.

The integration is exact for what it resolves: on a fine grid (``dt``) the gas is linear and
each stage's time constant constant over a step (taken at the step's midpoint), and the
two-stage chain is advanced by its closed-form solution for a linear input; the affine step
maps are composed with a parallel prefix scan (vectorised). The direction of each stage
(heating or cooling) is found by a fixed-point iteration on the trajectory. With the default
``dt`` of 5 ms it agrees with an adaptive ODE solver (LSODA, rtol 1e-10) to 2e-5 K
(tests/python/test_drive_cycle.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import scipy.signal

from dualprobe.simulate.profiles import RngLike, _rng
from dualprobe.simulate.sensors import _prefix_affine

__all__ = [
    "DriveCycle",
    "FieldRecording",
    "FieldSensor",
    "drive_cycle",
    "simulate_field_pair",
    "speed_trace",
]

_G = 9.81


@dataclass(frozen=True)
class FieldSensor:
    """A sensor in the exhaust. Time constants in seconds at the reference velocity."""

    tau_ref: float
    exponent: float = 0.5
    sheath_tau_ref: float = 0.0
    sheath_exponent: float | None = None  # None: the element's exponent
    cooling_factor: float = 1.0  # tau while cooling / tau while heating (both stages)
    level_exponent: float = 0.0  # tau ~ (Tg / level_reference)^-n (gas properties)
    level_reference: float = 573.15
    gain: float = 1.0
    offset: float = 0.0
    noise_std: float = 0.05

    def __post_init__(self) -> None:
        for name in ("tau_ref", "cooling_factor", "gain", "level_reference"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"FieldSensor: {name} must be finite and > 0, got {value!r}")
        for name in ("sheath_tau_ref", "noise_std"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"FieldSensor: {name} must be finite and >= 0, got {value!r}")

    def time_constants(
        self, velocity: np.ndarray, v_ref: float, gas: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """(sheath, element) heating time constants for the given gas velocity (and level)."""
        ratio = np.asarray(velocity, dtype=float) / v_ref
        level = 1.0
        if gas is not None and self.level_exponent != 0.0:
            level = (np.asarray(gas, dtype=float) / self.level_reference) ** -self.level_exponent
        m_s = self.exponent if self.sheath_exponent is None else self.sheath_exponent
        element = self.tau_ref * ratio**-self.exponent * level
        sheath = self.sheath_tau_ref * ratio**-m_s * level
        return sheath, element


@dataclass
class DriveCycle:
    """Conditions on a fine time grid: vehicle speed (km/h), engine load (0-1), engine speed
    (rpm), exhaust mass flow (kg/s), gas temperature (K) and gas velocity (m/s)."""

    t: np.ndarray
    vehicle_speed: np.ndarray
    load: np.ndarray
    engine_speed: np.ndarray
    mass_flow: np.ndarray
    gas: np.ndarray
    velocity: np.ndarray

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])


def speed_trace(
    duration: float, dt: float, rng: RngLike = None
) -> tuple[np.ndarray, np.ndarray]:
    """Vehicle speed (m/s) on a grid of step ``dt``: idle stops, accelerations of 0.6-2.5
    m/s^2, cruises of 10-90 s at up to 140 km/h with +-5 % drift, decelerations of 0.8-3 m/s^2,
    smoothed like a driver (second-order, ~1 s)."""
    gen = _rng(rng)
    n = round(duration / dt) + 1
    t = np.arange(n) * dt
    knots_t, knots_v = [0.0], [0.0]
    now, v = 0.0, 0.0
    while now < duration + 60.0:
        if v < 0.5:
            now += gen.uniform(5.0, 30.0)
            knots_t.append(now)
            knots_v.append(0.0)
            target = gen.choice([gen.uniform(8, 15), gen.uniform(14, 25), gen.uniform(22, 38)])
        else:
            target = gen.choice(
                [0.0, max(0.0, v - gen.uniform(5, 15)), min(38.0, v + gen.uniform(5, 15))])
        rate = gen.uniform(0.6, 2.5) if target > v else gen.uniform(0.8, 3.0)
        now += abs(target - v) / rate
        v = float(target)
        knots_t.append(now)
        knots_v.append(v)
        if v > 0.5:
            now += gen.uniform(10.0, 90.0)
            v *= gen.uniform(0.95, 1.05)
            knots_t.append(now)
            knots_v.append(v)
    speed = np.interp(t, knots_t, knots_v)
    b, a = scipy.signal.butter(2, min(0.3 * 2.0 * dt, 0.9))
    return t, np.maximum(scipy.signal.filtfilt(b, a, speed), 0.0)


def _lag(x: np.ndarray, dt: float, tau: float) -> np.ndarray:
    a = math.exp(-dt / tau)
    return scipy.signal.lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])[0]


def drive_cycle(
    duration: float,
    rng: RngLike = None,
    *,
    dt: float = 0.005,
    gas_range: tuple[float, float] = (460.0, 700.0),
    velocity_range: tuple[float, float] = (7.0, 60.0),
    fluctuation_std: float = 1.0,
    fluctuation_hz: float = 1.0,
    manifold_tau: float = 40.0,
    manifold_share: float = 0.45,
) -> DriveCycle:
    """Simulated exhaust conditions for ``duration`` seconds.

    The gas temperature spans ``gas_range`` (K) and the velocity ``velocity_range`` (m/s,
    log-affinely mapped); ``fluctuation_std`` K of band-limited noise (an octave either side of
    ``fluctuation_hz``) rides on the gas. Road grade drifts between -4 % and +4 % so that the
    load varies during cruises too."""
    if not (duration > 0.0 and dt > 0.0 and duration / dt >= 10):
        raise ValueError("drive_cycle: need duration > 0 and at least 10 fine steps")
    gen = _rng(rng)
    t, v = speed_trace(duration, dt, gen)
    acc = np.gradient(v, dt)
    grade = 0.04 * np.tanh(_lag(gen.standard_normal(t.size), dt, 20.0) * 8.0)
    mass, crr, cda, rho = 1500.0, 0.012, 0.7, 1.2
    power = (mass * acc + mass * _G * (crr + grade) + 0.5 * rho * cda * v * v) * v
    fuel_cut = (power < 0.0) & (v > 5.0)
    load = np.where(fuel_cut, 0.0, np.clip(power / 90e3, 0.04, 1.0))
    ratios = np.array([120.0, 75.0, 52.0, 40.0, 32.0, 27.0])  # rpm per m/s, gears 1-6
    gear_rpm = ratios[:, None] * v[None, :]
    usable = (gear_rpm >= 1300.0) & (gear_rpm <= 3000.0)
    highest = len(ratios) - 1 - np.argmax(usable[::-1], axis=0)
    gear = np.where(usable.any(axis=0), highest, 0)
    rpm = np.maximum(gear_rpm[gear, np.arange(v.size)], 800.0)
    mass_flow = 0.1 * rpm / 3000.0 * (0.15 + 0.85 * load)
    steady = np.where(fuel_cut, 0.0, load**0.6 + 0.15 * (rpm - 800.0) / 2200.0)
    combustion = _lag(steady, dt, 0.3)
    wall = _lag(combustion, dt, manifold_tau)
    shape = (1.0 - manifold_share) * combustion + manifold_share * wall
    lo, hi = gas_range
    gas = lo + (hi - lo) * (shape - shape.min()) / max(float(np.ptp(shape)), 1e-12)
    if fluctuation_std > 0.0:
        nyq = 0.5 / dt
        band = [0.5 * fluctuation_hz / nyq, min(2.0 * fluctuation_hz / nyq, 0.99)]
        b, a = scipy.signal.butter(2, band, "band")
        wiggle = scipy.signal.lfilter(b, a, gen.standard_normal(t.size))
        gas = gas + fluctuation_std * wiggle / max(float(np.std(wiggle)), 1e-12)
    density_flow = np.log(_lag(mass_flow, dt, 0.2) * gas)  # v ~ mdot / rho ~ mdot T
    vlo, vhi = velocity_range
    span = max(float(np.ptp(density_flow)), 1e-12)
    velocity = np.exp(math.log(vlo) + (density_flow - density_flow.min()) / span
                      * (math.log(vhi) - math.log(vlo)))
    return DriveCycle(t, v * 3.6, load, rpm, mass_flow, gas, velocity)


def _first_order(x0: float, a: np.ndarray, f: np.ndarray) -> np.ndarray:
    """x(k+1) = a_k x(k) + f_k from x(0) = x0, all steps (N,) -> states (N+1,)."""
    a_cum, f_cum = _prefix_affine(a, f)
    return np.concatenate(([x0], a_cum * x0 + f_cum))


def _stage(u: np.ndarray, tau: np.ndarray, h: np.ndarray, x0: float) -> np.ndarray:
    """A first-order stage with time constant tau[k] on step k and input linear between the
    grid values u: exact per step."""
    slope = np.diff(u) / h
    a = np.exp(-h / tau)
    # tau x' = u0 + s t - x  =>  x(h) = a x0 + (1 - a)(u0 - s tau) + s h
    f = -np.expm1(-h / tau) * (u[:-1] - slope * tau) + slope * h
    return _first_order(x0, a, f)


def _chain(
    u: np.ndarray, sheath: np.ndarray, element: np.ndarray, h: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Sheath (taus ``sheath``, may be all 0) -> element, exact per step for a linear input
    and constant time constants: the element is driven by the sheath's exact trajectory
    within the step (closed form of the 2x2 triangular system)."""
    if not np.any(sheath > 0.0):
        return u.copy(), _stage(u, element, h, float(u[0]))
    a, b = sheath, element
    x1 = _stage(u, a, h, float(u[0]))
    slope = np.diff(u) / h
    eb = np.exp(-h / b)
    d = 1.0 / b - 1.0 / a
    hd = h * d
    small = np.abs(hd) < 1e-8
    rel = np.where(small, 1.0 + 0.5 * hd, np.expm1(hd) / np.where(small, 1.0, hd))
    m21 = (h / b) * eb * rel  # coupling of the sheath's start state into the element's end
    # particular solution for input u0 + s t: p1 = u0 + s t - s a, p2 = p1 - s b
    p1_0 = u[:-1] - slope * a
    p2_0 = p1_0 - slope * b
    p2_h = p2_0 + slope * h
    # x2(h) = eb x2(0) + m21 x1(0) + [p2_h - (eb p2_0 + m21 p1_0)]
    f = m21 * x1[:-1] + p2_h - (eb * p2_0 + m21 * p1_0)
    return x1, _first_order(float(u[0]), eb, f)


def _sensor_trajectory(
    conditions: DriveCycle, sensor: FieldSensor, v_ref: float, max_passes: int = 12
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free output on the fine grid and the element's and sheath's time constants in
    effect on each step (the last repeated)."""
    t, gas = conditions.t, conditions.gas
    h = np.diff(t)
    mid_v = 0.5 * (conditions.velocity[1:] + conditions.velocity[:-1])
    mid_g = 0.5 * (gas[1:] + gas[:-1])
    sheath_h, element_h = sensor.time_constants(mid_v, v_ref, mid_g)
    cool_s = np.zeros(h.size, dtype=bool)
    cool_e = np.zeros(h.size, dtype=bool)
    factor = sensor.cooling_factor
    for _ in range(max_passes):
        sheath = np.where(cool_s, factor * sheath_h, sheath_h)
        element = np.where(cool_e, factor * element_h, element_h)
        x1, x2 = _chain(gas, sheath, element, h)
        if factor == 1.0:
            break
        # direction of each stage over a step: its input below its state at the midpoint
        new_s = 0.5 * (gas[1:] + gas[:-1]) < 0.5 * (x1[1:] + x1[:-1])
        new_e = 0.5 * (x1[1:] + x1[:-1]) < 0.5 * (x2[1:] + x2[:-1])
        if np.array_equal(new_s, cool_s) and np.array_equal(new_e, cool_e):
            break
        cool_s, cool_e = new_s, new_e
    def full(x: np.ndarray) -> np.ndarray:
        return np.concatenate((x, x[-1:]))

    return x2, full(element), full(sheath)


@dataclass
class FieldRecording:
    """A simulated field recording at the logger's rows.

    ``t`` row times (s; irregular with clock jitter), ``t1``/``t2`` the logged sensor readings,
    ``tg`` the true gas temperature, ``flow`` the gas velocity (m/s) and ``mass_flow`` (kg/s)
    at the rows, ``tau1``/``tau2`` the element time constants in effect (truth),
    ``sheath1``/``sheath2`` the sheath time constants in effect (0 without a sheath),
    ``t1_clean``/``t2_clean`` the noise-free readings, ``ts`` the nominal row interval."""

    t: np.ndarray
    t1: np.ndarray
    t2: np.ndarray
    tg: np.ndarray
    flow: np.ndarray
    mass_flow: np.ndarray
    tau1: np.ndarray
    tau2: np.ndarray
    sheath1: np.ndarray
    sheath2: np.ndarray
    ts: float
    t1_clean: np.ndarray
    t2_clean: np.ndarray
    v_ref: float
    sensors: tuple[FieldSensor, FieldSensor] = field(default=None)  # type: ignore[assignment]

    def to_csv(self, path: str, *, truth: bool = True) -> None:
        """``t,T_m1,T_m2,flow,mass_flow`` (+ ``T_g,tau1,tau2`` with ``truth``)."""
        columns = {"t": self.t, "T_m1": self.t1, "T_m2": self.t2, "flow": self.flow,
                   "mass_flow": self.mass_flow}
        if truth:
            columns.update(T_g=self.tg, tau1=self.tau1, tau2=self.tau2)
        data = np.column_stack(list(columns.values()))
        np.savetxt(path, data, delimiter=",", header=",".join(columns), comments="",
                   fmt="%.10g")


def simulate_field_pair(
    conditions: DriveCycle,
    sensor1: FieldSensor,
    sensor2: FieldSensor,
    *,
    sample_rate: float = 10.0,
    v_ref: float = 20.0,
    quantisation: float = 0.0,
    hold: int = 1,
    jitter: float = 0.0,
    rng: RngLike = None,
) -> FieldRecording:
    """Log the pair at ``sample_rate`` Hz: noise, ADC ``quantisation`` (K), a logger that
    refreshes its reading every ``hold`` rows, and a clock jitter (s, uniform +-jitter) on the
    row instants (the time column records the actual instants)."""
    gen = _rng(rng)
    ts = 1.0 / float(sample_rate)
    if not (ts >= conditions.dt * 0.999):
        raise ValueError("simulate_field_pair: the sample interval must exceed the fine step")
    if hold < 1:
        raise ValueError("simulate_field_pair: hold must be >= 1")
    out1, tau1, sheath1 = _sensor_trajectory(conditions, sensor1, v_ref)
    out2, tau2, sheath2 = _sensor_trajectory(conditions, sensor2, v_ref)
    t_end = float(conditions.t[-1])
    nominal = np.arange(0.0, t_end - jitter - 1e-9, ts)
    instants = nominal + (gen.uniform(-jitter, jitter, nominal.size) if jitter > 0.0 else 0.0)
    instants = np.clip(instants, 0.0, t_end)

    def at(x: np.ndarray) -> np.ndarray:
        return np.interp(instants, conditions.t, x)

    clean1 = sensor1.gain * at(out1) + sensor1.offset
    clean2 = sensor2.gain * at(out2) + sensor2.offset
    read1 = clean1 + sensor1.noise_std * gen.standard_normal(instants.size)
    read2 = clean2 + sensor2.noise_std * gen.standard_normal(instants.size)
    if quantisation > 0.0:
        read1 = np.round(read1 / quantisation) * quantisation
        read2 = np.round(read2 / quantisation) * quantisation
    if hold > 1:
        latest = (np.arange(instants.size) // hold) * hold
        read1, read2 = read1[latest], read2[latest]
    return FieldRecording(
        t=instants, t1=read1, t2=read2, tg=at(conditions.gas), flow=at(conditions.velocity),
        mass_flow=at(conditions.mass_flow), tau1=at(tau1), tau2=at(tau2),
        sheath1=at(sheath1), sheath2=at(sheath2), ts=ts,
        t1_clean=clean1, t2_clean=clean2, v_ref=v_ref, sensors=(sensor1, sensor2),
    )
