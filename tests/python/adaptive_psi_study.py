"""A freer tracked psi, kept where the data repeat it: a study of the no-flow schedule, not a test.

    python tests/python/adaptive_psi_study.py [CASE ...]

The tracking's penalty is chosen for the whole record (the discrepancy principle,
estimation/tracking.py), so a stretch whose psi barely moves the record's misfit (the readings
nearly coincide while gas and flow move together, a cruise's wobble) is smoothed there. This
study tracks psi again at a tenth of the chosen penalty, on the whole record and on its even
and odd rows apart (the same gas and flow, independent noise), and per 30 s window (half
overlapping) keeps the share k = s / (s + n) of the freer psi's departure from the tracked
one, with s the product of the halves' departures (what they repeat: signal) and n a quarter
of their squared difference (the whole record's noise in it); windows interpolated between
centres. Where a freer psi is not positive everywhere, nothing is kept. Each schedule is
judged by the product's own fit and reconstruction given it as a flow column (`tracked` is the
product's schedule so given, which reproduces its gas), against the oracle (field_oracle.py).

Cases: u0-u7 unsheathed pairs of the separate generator (field_independent.py, seeds
7700-7707: fast element 3-8 s, ratio 2-4, m 0.3-0.7, 5-20 Hz); b9002 case 9002's unsheathed
world of tests/python/common_lag_study.py; s5302 pair 5302 of field_sweep_independent.py;
p204, p206, p803, p805 unsheathed pairs of field_sweep.py 1 8 / 7 12 (the project's generator).
Measured (README, 2026-12-03): see there.
"""

from __future__ import annotations

import math
import sys

import numpy as np

import dualprobe.estimation.tracking as tracking
import field_independent as fi
from common_lag_study import CASES, _oracle
from dualprobe.estimation.field import effective_rows, fit_of
from dualprobe.io import EstimationError
from dualprobe.workflows.characterise import characterise_arrays
from field_oracle import oracle
from test_field_conditions import Case, _oracle_rmse, _record

_FREER = 0.1  # of the chosen penalty
_WINDOW = 30.0  # s
_PROJECT = {204: Case(0.51, 2.23, (0.0, 0.0), (1.002, 0.998), 204),
            206: Case(0.5, 3.51, (0.0, 0.0), (1.018, 0.981), 206),
            803: Case(0.32, 2.07, (0.0, 0.0), (1.0, 1.0), 803),
            805: Case(0.36, 2.54, (0.0, 0.0), (1.0, 1.0), 805)}


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(np.square(x))))


def _pair(label: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, float]:
    """(t, t1, t2, ts, gas, oracle's RMSE) of a case label."""
    kind, number = label[0], int(label[1:])
    if kind == "p":
        case = _PROJECT[number]
        rec = _record(case)
        return rec.t, rec.t1, rec.t2, rec.ts, case.gains[0] * rec.tg, _oracle_rmse(rec, case)
    if kind == "b":
        tau, ratio, m, rate, sheaths, gains = CASES[number]
        r = fi.record(number, tau=tau, ratio=ratio, m=m, rate=rate, sheaths=sheaths,
                      gains=gains, common=min(sheaths))
        return r.t, r.t1, r.t2, r.ts, r.gas, _oracle(r, gains)
    if kind == "s":  # pair 5302's draws (field_sweep_independent.py 53 8)
        r = fi.record(5302, tau=6.52, ratio=2.16, m=0.62, rate=10.0, sheaths=(0.25, 0.21))
    else:
        rng = np.random.default_rng(7700 + number)
        tau, ratio = round(float(rng.uniform(3, 8)), 2), round(float(rng.uniform(2, 4)), 2)
        m, rate = round(float(rng.uniform(0.3, 0.7)), 2), float(rng.choice([5.0, 10.0, 20.0]))
        r = fi.record(7700 + number, tau=tau, ratio=ratio, m=m, rate=rate)
    stages = [s if np.any(s > 0) else None for s in (r.sheath1, r.sheath2)]
    best = oracle(r.t, r.t1, r.t2, r.gas, r.tau1, r.tau2, (r.noise, r.noise),
                  sheath1=stages[0], sheath2=stages[1], gases=("rw",)).rmse
    return r.t, r.t1, r.t2, r.ts, r.gas, best


