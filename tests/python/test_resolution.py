"""The smoother's bandwidth (dualprobe.reconstruction.resolution) against the smoother itself.

A sine gas through first-order stages has an exact steady-state response (amplitude
prod 1/sqrt(1 + (w tau)^2), phase -sum atan(w tau)): written here, independent of the product's
discretisation. The smoother (the banded MAP solve the product runs, at a fixed intensity) is
linear, so on noise-free readings its estimate is the gas times its gain; the predicted Wiener
gain must match it, and be 1/2 at the reported bandwidth."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dualprobe.reconstruction import bandwidth
from dualprobe.reconstruction.resolution import wiener_gain
from dualprobe.reconstruction.statespace import pair_model
from dualprobe.reconstruction.trajectory import Trajectory


def _steady_response(t: np.ndarray, frequency: float, taus: tuple[float, ...]) -> np.ndarray:
    w = 2.0 * math.pi * frequency
    amplitude = math.prod(1.0 / math.sqrt(1.0 + (w * tau) ** 2) for tau in taus)
    phase = -sum(math.atan(w * tau) for tau in taus)
    return amplitude * np.sin(w * t + phase)


def _smoother_gain(model: object, q: float, sigma: tuple[float, float], frequency: float,
                   taus: tuple[tuple[float, ...], tuple[float, ...]], ts: float) -> float:
    """In-phase gain of the smoother's gas on a noise-free sine, away from the record's ends."""
    n = 6000
    t = np.arange(n) * ts
    y = np.column_stack([_steady_response(t, frequency, taus[0]),
                         _steady_response(t, frequency, taus[1])])
    system = Trajectory(model, y, np.asarray(sigma))  # type: ignore[arg-type]
    _, x, _ = system.evaluate(math.log(q), np.ones(n - 1), np.zeros(n - 1, dtype=np.intp))
    middle = slice(n // 4, 3 * n // 4)
    w = 2.0 * math.pi * frequency
    basis = np.column_stack([np.sin(w * t[middle]), np.cos(w * t[middle])])
    coefficients = np.linalg.lstsq(basis, x[middle, 0], rcond=None)[0]
    assert abs(coefficients[1]) < 1e-3  # zero phase: the smoother is non-causal
    return float(coefficients[0])


@pytest.mark.parametrize("gas,taus1,taus2,ts,q,sigma", [
    ("irw", (4.0,), (12.0,), 0.1, 200.0, (0.05, 0.05)),  # a drive-cycle pair at 10 Hz
    ("rw", (0.3, 4.0), (12.0,), 0.1, 30.0, (0.05, 0.08)),  # a sheath: the stage floor counts
    ("irw", (20.0,), (1.0, 50.0), 1.0, 0.01, (0.02, 0.02)),  # slow laboratory RTDs at 1 Hz
])
def test_the_predicted_gain_is_the_smoothers(gas: str, taus1: tuple[float, ...],
                                             taus2: tuple[float, ...], ts: float, q: float,
                                             sigma: tuple[float, float]) -> None:
    model = pair_model(taus1, taus2, ts, gas=gas)
    resolved = bandwidth(model, q, sigma)
    assert not resolved.limited
    assert resolved.low_hz == resolved.hz == resolved.high_hz  # constant time constants
    assert 0.0 < resolved.hz < 0.5 / ts
    for frequency in (resolved.hz / 3.0, resolved.hz, 3.0 * resolved.hz):
        measured = _smoother_gain(model, q, sigma, frequency, (taus1, taus2), ts)
        predicted = float(wiener_gain(model, q, sigma, frequency))
        # the prediction is the continuous-time steady state; the smoother is discrete (FOH
        # input, exact discretisation): measured 0.0002-0.017 apart up to w Ts = 0.45
        assert measured == pytest.approx(predicted, abs=0.03)
    assert float(wiener_gain(model, q, sigma, resolved.hz)) == pytest.approx(0.5, abs=1e-9)


def test_fast_sensors_are_limited_by_the_sampling() -> None:
    """Sensors far faster than the samples and a rough gas: every frequency below Nyquist is
    resolved, and the bandwidth says the sampling limits it."""
    model = pair_model((0.05,), (0.2,), 1.0, gas="rw")
    resolved = bandwidth(model, 1e4, (0.01, 0.01))
    assert resolved.limited and resolved.hz == pytest.approx(0.5)


def test_time_constants_that_follow_the_flow_give_a_range() -> None:
    """A schedule doubling the time constants over the record: the bandwidth at the slowest
    level is the lowest, and the reported median lies between the 5 % and 95 % levels."""
    n = 2000
    schedule = np.linspace(1.0, 2.0, n)
    model = pair_model((4.0,), (12.0,), 0.1, gas="irw", schedule=schedule)
    resolved = bandwidth(model, 200.0, (0.05, 0.05))
    fast = bandwidth(pair_model((4.0,), (12.0,), 0.1, gas="irw"), 200.0, (0.05, 0.05))
    slow = bandwidth(pair_model((8.0,), (24.0,), 0.1, gas="irw"), 200.0, (0.05, 0.05))
    assert slow.hz < resolved.low_hz < resolved.hz < resolved.high_hz < fast.hz
    # the 5 % and 95 % levels of a linear ramp: 1.05 and 1.95 times the time constants
    assert resolved.high_hz == pytest.approx(
        bandwidth(pair_model((4.2,), (12.6,), 0.1, gas="irw"), 200.0, (0.05, 0.05)).hz, rel=0.01)
    assert resolved.low_hz == pytest.approx(
        bandwidth(pair_model((7.8,), (23.4,), 0.1, gas="irw"), 200.0, (0.05, 0.05)).hz, rel=0.01)
