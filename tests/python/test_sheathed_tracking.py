"""Sheathed pairs without a flow signal (issue 11): the joint cross-relation fit
(dualprobe.estimation.crossfit), psi refined by the joint MAP (dualprobe.estimation.psi_map),
against the oracle that knows the true time-varying sensors (tests/python/field_oracle.py)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from dualprobe import simulate as sim
from dualprobe.estimation import crossfit, map_schedule, sheathed
from dualprobe.estimation.damping import damped_search
from dualprobe.estimation.psi_map import map_psi
from dualprobe.io import EstimationError
from dualprobe.workflows.characterisation import SHEATHED_STD_NOTE
from dualprobe.workflows.characterise import characterise_arrays
from field_oracle import oracle
from test_field_conditions import ADC, NOISE, Case, _oracle_rmse, _record, _rmse

SHEATHED = [
    Case(0.32, 3.28, (0.7, 0.0), (1.0, 1.0), 205),  # sheath on the fast sensor: 1.32x measured
    Case(0.58, 2.78, (0.19, 0.61), (1.023, 1.026), 104),  # both sheathed, gains: 2.30x measured
]


@pytest.mark.parametrize("case", SHEATHED, ids=["fast-sheathed", "both-sheathed-gains"])
def test_without_flow_sheathed_pairs_reach_2_5x_the_oracle(case: Case) -> None:
    """Before the sheathed path these were refused (exit 3) or warned at 5-12x."""
    rec = _record(case)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert result.gas_estimate is not None
    ours = _rmse(result.gas_estimate, case.gains[0] * rec.tg)  # the gas as sensor 1 reads it
    assert ours <= 2.5 * _oracle_rmse(rec, case), ours  # the bound without flow
    # never "ok": a misfit is warned (fast-sheathed: 5.8 times the noise), and where the
    # signals are explained (both-sheathed-gains) the schedule's bias is still not measurable
    # (1.3-3x the oracle on pairs whose residuals and even/odd splits look alike)
    check = result.model_check
    assert check is not None and not check.adequate
    assert not check.fits or any("without a flow signal" in reason and "--flow" in reason
                                 for reason in check.reasons), check.reasons
    assert "model check: the model explains" not in result.summary()
    assert 0.0 < model.psi_noise < 0.05  # the MAP psi's noise part, measured
    # T_g_std carries the sheathed path's measured schedule error (settings.py): the gas error
    # below the bandwidth over T_g_std had an RMS of 0.75 / 2.73 with psi_noise alone, 0.46 /
    # 0.98 with it (fast-sheathed / both-sheathed-gains); an honest band gives 1, and the
    # bounds are those of the unsheathed tracked pairs' check (test_field_independent.py)
    assert result.gas_std is not None and result.bandwidth is not None
    error = result.gas_estimate - case.gains[0] * rec.tg
    below = sosfiltfilt(butter(4, result.bandwidth.hz, fs=1.0 / rec.ts, output="sos"), error)
    z = below / result.gas_std
    assert 0.4 <= float(np.sqrt(np.mean(z * z))) <= 1.5
    assert float(np.mean(np.abs(z) < 2.0)) >= 0.90
    assert SHEATHED_STD_NOTE in result.summary()
    # the sheath found where there is one (within 20 %: 0.645-0.758 s measured for 0.7 s;
    # 0.14 for 0.19 s is weakly seen behind a 5 s element, so only the larger is checked)
    psi = 1.0 / rec.tau1
    psi /= np.exp(np.mean(np.log(psi)))
    for i, sheath in enumerate((rec.sheath1, rec.sheath2)):
        taus = result.estimate.time_constants[i]
        truth = float(np.median(sheath * psi))
        if truth >= 0.5:
            assert len(taus) == 2 and taus[1] == pytest.approx(truth, rel=0.2), (taus, truth)


def test_map_psi_given_the_true_stages_reaches_the_oracle() -> None:
    """Given the true stage time constants, the MAP schedule is good enough for the oracle's
    own smoother to come within 1.5x of what the true schedule gives (1.23x measured; psi's
    error is where the gas does not move, where it does not matter)."""
    case = SHEATHED[1]
    rec = _record(case)
    target = case.gains[0] * rec.tg
    psi_true = 1.0 / rec.tau1
    psi_true /= np.exp(np.mean(np.log(psi_true)))
    stages = [[float(np.median(s * psi_true)), float(np.median(e * psi_true))]
              for s, e in ((rec.sheath1, rec.tau1), (rec.sheath2, rec.tau2))]
    sheathed = [None if np.all(s == 0) else s for s in (rec.sheath1, rec.sheath2)]
    best = oracle(rec.t, rec.t1, rec.t2, target, rec.tau1, rec.tau2, (NOISE, NOISE),
                  sheath1=sheathed[0], sheath2=sheathed[1], static1=(1.0, 0.0),
                  static2=(case.gains[1] / case.gains[0], 0.0), gases=("rw",))
    found = map_psi(rec.t, rec.t1, rec.t2, stages[0], stages[1], (1.0, 0.0), (NOISE, NOISE),
                    best.q, 10, 0.05)
    assert found.static[0] == pytest.approx(case.gains[1] / case.gains[0], abs=1e-3)
    ours = oracle(rec.t, rec.t1, rec.t2, target, stages[0][1] / found.psi,
                  stages[1][1] / found.psi, (NOISE, NOISE), sheath1=stages[0][0] / found.psi,
                  sheath2=stages[1][0] / found.psi, static1=(1.0, 0.0), static2=found.static,
                  gases=("rw",))
    assert ours.rmse <= 1.5 * best.rmse, (ours.rmse, best.rmse)


def test_damped_search_grows_the_damping_until_the_cost_falls() -> None:
    """The shared Levenberg search: an unsolvable system (None) or a higher cost grows the
    damping tenfold; the first lower cost is taken with the damping that gave it."""
    tried: list[float] = []

    def attempt(damping: float) -> tuple[str, float] | None:
        tried.append(damping)
        if damping < 1e-2:
            return None
        return ("state", 5.0 if damping < 1.0 else 2.0)

    state, cost, damping = damped_search(attempt, 3.0, 1e-3, 10)
    assert (state, cost, damping) == ("state", 2.0, pytest.approx(1.0))
    assert tried == pytest.approx([1e-3, 1e-2, 1e-1, 1.0])
    state, cost, damping = damped_search(attempt, 1.0, 1e-3, 3)  # never below 1.0
    assert state is None and cost == 1.0 and damping == pytest.approx(1.0)


def _sheathed_record(rate: float, duration: float) -> sim.FieldRecording:
    """Sheaths 0.75 / 0.32 s on elements of 2.9 / 10.7 s (m 0.42), the project's simulator."""
    rng = np.random.default_rng(8801)
    conditions = sim.drive_cycle(duration, rng)
    s1 = sim.FieldSensor(2.91, 0.42, 0.75, noise_std=NOISE)
    s2 = sim.FieldSensor(2.91 * 3.68, 0.42, 0.32, noise_std=NOISE)
    return sim.simulate_field_pair(conditions, s1, s2, sample_rate=rate, quantisation=ADC,
                                   rng=rng)


