"""The flow column's timing (dualprobe.estimation.flow_timing): a shift in time, the delay
profile's minimum (held values: test_held.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dualprobe.estimation.flow import check_flow
from dualprobe.estimation.flow_timing import delay_profile, shifted
from dualprobe.models.shift import later
from dualprobe.workflows.characterise import characterise_arrays
from test_field_conditions import Case, _record


def test_shifted_is_the_flow_later_in_time() -> None:
    ts = 0.1
    ramp = 5.0 + 0.2 * np.arange(200)
    signal = check_flow(ramp, "mdot", ramp.size)
    later = shifted(signal, 0.25, ts)
    # v(t - 0.25 s): 2.5 rows earlier on the ramp; the ends held, the reference unchanged
    np.testing.assert_allclose(later.values[3:], ramp[3:] - 0.2 * 2.5, atol=1e-12)
    assert later.values[0] == ramp[0] and later.reference == signal.reference
    np.testing.assert_allclose(shifted(signal, -0.5, ts).values[:-5], ramp[:-5] + 1.0)
    assert shifted(signal, 0.0, ts) is signal


def test_the_delay_profile_finds_the_minimum_within_the_range() -> None:
    calls: list[float] = []

    def misfit(d: float) -> float:
        calls.append(d)
        return 1.0 + (d - 0.37) ** 2

    d, value = delay_profile(misfit, 0.1)
    assert abs(d - 0.37) < 0.01 and value < 1.0001
    assert len(calls) < 40  # the grid (17) and Brent, not a fine scan
    d, value = delay_profile(lambda d: 1.0 + (d + 0.83) ** 2, 0.1)
    assert abs(d + 0.83) < 0.01
    d, value = delay_profile(lambda d: math.inf, 0.1)
    assert math.isnan(d) and value == math.inf


@pytest.mark.parametrize("seed", [501, 503])
def test_a_late_flow_column_is_located_to_the_searchs_tolerance(seed: int) -> None:
    """A drive cycle (test_field_conditions' nominal record) whose flow column is logged 0.5 s
    late: the delay is refined past half a row. It was left at the first location, 0.458 s
    on the first seed, where the model misfit by 2.25 times the noise (1.12 at 0.5 s)."""
    rng = np.random.default_rng(seed)
    case = Case(float(rng.uniform(0.3, 0.7)), float(rng.uniform(2, 4)), (0.0, 0.0), (1.0, 1.0),
                seed)
    rec = _record(case)
    late = later(rec.flow, 0.5, rec.ts)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction=None,
                                 flow=late, flow_column="mdot", uncertainty=False)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    # the search's tolerance (DELAY_TOLERANCE, 0.01 s) plus the profile's flatness at the
    # noise: measured -0.492 to -0.504 s on seven seeds (one kept -0.468 s: the law at the
    # refined delay changed structure without the evidence a structure change needs)
    assert abs(model.delay + 0.5) < 0.015, model.delay
    assert abs(model.exponent - case.exponent) < 0.005  # measured within 0.0002
    assert result.model_check is not None and result.model_check.adequate
