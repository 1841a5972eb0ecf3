"""A jittered sampling clock (readings taken early or late, logged at the nominal instant):
measured from the readings (:mod:`dualprobe.models.jitter`), judged by its mean and spread over
the rows by the smoother, on the SEPARATE generator (tests/python/field_independent.py, whose
``jitter`` moves each reading's instant and keeps the logged one)."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest

import field_independent as fi
from dualprobe.models.jitter import jitter_variance, row_noise_scale
from dualprobe.reconstruction.statespace import pair_model
from dualprobe.reconstruction.trajectory import Trajectory
from dualprobe.workflows.characterisation import Characterisation
from dualprobe.workflows.characterise import characterise_arrays
from field_oracle import oracle

# an unsheathed 3.1 / 12.6 s pair, m 0.32, 0.02 K noise and 0.02 K steps, 25 Hz
_PAIR = {"tau": 3.11, "ratio": 4.06, "m": 0.32, "sheaths": (0.0, 0.0), "gains": (0.961, 0.975),
         "noise": 0.02, "adc": 0.02, "hold": 1}


@pytest.mark.parametrize(("rate", "jitter"), [(25.0, 0.01), (25.0, 0.005), (10.0, 0.01)])
def test_the_clock_jitter_is_measured_from_the_readings(rate: float, jitter: float) -> None:
    """Each sensor's noise variance grows as sigma^2 + j^2 x'^2; the fit over eight slope
    classes of 1 200 s gives j within 15 % (measured 9.8 / 10.1, 4.9 / 5.0, 10.7 / 10.8 ms: a
    class's robust mean of 1 800-3 750 squared differences scatters by ~5 % in variance)."""
    rec = fi.record(83003, rate=rate, jitter=jitter, duration=1200.0, **_PAIR)
    for x in (rec.t1, rec.t2):
        j = math.sqrt(jitter_variance(x, rec.ts))
        if j == 0.0 and jitter < 0.01:
            continue  # the slow sensor's slopes are too small to show 5 ms
        assert j == pytest.approx(jitter, rel=0.15)


@pytest.mark.parametrize(("rate", "jitter"), [(1.0, 0.0), (2.0, 0.0), (10.0, 0.0), (25.0, 0.0),
                                             (2.0, 0.01)])
def test_no_jitter_is_found_where_there_is_none_or_it_cannot_be_told(rate: float,
                                                                      jitter: float) -> None:
    """Without jitter: nothing at 10-25 Hz (the differences are noise on every row) nor at
    1-2 Hz, where the drive cycle's own motion shows in the differences, most where the sensor
    moves fastest (the steepest class up to 4 times as variable as the stillest at 2 Hz), and
    the steepest rows' neighbouring differences correlate at -0.2 to -0.55 where white errors
    give -0.8. With 10 ms at 2 Hz
    the jitter is hidden in that motion (15 ms was found before the correlation test): none
    is claimed."""
    rec = fi.record(83003, rate=rate, jitter=jitter, duration=1200.0, **_PAIR)
    for x in (rec.t1, rec.t2):
        assert jitter_variance(x, rec.ts) == 0.0
    assert row_noise_scale(np.column_stack([rec.t1, rec.t2]), rec.ts) is None


def test_rows_alike_are_the_homoscedastic_smoother() -> None:
    """A scale of ones is the smoother without one: the same likelihood and trajectory."""
    rng = np.random.default_rng(4)
    y = np.cumsum(rng.standard_normal((300, 2)), axis=0) * 0.1
    model = pair_model((2.0,), (5.0,), 0.1, gas="rw")
    sigma = np.array([0.05, 0.08])
    lam, modes = np.ones(299), np.zeros(299, dtype=np.intp)
    plain = Trajectory(model, y, sigma).evaluate(0.0, lam, modes)
    scaled = Trajectory(model, y, sigma, np.ones((300, 2))).evaluate(0.0, lam, modes)
    assert scaled[0] == pytest.approx(plain[0], rel=1e-12)
    np.testing.assert_allclose(scaled[1], plain[1], rtol=0, atol=1e-9)


def _within_the_issue_bounds(rec: fi.Recording, gain_ratio: float) -> list[Characterisation]:
    """``rec`` characterised with the mass flow and without, each within the issue's bound of
    the oracle (1.5x, 2.5x) and adequate; the two results."""
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  static2=(gain_ratio, 0.0), gases=("rw",)).rmse
    results = []
    for flow, bound in ((rec.mass_flow, 1.5), (None, 2.5)):  # the issue's bounds
        result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=flow,
                                     flow_column=None if flow is None else "mdot")
        assert result.gas_estimate is not None and result.model_check is not None
        ours = float(np.sqrt(np.mean((result.gas_estimate - rec.gas) ** 2)))
        assert ours <= bound * best
        assert result.model_check.adequate
        results.append(result)
    return results