def _spy_on_the_cross_relation(monkeypatch: pytest.MonkeyPatch) -> list[tuple[int, float]]:
    """(rows, sample interval) of every call of the sheathed path's cross-relation fit."""
    calls: list[tuple[int, float]] = []
    fit = crossfit.fit_cross_relation

    def spy(t1: np.ndarray, t2: np.ndarray, ts: float, *args: Any, **kwargs: Any) -> Any:
        calls.append((t1.size, ts))
        return fit(t1, t2, ts, *args, **kwargs)

    monkeypatch.setattr(crossfit, "fit_cross_relation", spy)
    return calls


def test_a_record_over_the_row_limit_takes_the_sheathed_path_on_block_means(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A record over the sheathed path's row limit (60,000: 20 min at 50 Hz) runs it on means
    of blocks of rows, the fewest that fit, instead of skipping it. Here at a tenth of the
    scale: a 20 Hz, 10 min record under a limit of 6,000 rows, so blocks of 2 rows (10 Hz).
    Measured: 1.35x the oracle (1.51x on all the rows; skipped, the pair was refused: "the
    fitted dynamics oscillate"); at full scale (25 min at 50 Hz, blocks of 2) three pairs went
    from refused, 14.4x and 12.6x to 1.87x, 5.27x and 5.87x."""
    monkeypatch.setattr(map_schedule, "SHEATHED_MAX_ROWS", 6000)
    calls = _spy_on_the_cross_relation(monkeypatch)
    rec = _sheathed_record(20.0, 600.0)
    result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    # once, with the engine's filter, on the block means: its result explains the data, so the
    # finer filter's try could not be taken and is skipped (sheathed.track)
    assert calls == [(6000, pytest.approx(0.1))]
    model = result.estimate.flow_model
    assert model is not None and model.kind == "tracked"
    assert model.evidence.get("sheathed_path") == 1.0
    assert model.evidence.get("sheathed_block_rows") == 2.0
    assert model.psi.size == rec.t.size  # the blocks' schedule on every row
    assert [len(taus) for taus in result.estimate.time_constants] == [2, 2]
    assert result.gas_estimate is not None
    best = oracle(rec.t, rec.t1, rec.t2, rec.tg, rec.tau1, rec.tau2, (NOISE, NOISE),
                  sheath1=rec.sheath1, sheath2=rec.sheath2, gases=("rw",)).rmse
    ours = _rmse(result.gas_estimate, rec.tg)
    assert ours <= 2.5 * best, (ours, best)  # the bound without flow


def test_block_means_slower_than_10_hz_are_not_used(monkeypatch: pytest.MonkeyPatch) -> None:
    """Blocks of 2 rows of a 10 Hz record would be 5 Hz, too slow for sheaths of 0.1-0.8 s:
    such a record over the limit keeps what the first-order tracking gave, as before (this
    pair is then refused: its first-order fit oscillates; within the limit it is tracked)."""
    monkeypatch.setattr(map_schedule, "SHEATHED_MAX_ROWS", 5000)
    calls = _spy_on_the_cross_relation(monkeypatch)
    rec = _sheathed_record(10.0, 600.0)
    assert rec.t.size > 5000
    with pytest.raises(EstimationError, match="oscillate"):
        characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction=None)
    assert calls == []


def test_block_means_are_the_fewest_blocks_within_the_limit() -> None:
    t1 = np.arange(13.0)
    a, b, size = map_schedule.block_means(t1, -t1, 0.01)
    assert (a.size, size) == (13, 1) and a is t1
    limit = map_schedule.SHEATHED_MAX_ROWS
    rows = 2 * limit + 3  # needs blocks of 3; the last 2 rows fall off
    t1 = np.arange(float(rows))
    a, b, size = map_schedule.block_means(t1, 2.0 * t1, 0.01)
    assert size == 3 and a.size == rows // 3 <= limit
    assert a[0] == 1.0 and a[-1] == float(3 * (rows // 3) - 2)
    np.testing.assert_array_equal(b, 2.0 * a)


def test_the_cross_relation_fits_normal_equations_solve_as_the_dense_system() -> None:
    """The Levenberg step of crossfit solves its normal equations by their structure (banded
    knot block, six dense unknowns, the rank-one mean penalty); checked against scipy's dense
    symmetric solve of the assembled matrix on a drive cycle's actual Jacobian, at the
    dampings the search tries. Agreement to 1e-9: both are backward stable, the matrix's
    condition number sets what they may differ by (measured 4e-12 to 2e-15)."""
    import scipy.linalg
    import scipy.sparse as sp

    from dualprobe.estimation import crossfit

    rec = _sheathed_record(10.0, 300.0)
    ts, tf = rec.ts, 2.0
    cols = crossfit._Columns(rec.t1, rec.t2, ts, tf, round(0.5 * tf / ts))
    k = cols.knots
    rng = np.random.default_rng(0)
    p = np.concatenate([[1.0, 0.1, 2.0, 6.0, 0.3, 0.5], 0.2 * rng.standard_normal(k)])
    weights = np.ones(rec.t1.size)
    weights[:400] = 0.0
    walk = sp.diags([np.ones(k - 1), -np.ones(k - 1)], [0, 1], shape=(k - 1, k))
    rough = (walk.T @ walk).tocsc()
    mean, stiff, penalty = np.full(k, 1.0 / k), 1e6, 300.0
    _, psi, phi = cols.residual(p)
    dense, knots = cols.jacobian(p, psi, phi)
    wd = dense * weights[:, None]
    h = np.block([[dense.T @ wd, np.asarray(knots.T @ wd).T],
                  [np.asarray(knots.T @ wd), (knots.T @ sp.diags(weights) @ knots).toarray()
                   + penalty * rough.toarray() + stiff * np.outer(mean, mean)]])
    diag = np.maximum(np.diag(h), 1e-12)
    grad = rng.standard_normal(6 + k) * np.sqrt(diag)
    normal = crossfit._Normal(dense, knots, weights, rough, penalty, mean, stiff, cols.layout)
    np.testing.assert_allclose(normal.diag, diag, rtol=1e-12)
    assert normal.band.shape[0] < k // 4  # banded indeed: the point of the structure
    for damp in (1e-9, 1e-3, 1.0):
        expected = scipy.linalg.solve(h + damp * np.diag(diag), grad, assume_a="sym")
        np.testing.assert_allclose(normal.solve(damp, grad), expected, rtol=0,
                                   atol=1e-9 * np.linalg.norm(expected))


def test_the_knot_gram_from_windows_is_the_sparse_product() -> None:
    """crossfit's knot block K' W K, computed from the knot columns as dense windows (one
    row-wise dot per diagonal), is the sparse product's lower band, the record's first and
    last knots (windows reaching outside the record) included, with weights that vary by
    row. Both sum the same products, so they agree to rounding (1e-13 of the largest entry)."""
    import scipy.sparse as sp

    from dualprobe.estimation import crossfit
    from dualprobe.estimation.banded import lower_band

    rec = _sheathed_record(10.0, 300.0)
    ts, tf = rec.ts, 2.0
    cols = crossfit._Columns(rec.t1, rec.t2, ts, tf, round(0.5 * tf / ts))
    rng = np.random.default_rng(3)
    weights = rng.uniform(0.0, 2.0, rec.t1.size)
    weights[:400] = 0.0
    knots = (0.9 * cols.k2 - cols.k1 + 0.3 * cols.y1).tocsc()
    expected = lower_band((knots.T @ sp.diags(weights) @ knots).tocsc())
    band = crossfit._gram_band(knots, weights, cols.layout)
    rows = max(band.shape[0], expected.shape[0])
    padded = [np.vstack([b, np.zeros((rows - b.shape[0], b.shape[1]))]) for b in (band, expected)]
    np.testing.assert_allclose(padded[0], padded[1], rtol=0,
                               atol=1e-13 * np.max(np.abs(expected)))
    assert band.shape[0] < cols.knots // 4  # banded: the windows overlap few neighbours


def _short_one_sheath_record() -> sim.FieldRecording:
    """90 s at 50 Hz, one sheath (found 2026-12-03 by short random drive cycles)."""
    rng = np.random.default_rng(1)
    conditions = sim.drive_cycle(90.0, rng)
    return sim.simulate_field_pair(conditions, sim.FieldSensor(5.6, 0.5, 0.0, noise_std=NOISE),
                                   sim.FieldSensor(18.9, 0.5, 0.5, noise_std=NOISE),
                                   sample_rate=50.0, quantisation=ADC, rng=rng)


def test_a_cross_relation_without_a_positive_element_leaves_the_sheathed_path(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # With the engine's filter the cross-relation's elements came out at -0.28 and -4.7 s,
    # which left sensor 1 no stage at all and the MAP an empty chain (IndexError, a traceback
    # from characterise). That try now leaves the sheathed path; with the finer filter's try
    # made the same one, the first-order result misfits 4e4 times the noise with a time
    # constant the data do not determine, which is refused (exit 3) with the reason.
    monkeypatch.setattr(sheathed, "_FINER_FILTER", 1.0)
    rec = _short_one_sheath_record()
    with pytest.raises(EstimationError, match="the data do not determine it"):
        characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")


def test_the_finer_filter_s_sheathed_result_on_that_record_is_refused_as_implausible(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The same record as it runs: the engine's filter's cross-relation has no positive
    element, the finer filter's (sheathed.track) has, and its schedule is kept
    over the first-order one. It puts the slow sensor's time constant past a third of the
    90 s record (39 s, 3.5 times its median, measured), which is refused with that reason."""
    elements: list[bool] = []
    fit = crossfit.fit_cross_relation

    def spy(*args: Any, **kwargs: Any) -> Any:
        found = fit(*args, **kwargs)
        elements.append(all(pair[0] > 0.0 for pair in found.stages))
        return found

    monkeypatch.setattr(crossfit, "fit_cross_relation", spy)
    rec = _short_one_sheath_record()
    with pytest.raises(EstimationError, match="longer than a third of the record"):
        characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t, reconstruction="smoother")
    # each time the path runs (the searched static map, then unit gains): the engine's
    # filter's try, then the finer one's
    assert elements == [False, True] * (len(elements) // 2) and elements