def _at_penalty_share(share: float) -> None:
    """Make tracking.choose_penalty return its choice times ``share`` (1: unchanged)."""
    original = getattr(tracking, "_study_original", tracking.choose_penalty)
    tracking._study_original = original  # type: ignore[attr-defined]

    def choose(system, rows, **kw):  # type: ignore[no-untyped-def]
        chosen, freest, stiffest = original(system, rows, **kw)
        if share != 1.0:
            chosen = tracking.solve_penalised(system, max(chosen.penalty * share, 1e-3))
        return chosen, freest, stiffest

    tracking.choose_penalty = choose  # type: ignore[assignment]


def _centred_log(psi: np.ndarray, rows: np.ndarray, n: int) -> np.ndarray | None:
    if not np.all(psi > 0.0):
        return None
    out = np.interp(np.arange(n), rows[: psi.size], np.log(psi))
    return out - float(np.mean(out))


def study(label: str) -> None:
    t, t1, t2, ts, gas, best = _pair(label)
    ours = characterise_arrays(t1, t2, ts, time=t, reconstruction="smoother")
    assert ours.gas_estimate is not None
    model = ours.estimate.flow_model
    if model is None or model.kind != "tracked" or model.tracking is None or model.sheathed_path:
        print(f"{label}: not a first-order tracked schedule", flush=True)
        return
    fit, track = fit_of(ours.estimate), model.tracking
    kw = {"tf": fit.tf, "order": 1, "sigma": fit.sigma, "static": track.static,
          "spacing_of_tf": track.spacing_of_tf}
    rows = effective_rows(ours.estimate)
    n = t1.size
    _at_penalty_share(_FREER)
    try:
        full = tracking.track(t1, t2, ts, effective_rows=rows, **kw)
        halves = [tracking.track(t1[k::2], t2[k::2], 2.0 * ts, effective_rows=0.5 * rows, **kw)
                  for k in (0, 1)]
    finally:
        _at_penalty_share(1.0)
    tracked = np.log(model.psi) - float(np.mean(np.log(model.psi)))
    freer = _centred_log(full.psi, np.arange(n), n)
    even = _centred_log(halves[0].psi, np.arange(0, n, 2), n)
    odd = _centred_log(halves[1].psi, np.arange(1, n, 2), n)
    schedules = {"tracked": tracked}
    kept = math.nan
    if freer is not None and even is not None and odd is not None:
        de, do = even - tracked, odd - tracked
        width = max(2, round(_WINDOW / ts))
        centres, shares = [], []
        for start in range(0, n, width // 2):
            part = slice(start, min(n, start + width))
            signal = max(float(np.mean(de[part] * do[part])), 0.0)
            noise = float(np.mean((de[part] - do[part]) ** 2)) / 4.0
            centres.append(0.5 * (start + min(n, start + width) - 1))
            shares.append(signal / (signal + noise) if signal + noise > 0.0 else 0.0)
        share = np.interp(np.arange(n), centres, shares)
        kept = float(np.mean(share))
        schedules["freer"] = freer
        schedules["adaptive"] = tracked + share * (freer - tracked)
    found = {}
    for name, log_psi in schedules.items():
        try:
            result = characterise_arrays(t1, t2, ts, time=t, reconstruction="smoother",
                                         flow=np.exp(log_psi), flow_column="psi", order=1)
        except EstimationError as exc:
            found[name] = f"refused ({str(exc)[:50]})"
            continue
        assert result.gas_estimate is not None
        found[name] = f"{_rms(result.gas_estimate - gas) / best:.2f}x"
    print(f"{label}: ours {_rms(ours.gas_estimate - gas) / best:.2f}x the oracle "
          f"({best:.3f} K); given as a flow: " + ", ".join(f"{k} {v}" for k, v in found.items())
          + f"; mean share kept {kept:.2f}", flush=True)


if __name__ == "__main__":
    for name in sys.argv[1:] or [f"u{k}" for k in range(8)] + ["b9002", "s5302", "p204",
                                                                "p206", "p803", "p805"]:
        study(name)
