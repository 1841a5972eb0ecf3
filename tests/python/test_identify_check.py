"""`dualprobe identify`'s model check: a fit that leaves a structured misfit is named on a
warning line and in the JSON (``model_check``), with what to try; the true model is not.

The records come from a generator written here, independent of the identification's model:
the gas (steps at random instants, a slow fluctuation, a random walk) is integrated on a 1 ms
grid through first-order stages by exact recursion, then sampled, with white noise and an ADC
step on both channels. The reference thermocouple lags the gas by ``tref``; the sensor sees the
gas, not the reference, so a reference lag is a real effect the transfer function from the
reference cannot hold (a zero), which the check must see when it matters.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import signal

from dualprobe.cli import main
from dualprobe.identify import fit_step, fit_transfer_function
from dualprobe.workflows.identification import check_identified, check_plunge

FINE = 1e-3


def _lag(x: np.ndarray, taus: list[float]) -> np.ndarray:
    for tau in taus:
        a = math.exp(-FINE / tau)
        x = signal.lfilter([1.0 - a], [1.0, -a], x, zi=[a * x[0]])[0]
    return x


def record(rng: np.random.Generator, taus: list[float], *, rate: float, tref: float,
           noise: float, adc: float, dead: float = 0.0, duration: float = 90.0
           ) -> tuple[float, np.ndarray, np.ndarray]:
    t = np.arange(0.0, duration, FINE)
    gas = np.full(t.size, rng.uniform(20.0, 300.0))
    for at in rng.uniform(0.05 * duration, 0.9 * duration, 5):
        gas[t >= at] += rng.uniform(-80.0, 80.0)
    gas += rng.uniform(1.0, 8.0) * np.sin(2.0 * np.pi * rng.uniform(0.02, 0.2) * t)
    gas += np.cumsum(rng.standard_normal(t.size)) * math.sqrt(FINE) * 0.5
    u = _lag(gas, [tref]) if tref > 0 else gas
    y = rng.uniform(0.97, 1.03) * _lag(gas, taus)
    if dead:
        shift = round(dead / FINE)
        y = np.concatenate([np.full(shift, y[0]), y[:-shift]])
    step = round(1.0 / (rate * FINE))
    u = u[::step] + noise * rng.standard_normal(u[::step].size)
    y = y[::step] + noise * rng.standard_normal(y[::step].size)
    if adc:
        u, y = np.round(u / adc) * adc, np.round(y / adc) * adc
    return 1.0 / rate, u, y


def test_the_true_model_is_not_called_a_misfit() -> None:
    """Eight records of the independent generator, first- and second-order sensors of 2-20 s,
    10-100 Hz, noise 10-100 mK, ADC 0-50 mK, a reference of 1 ms: the true order is adequate.
    Measured 0.49-1.41 times the floor on 70 such records of 60-300 s (limit 2: diagnose's
    rule)."""
    rng = np.random.default_rng(33)
    ratios = []
    for k in range(8):
        dominant = float(rng.uniform(2.0, 20.0))
        taus = [dominant] + ([float(rng.uniform(0.05, 0.3)) * dominant] if k % 2 else [])
        ts, u, y = record(rng, taus, rate=float(rng.choice([10.0, 20.0, 50.0, 100.0])),
                          tref=1e-3, noise=float(rng.uniform(0.01, 0.1)),
                          adc=float(rng.choice([0.0, 0.01, 0.05])))
        fit = fit_transfer_function(ts, u, y, order=len(taus))
        check = check_identified(u, y, fit)
        ratios.append(check.misfit_to_noise)
        assert check.adequate, (k, taus, check)
    print("true model, misfit to the noise floor:", np.round(ratios, 2))


def test_a_hidden_dead_time_is_named_and_then_explained() -> None:
    """A 0.5 s dead time fitted without --delay: a structured misfit whose advice names the
    dead time (measured 5.7 times the floor here, 3.5-3.8 on the paper's records); with it,
    adequate (0.90)."""
    rng = np.random.default_rng(34)
    ts, u, y = record(rng, [8.0, 0.6], rate=20.0, tref=1e-3, noise=0.03, adc=0.0, dead=0.5)
    without = check_identified(u, y, fit_transfer_function(ts, u, y, order=2))
    assert not without.adequate and "a dead time (--delay)" in without.advice
    with_delay = check_identified(u, y, fit_transfer_function(ts, u, y, order=2, delay=True))
    assert with_delay.adequate, with_delay


def test_a_lagging_reference_is_a_misfit_not_hidden() -> None:
    """A reference that lags by 60 ms in front of a 1.5 s sensor at 100 Hz: the transfer
    function from it is a lead-lag no order holds; the time constant comes out 4 % short
    (1.44 s, measured) and the residual 11.6 times the floor. Said, with the advice to use a
    faster reference; with a 0.5 ms reference the same sensor is explained."""
    for tref, adequate in ((0.06, False), (5e-4, True)):
        rng = np.random.default_rng(35)
        ts, u, y = record(rng, [1.5], rate=100.0, tref=tref, noise=0.02, adc=0.0)
        check = check_identified(u, y, fit_transfer_function(ts, u, y, order=1))
        assert check.adequate == adequate, (tref, check)
        assert ("faster reference" in check.summary_line()) == (not adequate)


def plunge(rng: np.random.Generator, taus: list[float], *, rate: float, noise: float,
           adc: float, hold: int, drift: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A sensor plunged into a bath (optionally drifting: not in the step model), sampled,
    with noise, an ADC step and a logger that holds each reading for ``hold`` rows."""
    duration = max(10.0 * taus[0], 20.0)
    t = np.arange(0.0, duration, FINE)
    onset = rng.uniform(1.0, 5.0)
    bath = np.where(t >= onset, rng.uniform(50.0, 400.0) + drift * (t - onset), 20.0)
    y = _lag(bath, taus)
    step = round(1.0 / (rate * FINE))
    t, y = t[::step], y[::step] + noise * rng.standard_normal(t[::step].size)
    if adc:
        y = np.round(y / adc) * adc
    if hold > 1:
        y = np.repeat(y[::hold], hold)[: y.size]
    return t, y


def test_plunges_the_step_model_explains_and_a_drifting_bath() -> None:
    """Plunge tests (`identify --step`): the step response of the order chosen by BIC leaves
    0.55-1.36 times the readings' noise on 60 records of the generator above (measured); a
    bath drifting by 0.05 K/s after the plunge 1.8-48 times (flagged from 3.6 on). Once that
    drift crashed the fit ("array must not contain infs or NaNs": the order-2 Jacobian's step
    took a vanishing tau_b below zero)."""
    rng = np.random.default_rng(36)
    cases = [([12.0], 10.0, 0.05, 0.0, 1), ([15.0, 2.5], 50.0, 0.02, 0.1, 2),
             ([6.0], 5.0, 0.1, 0.25, 4), ([9.0, 1.2], 100.0, 0.01, 0.01, 1)]
    for taus, rate, noise, adc, hold in cases:
        t, y = plunge(rng, taus, rate=rate, noise=noise, adc=adc, hold=hold)
        fit = fit_step(t, y)
        check = check_plunge(t, y, fit)
        assert check.adequate and check.misfit_to_noise < 1.6, (taus, check)
    rng = np.random.default_rng(2)  # crashes without the fix (11.4 s, 10 Hz, 0.1 K ADC)
    t, y = plunge(rng, [11.4], rate=10.0, noise=0.005, adc=0.1, hold=1, drift=0.05)
    fit = fit_step(t, y)
    check = check_plunge(t, y, fit)
    assert not check.adequate and "the bath held one temperature" in check.advice


def test_the_plunge_check_is_printed_and_in_the_json(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    rng = np.random.default_rng(37)
    t, y = plunge(rng, [8.0], rate=10.0, noise=0.02, adc=0.0, hold=1, drift=0.2)
    path, target = tmp_path / "plunge.csv", tmp_path / "plunge.json"
    np.savetxt(path, np.column_stack([t, y]), delimiter=",", header="t,TC", comments="")
    status = main(["identify", str(path), "--output", "TC", "--step", "--json", str(target)])
    out = capsys.readouterr().out
    assert status == 0
    assert "warning: the model does not explain the data" in out
    assert json.loads(target.read_text())["model_check"]["adequate"] is False
