"""Issue 14: the verdict, logger data and the report on recordings the catalogue does and does not
describe (hidden_field.py, hidden_effects.py; neither imports dualprobe.diagnose).

- negative controls under drive-cycle gas with a varying flow (given): nothing named,
  ``nothing_missing``, in every one of 10 recordings; first-order laboratory controls too;
- out-of-catalogue misfits (intermittent 0.4 Hz pickup, a reading that sticks for seconds):
  ``partly_explained`` or ``unexplained`` in every one of 10 recordings each, the pickup
  localised at its frequency;
- a logger's record (15 ms rows, 0.25 K steps, the reading held for 5 rows): no error, the hold
  and the grid named;
- quantised, held and noise-free inputs never raise anything but the documented errors.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from dualprobe import diagnose as dg
from dualprobe.io import EstimationError
from hidden_effects import make_case
from hidden_field import MISFITS, make_field_case, make_logger_case

SEEDS = tuple(range(1, 11))


def test_drive_cycle_controls_name_nothing_and_find_nothing_missing() -> None:
    outcomes = {}
    for seed in SEEDS:
        case = make_field_case((), seed, conditions="drive")
        d = dg.diagnose(case.reference, case.measured, case.ts, flow=case.flow)
        assert d.verdict is not None
        outcomes[seed] = (d.effects, d.verdict.verdict, round(d.verdict.misfit_to_noise, 2))
    print(f"\ndrive-cycle controls with the flow given: {outcomes}")
    assert all(effects == [] and v == "nothing_missing" for effects, v, _ in outcomes.values())


@pytest.mark.parametrize("seed", [1, 2, 3, 4, 5])
def test_laboratory_controls_find_nothing_missing(seed: int) -> None:
    case = make_case((), seed, duration=(1200.0, 1800.0, 2400.0)[seed % 3])
    d = dg.diagnose(case.reference, case.measured, case.ts)
    assert d.verdict is not None
    assert d.effects == [] and d.verdict.verdict == "nothing_missing", d.verdict.sentence
    # a reference lagging 10-40 ms leaves up to ~1.4x the floor; below the limit of 2
    assert d.verdict.misfit_to_noise < dg.MISFIT_LIMIT


@pytest.mark.parametrize("misfit", MISFITS)
def test_out_of_catalogue_misfits_are_never_explained(misfit: str) -> None:
    outcomes = {}
    for seed in SEEDS:
        case = make_field_case((), seed, misfit=misfit)
        d = dg.diagnose(case.reference, case.measured, case.ts)
        assert d.verdict is not None
        outcomes[seed] = (d.effects, d.verdict.verdict, round(d.verdict.misfit_to_noise, 2))
        assert d.verdict.verdict in ("partly_explained", "unexplained"), d.verdict.sentence
        assert "explains the data" not in d.summary()
        if misfit == "pickup":
            band = d.misfit["frequency"]["dominant_band"]
            # the octave holding most of the excess power holds the pickup's 0.4 Hz
            assert band["low_hz"] <= 0.4 <= band["high_hz"], band
    print(f"\n{misfit}: {outcomes}")


def test_a_loggers_record_is_diagnosed_and_the_hold_named() -> None:
    outcomes = {}
    for seed in SEEDS:
        case = make_logger_case(seed)
        d = dg.diagnose(case.reference, case.measured, case.ts)
        outcomes[seed] = (d.effects, d.verdict.verdict if d.verdict else None)
        steps = {s.effect: s.params for s in d.steps}
        assert "sample_and_hold" in steps and "quantisation" in steps, outcomes[seed]
        assert steps["sample_and_hold"] == {
            "hold_samples": 5.0,
            "hold_phase": case.truth["hold_phase"],
        }
        assert steps["quantisation"]["quantisation_step"] == pytest.approx(0.25, abs=1e-9)
        # the measured channel's noise is never below the grid's rounding error
        assert d.noise_std[1] >= 0.25 / math.sqrt(12.0) - 1e-12
    print(f"\nlogger records: {outcomes}")


def test_quantised_held_and_noise_free_inputs_raise_nothing_undocumented(
    rng: np.random.Generator,
) -> None:
    case = make_field_case((), 5, duration=300.0)
    u, y, ts = case.reference, case.measured, case.ts
    step = 0.25
    held = np.repeat(np.round(y / step)[::4] * step, 4)[: y.size]
    variants = {
        "quantised both, no noise left": (np.round(u / 1.0) * 1.0, np.round(y / 1.0) * 1.0),
        "both held": (np.repeat(u[::3], 3)[: u.size], np.repeat(y[::3], 3)[: y.size]),
        "quantised and held": (np.round(u / step) * step, held),
        "noise-free": (case.gas, dg.simulate_effects(case.gas, ts, {"tau": 3.0, "initial": 100.0})),
    }
    for name, (a, b) in variants.items():
        d = dg.diagnose(a, b, ts)
        assert d.verdict is not None and d.verdict.verdict in dg.VERDICTS, name
        assert all(math.isfinite(s) and s > 0 for s in d.noise_std), (name, d.noise_std)
        json.dumps(d.to_json_dict(), allow_nan=False)
    flat = np.full(500, 20.0)
    with pytest.raises(EstimationError, match="cannot be identified"):
        dg.diagnose(flat, flat, 0.1)  # noise-free and never moving
    constant_steps = np.repeat([20.0, 50.0], 250)
    d = dg.diagnose(constant_steps, constant_steps, 0.1)  # noise-free steps, no lag at all
    assert d.verdict is not None


def test_given_noise_level_is_used_and_checked() -> None:
    case = make_field_case((), 6, duration=300.0)
    d = dg.diagnose(case.reference, case.measured, case.ts, noise_std=(0.05, 0.06))
    assert d.noise_std == (0.05, 0.06)
    assert d.noise["measured_source"] == "given"
    d = dg.diagnose(case.reference, case.measured, case.ts, noise_std=0.07)
    assert d.noise_std == (0.07, 0.07)
    for bad in (0.0, -1.0, math.nan, (0.1,), (0.1, 0.2, 0.3)):
        with pytest.raises(ValueError, match="noise_std"):
            dg.diagnose(case.reference, case.measured, case.ts, noise_std=bad)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("change", "message"),
    [("zero", "must be finite and > 0"), ("nan", "must be finite"), ("short", "samples")],
)
def test_bad_flow_is_a_value_error(change: str, message: str) -> None:
    case = make_field_case((), 7, conditions="drive", duration=120.0)
    flow = case.flow.copy()
    if change == "zero":
        flow[10] = 0.0
    elif change == "nan":
        flow[10] = math.nan
    else:
        flow = flow[:-1]
    with pytest.raises(ValueError, match=message):
        dg.diagnose(case.reference, case.measured, case.ts, flow=flow)


def test_report_regimes_units_and_one_delta_bic_sign(tmp_path: Path) -> None:
    """On a 22 -> 52 degC record: level bands are thirds of the record's own range, every group
    of regimes adds up to 100 % of the time and of the squared error; delta BIC has one sign
    (> 0: evidence for the effect) in the table, the steps and the JSON; parameters carry units."""
    case = make_logger_case(3)
    d = dg.diagnose(case.reference, case.measured, case.ts)
    for localisation in (d.localisation, d.misfit):
        regimes = localisation["regimes"]
        assert set(regimes) == {"direction", "level"}
        low, mid, high = (regimes["level"][b]["range"] for b in ("low", "mid", "high"))
        assert 20.0 < low[0] < 24.0 and 50.0 < high[1] < 55.0, (low, high)
        assert low[1] == pytest.approx(mid[0]) and mid[1] == pytest.approx(high[0])
        for group in regimes.values():
            assert sum(r["fraction_of_time"] for r in group.values()) == pytest.approx(1.0)
            assert sum(r["share_of_squared_error"] for r in group.values()) == pytest.approx(1.0)
    text = d.write_report(tmp_path).read_text()
    assert "level_low" not in text
    hold = next(s for s in d.steps if s.effect == "sample_and_hold")
    assert hold.evidence["delta_bic"] > 0 and hold.evidence["significant"]
    shown = f"{hold.evidence['delta_bic']:.4g}"
    row = next(line for line in text.splitlines() if line.startswith("| + sample_and_hold |"))
    assert row.rstrip(" |").endswith(shown), row
    assert f"delta_bic = {shown}" in text  # the step's evidence line: the same number and sign
    assert re.search(r"tau = [0-9.]+ s\b", text)
    assert "hold_samples = 5 samples" in text
    doc = d.to_json_dict()
    assert doc["steps"][-1]["units"]["hold_samples"] == "samples"
    assert doc["baseline"]["units"]["tau"] == "s"
    assert d.verdict is not None and doc["verdict"] == d.verdict.verdict
    assert doc["misfit"]["misfit_to_noise"] == pytest.approx(doc["misfit_to_noise"])


def test_summary_says_the_verdict_in_one_sentence_with_the_numbers() -> None:
    case = make_field_case((), 2, misfit="sticking", duration=600.0)
    d = dg.diagnose(case.reference, case.measured, case.ts)
    assert d.verdict is not None
    last = d.summary().splitlines()[-1]
    assert last.startswith(f"verdict: {d.verdict.verdict}.")
    assert f"{d.verdict.misfit_to_noise:.3g} x the noise floor" in last
    assert last.count(". ") <= 2  # the verdict word, then one sentence
