"""Sensor columns in very different units (workflows/scales.py): a second column logged
1e-5 times smaller (a type S thermocouple's voltage in V beside a temperature) was called a
model misfit with negative misfits printed; the pair is linear in sensor 2's scale, so its
characterisation must be the same pair's, with the static map and noise level in its units."""

from __future__ import annotations

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.workflows.characterise import characterise_arrays


@pytest.fixture(scope="module")
def pair() -> sim.FieldRecording:
    rng = np.random.default_rng(5)
    conditions = sim.drive_cycle(600.0, rng)
    return sim.simulate_field_pair(conditions, sim.FieldSensor(3.0, 0.5),
                                   sim.FieldSensor(9.0, 0.5), sample_rate=10.0,
                                   quantisation=0.02, rng=rng)


# A power of ten changes only the rounding: measured 3e-10 relative in the time constants and
# gain, 3e-8 K in the gas (noise 0.05 K); 1e-6 leaves room for rounding, none for a change of
# model (the old code's misfit moved the time constants by whole per cent).
RELATIVE = 1e-6


@pytest.mark.parametrize("scale", [1e-5, 1e-6, 1e3])
def test_a_column_in_other_units_gives_the_same_pair(pair: sim.FieldRecording,
                                                     scale: float) -> None:
    t2 = 0.98 * pair.t2 + 3.0  # gains and offsets a sensor pair has: the affine map
    base = characterise_arrays(pair.t1, t2, pair.ts, time=pair.t, flow=pair.flow,
                               flow_column="mdot")
    other = characterise_arrays(pair.t1, t2 * scale, pair.ts, time=pair.t, flow=pair.flow,
                                flow_column="mdot")
    assert base.model_check is not None and other.model_check is not None
    assert base.model_check.adequate and other.model_check.adequate
    b, o = base.estimate, other.estimate
    assert np.allclose(o.time_constants, b.time_constants, rtol=RELATIVE, atol=0.0)
    assert o.details["static_model"] == b.details["static_model"] == "affine"
    # T_m1 = g T_m2 + b: g divided by the scale, the offset unchanged (it is in T_m1's scale)
    assert o.details["gain_ratio"] == pytest.approx(b.details["gain_ratio"] / scale,
                                                    rel=RELATIVE)
    assert o.details["offset"] == pytest.approx(b.details["offset"], rel=RELATIVE)
    assert o.noise_std[1] == pytest.approx(b.noise_std[1] * scale, rel=RELATIVE)
    assert o.confidence is not None and b.confidence is not None
    assert o.confidence.std["gain_ratio"] == pytest.approx(
        b.confidence.std["gain_ratio"] / scale, rel=1e-3)  # a jackknife: more rounding
    assert other.gas_estimate is not None and base.gas_estimate is not None
    assert np.max(np.abs(other.gas_estimate - base.gas_estimate)) < RELATIVE
    assert any("columns in different units?" in note for note in other.notes)


def test_unit_gains_in_other_units_are_the_affine_map_of_the_scale(
        pair: sim.FieldRecording) -> None:
    """Unit gains chosen on the rescaled pair are ``T_m1 = 1e5 x T_m2 + 0`` in the columns'
    own units: the static map the summary and the JSON give."""
    base = characterise_arrays(pair.t1, pair.t2, pair.ts, time=pair.t, flow=pair.flow,
                               flow_column="mdot")
    other = characterise_arrays(pair.t1, pair.t2 * 1e-5, pair.ts, time=pair.t,
                                flow=pair.flow, flow_column="mdot")
    assert base.estimate.details["static_model"] != "affine"  # unit gains, by evidence
    assert other.model_check is not None and other.model_check.adequate
    details = other.estimate.details
    assert details["static_model"] == "affine"
    assert details["gain_ratio"] == pytest.approx(1e5, rel=1e-12)
    assert details["offset"] == 0.0
    document = other.to_json_dict()
    assert document["static_model"]["gain_ratio_std"] == 0.0
    assert np.allclose(other.estimate.time_constants, base.estimate.time_constants,
                       rtol=RELATIVE, atol=0.0)
