"""A freer tracked psi, kept where the data repeat it: a study of the no-flow schedule, not a test.

    python tests/python/adaptive_psi_study.py [CASE ...]

The tracking's penalty is chosen for the whole record (the discrepancy principle,
estimation/tracking.py), so a stretch whose psi barely moves the record's misfit (the readings
nearly coincide while gas and flow move together, a cruise's wobble) is smoothed there. The
product frees it where the data repeat a freer psi (estimation/adaptive.py: tracked again at a
tenth of the penalty on the whole record and on its even and odd rows apart, the share of the
freer psi's departure that both halves repeat kept per 30 s window). This study runs the
product with and without that step on each case and prints both gases' errors against the
oracle (field_oracle.py), the share kept, psi_noise and the model check's verdict.

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

import field_independent as fi
from common_lag_study import CASES, _oracle
from dualprobe.estimation import without_flow
from dualprobe.io import EstimationError
from dualprobe.workflows.characterise import Characterisation, characterise_arrays
from field_oracle import oracle
from test_field_conditions import Case, _oracle_rmse, _record

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


def _characterised(t: np.ndarray, t1: np.ndarray, t2: np.ndarray, ts: float,
                   adapted: bool) -> Characterisation:
    """The product's characterisation, with the adaptation or with it left out."""
    original = without_flow._adapted
    if not adapted:
        without_flow._adapted = lambda t1, t2, chosen, run: chosen  # type: ignore[assignment]
    try:
        return characterise_arrays(t1, t2, ts, time=t, reconstruction="smoother")
    finally:
        without_flow._adapted = original  # type: ignore[assignment]


def study(label: str) -> None:
    t, t1, t2, ts, gas, best = _pair(label)
    parts = []
    for adapted in (False, True):
        try:
            result = _characterised(t, t1, t2, ts, adapted)
        except EstimationError as exc:
            parts.append(f"refused ({str(exc)[:50]})")
            continue
        assert result.gas_estimate is not None and result.model_check is not None
        model = result.estimate.flow_model
        evidence = model.evidence if model is not None else {}
        parts.append(f"{_rms(result.gas_estimate - gas) / best:.2f}x, share "
                     f"{evidence.get('adaptive_share', 0.0):.2f}, psi_noise "
                     f"{evidence.get('psi_noise', math.nan):.3f}, adequate "
                     f"{result.model_check.adequate}")
    print(f"{label} (oracle {best:.3f} K): without the adaptation {parts[0]}; with it "
          f"{parts[1]}", flush=True)


if __name__ == "__main__":
    for name in sys.argv[1:] or [f"u{k}" for k in range(8)] + ["b9002", "s5302", "p204",
                                                                "p206", "p803", "p805"]:
        study(name)
