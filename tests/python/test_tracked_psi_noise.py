"""A tracked schedule that follows the noise is flagged (issue 11: never "explains the data"
beside a wrong answer).

Without a flow column the tracked common factor psi can absorb what the first-order model
lacks: a 0.32 s sheath on the slow sensor of a 2 Hz pair (shorter than a row) made the tracking
choose a penalty 30 times weaker than on the same pair without it, and psi followed the noise
(its log correlated 0.41 with the truth, per-row time constants 28 % RMS off, the gas 3.3x the
oracle) while the misfit stayed at the noise. The check tracks the even and the odd rows apart
(tracking.split_noise): their difference is noise only. Recordings from the project's
drive-cycle simulator (dualprobe.simulate), written apart from the check.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dualprobe import simulate as sim
from dualprobe.estimation import tracking
from dualprobe.workflows.characterise import characterise_arrays
from dualprobe.workflows.checks import PSI_NOISE_LIMIT


def _pair(sheath2: float) -> sim.FieldRecording:
    # 20 min at 2 Hz, 0.141 K noise, elements 7.4 / 23.7 s following the velocity with
    # m = 0.37 (the sheath with them), gains 0.972 / 0.992 (field_sweep.py 13 8 noflow wide)
    rng = np.random.default_rng(6305)
    conditions = sim.drive_cycle(1200.0, rng)
    s1 = sim.FieldSensor(7.4, 0.37, 0.0, gain=0.972, noise_std=0.141)
    s2 = sim.FieldSensor(7.4 * 3.2, 0.37, sheath2, gain=0.992, noise_std=0.141)
    return sim.simulate_field_pair(conditions, s1, s2, sample_rate=2.0, quantisation=0.0,
                                   rng=rng)


def _characterise(rec: sim.FieldRecording) -> tuple[object, float, float, list[str], bool]:
    """(result, per-row error of sensor 1's time constants (relative RMS), psi_noise, the
    model check's reasons, adequate)."""
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    assert result.model_check is not None and result.estimate.flow_model is not None
    assert result.estimate.flow_model.kind == "tracked"
    tau1, _ = result.time_constants_per_row()
    error = float(np.sqrt(np.mean((tau1 / rec.tau1 - 1.0) ** 2)))
    noise = result.estimate.flow_model.psi_noise
    return result, error, noise, result.model_check.reasons, result.model_check.adequate


def _flagged(reasons: list[str]) -> bool:
    return any("tracked time constants are not determined" in r for r in reasons)


def test_a_tracked_schedule_that_absorbs_a_sheath_is_not_called_adequate() -> None:
    result, error, noise, reasons, adequate = _characterise(_pair(0.32))
    # the honesty property, whatever the tracker: per-row time constants more than 15 % RMS
    # off (three times the 5 % a field characterisation is held to) are never reported beside
    # "adequate" (measured: 28 % off, psi_noise 0.076, flagged; a tracker that got them right
    # would pass too)
    assert error <= 0.15 or (not adequate and _flagged(reasons)), (error, noise, reasons)
    if _flagged(reasons):
        assert noise > PSI_NOISE_LIMIT
    if reasons and all("tracked time constants are not determined" in r for r in reasons):
        # the signals are explained (measured: misfit at the noise): the summary's doubt says
        # what is wrong, not "the model does not explain both signals"
        doubts = result.reconstruction_doubts()  # type: ignore[attr-defined]
        assert any("not determined by these data" in d for d in doubts), doubts
        assert not any("does not explain" in d for d in doubts), doubts


def test_a_tracked_schedule_that_follows_the_flow_is_not_flagged() -> None:
    # the same pair without the sheath: tracked 7.6 % RMS off in log, psi_noise 0.024 (a lower
    # bound on that error: noise only), not flagged
    rec = _pair(0.0)
    result, error, noise, reasons, _ = _characterise(rec)
    assert error < 0.1
    assert not _flagged(reasons), reasons
    # psi moves little from knot to knot here: the knots stay every tf/2 (not refined)
    model = result.estimate.flow_model  # type: ignore[attr-defined]
    assert model.tracking is not None and model.tracking.spacing_of_tf == 0.5
    assert 0.0 < noise < PSI_NOISE_LIMIT
    tau1, _ = result.time_constants_per_row()  # type: ignore[attr-defined]
    log_error = np.log(tau1 / rec.tau1)
    assert noise <= float(np.sqrt(np.mean((log_error - log_error.mean()) ** 2)))


def test_a_tracked_schedule_whose_noise_check_fails_is_not_called_adequate(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # the split itself can fail (a half untrackable or its psi not positive: measured on two
    # 5 Hz pairs with knots every tf/4, whose halves run at 2.5 Hz); psi_noise is then NaN, and
    # an unchecked schedule is not "explains the data" (the failure stood in for here, on the
    # well-tracked pair above, which the check passes as it is)
    monkeypatch.setattr(tracking, "split_noise", lambda *args, **kwargs: math.nan)
    result, _, noise, reasons, adequate = _characterise(_pair(0.0))
    assert math.isnan(noise)
    assert not adequate
    assert any("could not be checked against the noise" in r for r in reasons), reasons
    assert result.model_check.fits  # type: ignore[attr-defined]
    doubts = result.reconstruction_doubts()  # type: ignore[attr-defined]
    assert any("not shown to be" in d for d in doubts), doubts
    assert not any("does not explain" in d for d in doubts), doubts


def test_the_noise_check_holds_on_a_quantised_pair_logged_near_the_filter_rate() -> None:
    # 2 Hz with 0.02 K ADC steps (the separate generator, tests/python/field_independent.py):
    # the filter's tf (1.2 s) puts the halves' knots at every row (1 Hz), and where both
    # sensors read the same step, T2 - T1 = 0 leaves a knot column exactly zero; its infinite
    # scale failed both halves, so psi_noise was unknown and the summary warned on a pair it
    # tracks well (measured: 1.77x the oracle, psi_noise then 0.033, time constants 8.7 % RMS)
    import field_independent as fi

    rec = fi.record(9003, rate=2.0, tau=6.0, ratio=3.0)
    assert np.any(rec.t1[::2] == rec.t2[::2])  # the case: equal readings at knots
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    assert result.model_check is not None and result.estimate.flow_model is not None
    assert result.estimate.flow_model.kind == "tracked"
    noise = result.estimate.flow_model.psi_noise
    assert 0.0 < noise < PSI_NOISE_LIMIT, noise
    assert result.model_check.adequate, result.model_check.reasons
    tau1, tau2 = result.time_constants_per_row()
    ratios = np.concatenate([tau1 / rec.tau1, tau2 / rec.tau2])
    error = float(np.sqrt(np.mean((ratios - 1.0) ** 2)))
    # checked, so it must be right: within twice the 5 % the issue holds a flow law to
    assert error < 0.1, error