def test_a_jittered_clock_no_longer_costs_the_gas() -> None:
    """10 ms of jitter at 25 Hz over 400 s: with one noise level per sensor the smoother took
    the errors at the transients (0.25 K at 25 K/s) for the gas, 2.96x the oracle with the
    mass flow (warned) and 2.95x without (called adequate); each row's noise counted by its
    slope, 0.97x and 0.97x (the oracle knows the sensors, not the jitter), the model adequate,
    the jitter named (11 and 12 ms measured)."""
    rec = fi.record(83003, rate=25.0, jitter=0.01, duration=400.0, **_PAIR)
    for result in _within_the_issue_bounds(rec, 0.975 / 0.961):
        named = [re.search(r"about (\d+(?:\.\d+)?) ms early or late", note)
                 for note in result.notes]
        # 11 and 12 ms measured: a third of the rows of the test above, so 25 %
        assert any(m is not None and 7.5 <= float(m.group(1)) <= 12.5 for m in named)


def test_a_given_noise_level_is_the_sensors_own_and_the_jitter_adds_to_it() -> None:
    """--noise-std 0.02 (the sensors' white noise) on the jittered pair: each jittered sensor
    is judged by that level plus the jitter's mean share (0.07 / 0.04 K measured at 1200 s),
    and the gas is as good as with the estimated level."""
    rec = fi.record(83003, rate=25.0, jitter=0.01, duration=400.0, **_PAIR)
    best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2, (rec.noise, rec.noise),
                  static2=(0.975 / 0.961, 0.0), gases=("rw",)).rmse
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                                 flow_column="mdot", noise_std=0.02)
    assert result.gas_estimate is not None and result.model_check is not None
    assert min(result.estimate.noise_std) > 0.02
    ours = float(np.sqrt(np.mean((result.gas_estimate - rec.gas) ** 2)))
    assert ours <= 1.5 * best and result.model_check.adequate


def test_quantised_readings_show_their_jitter_too() -> None:
    """10 ms at 25 Hz through 0.1 K ADC steps (an 8.2 / 25 s pair, m 0.64, 400 s; case 140002
    of settling_study.py 140 30): the differences of the stillest rows are mostly exactly 0,
    so a class's median was 0 and no jitter was found; the smoother took the transients'
    errors for the gas, 2.07x the oracle with the mass flow and called adequate (3.05x
    without). Robust class means find it and the gas is at the oracle's accuracy (1.01x with
    the flow, 1.13x without)."""
    rec = fi.record(140002, tau=8.22, ratio=3.05, m=0.64, rate=25.0, gains=(0.988, 0.985),
                    noise=0.02, adc=0.1, jitter=0.01, duration=400.0)
    for x in (rec.t1, rec.t2):
        # a third of the rows of the first test, coarser readings: 25 %
        assert math.sqrt(jitter_variance(x, rec.ts)) == pytest.approx(0.01, rel=0.25)
    _within_the_issue_bounds(rec, 0.985 / 0.988)
