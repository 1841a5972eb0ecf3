"""What estimation, reconstruction, identify and diagnose share (dualprobe.models, report)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dualprobe.io import InputError
from dualprobe.models.noise import ORDER_DIAGNOSE, ORDER_ESTIMATION, estimate_noise_std
from dualprobe.report.json import jsonable, write_json

ORDERS = (1, 2, 3, 4)


@pytest.mark.parametrize("order", ORDERS)
def test_noise_of_held_logger_data_is_the_adc_step_not_zero(order: int) -> None:
    """A slow signal through a 0.1 K ADC, held between changes: the differences are mostly
    exactly 0, the MAD is 0, and the RMS of the rare steps is far below the rounding noise.
    The estimate is floored at the rounding noise of one step, q / sqrt(12)."""
    q = 0.1
    t = np.arange(20_000) * 0.1
    held = q * np.round(300.0 + 2.0 * np.sin(2 * np.pi * t / 1800.0) / q)
    assert np.mean(np.diff(held) == 0.0) > 0.9  # mostly held
    assert estimate_noise_std(held, order) == pytest.approx(q / math.sqrt(12.0), rel=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_noise_floor_only_for_quantised_data(order: int) -> None:
    assert estimate_noise_std(np.full(100, 300.0), order) == 0.0  # never moves: no step
    parabola = np.linspace(0.0, 5.0, 200) ** 2  # moves every sample: not held data
    assert estimate_noise_std(parabola, max(order, 3)) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_noise_of_quantised_data_that_move_on_most_rows_is_the_rounding(order: int) -> None:
    """A plunge into a drifting bath through a 0.1 K ADC, 3 mK of noise: the reading moves on
    most rows (so the held-data floor did not apply) and most second differences are float
    rounding: the estimate was 3e-14 K. The readings lie on the ADC's lattice with a few step
    sizes: the rounding noise q / sqrt(12) is the floor (order 3's differences see a little
    more). A straight line (one step size) and a parabola on a lattice (all steps different)
    are not quantised data."""
    q, rng = 0.1, np.random.default_rng(6)
    t = np.arange(1200) * 0.1
    plunge = (20.0 + 330.0 * -np.expm1(-t / 12.0) + 0.15 * t
              + 0.003 * rng.standard_normal(t.size))
    quantised = q * np.round(plunge / q)
    assert np.mean(np.diff(quantised) == 0.0) < 0.5  # moves on most rows
    floor = q / math.sqrt(12.0)
    estimate = estimate_noise_std(quantised, order)
    assert estimate >= floor * (1 - 1e-9)
    assert order == 1 or estimate < 1.2 * floor  # first differences see the drift itself
    assert estimate_noise_std(np.arange(200) * 0.3, order) == pytest.approx(0.0, abs=1e-12)


@pytest.mark.parametrize("order", ORDERS)
def test_a_clean_step_profile_has_no_noise(order: int) -> None:
    """A noise-free reference switched between a few levels (a test generator's input): its
    smallest step is a step, not an ADC's (a 60 K step gave 17 K of "noise" and identify
    refused the record as unexcited), and its few non-zero differences are the steps (the RMS
    of them gave 2 K). Noise 0. Through a 0.1 K ADC with noise the floor stays."""
    t = np.arange(600) * 0.1
    steps = np.where((t > 5.0) & (t < 35.0), 80.0, 20.0)
    staircase = 20.0 + 10.0 * np.floor(t / 12.0)  # five levels
    for clean in (steps, staircase):
        assert estimate_noise_std(clean, order) == 0.0
    noisy = 0.1 * np.round((steps + 0.02 * np.random.default_rng(7).standard_normal(t.size))
                           / 0.1)
    assert estimate_noise_std(noisy, order) >= 0.1 / math.sqrt(12.0) * (1 - 1e-9)


def test_noise_of_white_noise_on_a_smooth_signal() -> None:
    rng = np.random.default_rng(5)
    t = np.arange(20_000) * 0.1
    x = 200.0 + 20.0 * np.sin(2 * np.pi * t / 300.0) + rng.normal(0.0, 0.05, t.size)
    for order in (ORDER_DIAGNOSE, ORDER_ESTIMATION):
        assert estimate_noise_std(x, order) == pytest.approx(0.05, rel=0.05)


def test_noise_rejects_bad_input() -> None:
    with pytest.raises(InputError, match="samples"):
        estimate_noise_std(np.ones(4), 3)
    with pytest.raises(InputError, match="finite"):
        estimate_noise_std(np.array([1.0, 2.0, np.inf, 4.0, 5.0, 6.0]), 2)
    with pytest.raises(ValueError, match="order"):
        estimate_noise_std(np.ones(10), 0)


def test_jsonable_is_strict_json(tmp_path: Path) -> None:
    document = {
        "a": np.float32(1.5), "b": np.int64(3), "c": (1, np.nan), "d": np.array([[1.0, np.inf]]),
        "e": np.bool_(True), "f": None, "g": Path("x.png"), 7: "seven",
    }
    clean = jsonable(document)
    assert clean == {"a": 1.5, "b": 3, "c": [1, None], "d": [[1.0, None]], "e": True,
                     "f": None, "g": "x.png", "7": "seven"}
    target = tmp_path / "doc.json"
    write_json(document, target)
    assert json.loads(target.read_text()) == clean
    with pytest.raises(InputError, match="cannot write"):
        write_json(document, tmp_path / "missing" / "doc.json")
