"""The flow law's level term searched again with the reconstructed gas as its level
(estimation/relevel.py), on the separate generator (tests/python/field_independent.py: the
sensors follow the velocity, mass flow x T, while the recording offers the mass flow)."""

from __future__ import annotations

from typing import Any

import pytest

from dualprobe.workflows.characterise import characterise_arrays
from field_independent import record
from test_field_independent import _oracle_rmse, _rmse, _tau_errors, _with_mass_flow

# Two unsheathed 10 Hz pairs of `field_sweep_independent`-like draws with a steep law (m 0.66 /
# 0.64), where the level from sensor 1's smoothed inverse left the law 2.02 / 2.76 times the
# noise (flagged "does not explain the data" beside a gas at 1.06x / 1.03x the oracle) with m
# 0.694 / 0.669 and per-row time constants 0.4 % / 0.3 % RMS off.
# And a pair with a 0.48 s sheath on the slow sensor (m 0.63), whose law fitted at 1.17 times
# the noise with m 0.663: with the reconstructed gas 0.96 and m 0.628 (an evidence of 4.7
# only, below the threshold a structural choice needs: the level is no added structure).
STEEP = [
    (9208, {"tau": 5.27, "ratio": 2.92, "m": 0.66}, (1.0, 1.0)),
    (9108, {"tau": 6.24, "ratio": 3.16, "m": 0.64, "gains": (1.018, 1.005)}, (1.018, 1.005)),
    (9101, {"tau": 5.87, "ratio": 2.38, "m": 0.63, "sheaths": (0.0, 0.48),
            "gains": (1.018, 0.974)}, (1.018, 0.974)),
]


@pytest.mark.parametrize("seed,kw,gains", STEEP)
def test_the_reconstructed_gas_is_the_level_term_s_level(seed: int, kw: dict[str, Any],
                                                          gains: tuple[float, float]) -> None:
    rec = record(seed, duration=1200.0, **kw)
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law" and model.level_reference is not None
    assert model.evidence.get("level_from_reconstruction") == 1.0
    # measured: m 0.660 / 0.637 / 0.628, misfit 1.09 / 1.03 / 0.96 (the true gas as the level:
    # 1.06 / 1.03 / 0.96); 0.01 is a third of the error the smoothed level left
    assert abs(model.exponent - kw["m"]) < 0.01
    # measured 0.16 % / 0.16 % / 0.2 % RMS; below the 0.3-0.4 % the smoothed level left
    assert max(_tau_errors(result, rec)) < 0.003
    assert result.gas_estimate is not None
    # measured 1.03x / 1.03x / 1.02x the oracle; the bound is 1.5x
    assert _rmse(result.gas_estimate, rec.gas) <= 1.1 * _oracle_rmse(rec, gains)
    assert result.model_check is not None and result.model_check.adequate


def test_a_level_the_reconstruction_does_not_improve_is_kept() -> None:
    """A sheath on the slow sensor (0.59 s, m 0.7, gains 0.976 / 1.004): the law with the
    sharper level of the first search misfits 1.83 times the noise; with the reconstructed gas
    as the level 7.3 (the same with the true gas). It is not taken, and the result stays as it
    was (1.02x the oracle, m 0.709)."""
    gains = (0.976, 1.004)
    rec = record(9204, duration=1200.0, tau=7.31, ratio=2.32, m=0.7, sheaths=(0.0, 0.59),
                 gains=gains)
    result = _with_mass_flow(rec)
    model = result.estimate.flow_model
    assert model is not None and model.kind == "power_law"
    assert "level_from_reconstruction" not in model.evidence
    assert abs(model.exponent - 0.7) < 0.05  # issue 11's bound
    assert result.gas_estimate is not None
    assert _rmse(result.gas_estimate, rec.gas) <= 1.5 * _oracle_rmse(rec, gains)


def test_the_law_is_the_same_without_a_reconstruction() -> None:
    """`dualprobe characterise --flow` without --output, --reference or --report asks for no
    gas; the level is still found again on one (the smoother's), so the same record reports
    the same law either way (before, m 0.694 there against 0.660 with --output)."""
    kw = dict(STEEP[0][1])
    rec = record(STEEP[0][0], duration=1200.0, **kw)
    with_gas = _with_mass_flow(rec).estimate.flow_model
    without = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, flow=rec.mass_flow,
                                  flow_column="mdot", reconstruction=None).estimate.flow_model
    assert with_gas is not None and without is not None
    assert without.evidence.get("level_from_reconstruction") == 1.0
    assert without.exponent == with_gas.exponent
