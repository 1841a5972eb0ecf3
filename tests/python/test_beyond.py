"""dualprobe.studies.beyond: the paper's studies with the second-order and hysteresis-aware methods
(issue 6, "What it must show")."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.models.inverse import zoh_inverse
from dualprobe.reference.difference import exact_inverse
from dualprobe.report.json import jsonable
from dualprobe.studies import beyond, beyond_report
from dualprobe.studies.run import run_beyond


@pytest.fixture(scope="module")
def quick(tmp_path_factory: pytest.TempPathFactory) -> tuple[str, dict[str, Any], Path]:
    """One `run_beyond(quick=True)`: every test below reads its numbers."""
    out = tmp_path_factory.mktemp("beyond")
    markdown, data = run_beyond(True, out, progress=False)
    return markdown, data, out


# ------------------------------------------------------------------------------------------
# The exact zero-order-hold inverse used on the paper's noise-free studies
# ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("taus", [(12.48,), (12.30, 0.17), (25.72, 1.08), (28.95, 0.001)])
def test_zoh_inverse_is_exact_for_gas_constant_over_each_interval(taus: tuple[float, ...]) -> None:
    rng = np.random.default_rng(1)
    ts = 0.1
    step_times = np.sort(rng.choice(np.arange(50, 1900), 6, replace=False)) * ts  # on the grid
    levels = 300.0 + rng.uniform(-200.0, 200.0, 7)
    profile = sim.multistep_profile(200.0, levels=levels, step_times=step_times)
    t = ts * np.arange(2001)
    measured = sim.simulate_sensor(profile, sim.SensorModel(taus), t)
    gas = zoh_inverse(measured, taus, ts)
    assert np.isnan(gas[-1])
    # exact up to rounding of ~1e-4 K steps amplified by the inverse (measured <= 3e-9 K)
    np.testing.assert_allclose(gas[:-1], profile(t[:-1]), atol=1e-6)


def test_zoh_inverse_of_one_time_constant_is_the_papers_inverse() -> None:
    rng = np.random.default_rng(2)
    temps = np.cumsum(rng.standard_normal(500))
    np.testing.assert_allclose(zoh_inverse(temps, (12.48,), 0.1),
                               exact_inverse(temps, 12.48, 0.1), rtol=1e-9, atol=1e-9)


def test_zoh_inverse_rejects_bad_time_constants() -> None:
    # one implementation (dualprobe.models.inverse.zoh_inverse) with its own wording
    with pytest.raises(ValueError, match="must be finite and > 0"):
        zoh_inverse(np.ones(10), (12.0, -1.0), 0.1)


# ------------------------------------------------------------------------------------------
# Issue 6: studies A and B, second-order RMSE at most 10 % of the first-order (paper's) one
# ------------------------------------------------------------------------------------------


@pytest.mark.slow
@pytest.mark.parametrize("study", ["a", "b"])
@pytest.mark.parametrize("variant", ["noise-free", "0.01 K noise"])
def test_studies_second_order_within_10_percent_of_the_papers_method(
    quick: tuple[str, dict[str, Any], Path], study: str, variant: str
) -> None:
    rows = quick[1][f"study_{study}"][variant]
    values = {row["a_p"] for row in rows}
    assert {0.001, 0.01, 0.1, 0.17, 1.08} <= values
    band = beyond.near_equal_band(study.upper(), rows[0]["noise_std"])
    worst, _, left_out = beyond_report.worst_ratio(rows, band=band)
    # issue 6: 10 %; measured <= 0.75 % noise-free (B, a_p = 0.01 s), <= 0.21 % with noise
    # (full sweeps of 45 a_p values: 0.77 % and, outside the band, 1.2 %)
    assert worst is not None and worst <= 0.10
    # left out: study B's equal poles (0.17 s, the paper's study C case) and, with noise,
    # nearly equal fast poles (0.1 s vs 0.17 s: only their difference is identifiable)
    expected = {"a": [], "b": [0.17] if variant == "noise-free" else [0.1, 0.17]}
    assert left_out == expected[study]
    for row in rows:
        assert row["order2_rmse"] is not None and "errors" not in row
        # never worse than the paper's method, in or out of the band (measured <= 0.52; at
        # exactly equal poles both return the filtered gas: 1.00002 noise-free)
        assert row["ratio"] <= 1.001


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["noise-free", "0.01 K noise"])
def test_study_b_equal_poles_is_diagnosed_and_recovers_the_filtered_gas(
    quick: tuple[str, dict[str, Any], Path], variant: str
) -> None:
    row = next(r for r in quick[1]["study_b"][variant] if r["a_p"] == 0.17)
    assert row["order2_identifiable"] is False and row["order2_shared_poles"] == 1
    np.testing.assert_allclose(np.concatenate(row["order2_time_constants"]), [12.30, 25.72],
                               rtol=2e-3)  # distinct poles; measured < 0.03 %
    # what any method can return: the gas filtered by the shared 0.17 s pole; noise-free
    # measured 4e-4 K (paper's standard for its study C: < 1e-2 K); with 0.01 K noise the
    # smoother keeps the steps sharper than the 0.17 s lag: measured 0.34 K
    assert row["rmse_prefiltered"] < (1e-2 if variant == "noise-free" else 1.0)
    assert row["rmse_prefiltered"] < 0.5 * row["order2_rmse"]


@pytest.mark.slow
def test_study_a_fast_pole_resolved_and_first_order_sensor_reported(
    quick: tuple[str, dict[str, Any], Path],
) -> None:
    for row in quick[1]["study_a"]["noise-free"]:
        assert row["order2_sensor_orders"] == [1, 2]
        taus = row["order2_time_constants"]
        assert taus[0][0] == pytest.approx(12.48, rel=1e-4)  # measured 2.4e-5
        # a_p = Ts/100 on a step at a sample: measured 4.3 %; from 10 ms on <= 0.8 %
        assert taus[1][1] == pytest.approx(row["a_p"], rel=0.1 if row["a_p"] < 0.01 else 0.01)


# ------------------------------------------------------------------------------------------
# Issue 6: 100 Hz pair with the paper's second-order models
# ------------------------------------------------------------------------------------------


def _check_second_order_pair(pair: dict[str, Any]) -> None:
    assert pair["reconstruction"] == "smoother"  # reconstruct_pair's default mode
    errors = np.array(pair["order2"]["relative_errors"])
    assert errors[[0, 2]].max() < 0.05  # issue 6: dominant within 5 %; measured < 0.02 %
    assert errors[[1, 3]].max() < 0.25  # issue 6: fast within 25 %; measured < 0.5 %
    # issue 6: at most half the first-order method's RMSE; measured 8e-5 (120 s record) to 0.1
    assert pair["ratio"] is not None and pair["ratio"] <= 0.5
    assert pair["order2"]["rmse"] < 0.1 * pair["sensor1_rmse"]  # far better than the sensor
    assert pair["order2"]["identifiable"] is True


@pytest.mark.slow
def test_100_hz_second_order_pair_in_the_report(quick: tuple[str, dict[str, Any], Path]) -> None:
    _check_second_order_pair(quick[1]["second_order_100hz"])


@pytest.mark.slow
def test_100_hz_second_order_pair_other_seed() -> None:
    pair = beyond.second_order_pair(duration=200.0, seed=7)
    assert pair["steps"] >= 2
    _check_second_order_pair(pair)


# ------------------------------------------------------------------------------------------
# Issue 6: hysteretic pair, and the identifiability diagnostic
# ------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_hysteretic_pair_four_time_constants_and_reconstruction(
    quick: tuple[str, dict[str, Any], Path],
) -> None:
    hyst = quick[1]["hysteresis"]
    aware = hyst["aware"]
    assert max(aware["relative_errors"]) < 0.05  # issue 6: 5 %; measured 0.25 %
    assert aware["identifiable"] is True
    # one common time constant per sensor cannot follow both directions: measured 0.08 K
    # with heating/cooling time constants vs 11.9 K without
    assert aware["rmse"] < 0.05 * hyst["plain"]["rmse"]
    assert hyst["plain"]["model_misfit"]  # the plain fit says its model does not fit


@pytest.mark.slow
def test_identifiability_fires_on_equal_poles_and_is_quiet_elsewhere(
    quick: tuple[str, dict[str, Any], Path],
) -> None:
    data = quick[1]
    cases = data["identifiability"]
    study_c = [c for c in cases if c["case"] == "study C"]
    assert len(study_c) == 6
    for case in study_c:
        assert case["identifiable"] is False and case["shared_poles"] == 1
        np.testing.assert_allclose(np.concatenate(case["time_constants"]), [12.30, 25.72],
                                   rtol=2e-3)  # the distinct poles; measured < 0.03 %
    assert data["second_order_100hz"]["order2"]["identifiable"] is True
    assert data["hysteresis"]["aware"]["identifiable"] is True
    for study in ("a", "b"):
        for row in data[f"study_{study}"]["noise-free"]:
            assert row["order2_identifiable"] is (study == "a" or row["a_p"] != 0.17)
    fired = {(s["study"], s["variant"]): s["fired_at"] for s in data["identifiability_sweeps"]}
    # with 0.01 K a 1 ms pole at 10 Hz leaves both sensors first order: the degenerate order-2
    # fit is reported as such (the 10 ms pole is resolved: measured 0.0091 s)
    assert fired == {("A", "noise-free"): [], ("A", "0.01 K noise"): [0.001],
                     ("B", "noise-free"): [0.17], ("B", "0.01 K noise"): [0.17]}


# ------------------------------------------------------------------------------------------
# The section itself
# ------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_report_section_figures_and_json(quick: tuple[str, dict[str, Any], Path]) -> None:
    markdown, data, out = quick
    for heading in ("### Studies A and B", "### 100 Hz pair", "### Hysteretic pair",
                    "### Identifiability diagnostic", "### Figures"):
        assert heading in markdown
    assert len(data["figures"]) == 5
    for name in data["figures"]:
        path = out / name
        assert path.suffix == ".png" and path.stat().st_size > 10_000
        assert f"]({name})" in markdown
    text = json.dumps(jsonable(data), allow_nan=False)
    assert json.loads(text)["settings"]["quick"] is True
    # paper --quick must stay under a minute in all; measured 15 s for this section alone
    # The run time is reported (speed is measured by commands, not asserted by timed tests).
    assert math.isfinite(data["settings"]["seconds"]) and data["settings"]["seconds"] > 0.0
    assert not math.isnan(data["study_a"]["noise-free"][0]["paper_rmse"])
