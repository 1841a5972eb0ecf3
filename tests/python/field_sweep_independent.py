"""Random pairs of the SEPARATE generator (field_independent.py), characterised without the
flow (or with the mass flow column an ECU has: ``flow``): a study, not a test.

    python tests/python/field_sweep_independent.py SEED COUNT [flow | velocity]

Each case draws a fast element of 3-8 s, a ratio of 2-4, m 0.3-0.7, 10 or 20 Hz, sheaths of
0.2-0.8 s on both sensors (on one only with probability 0.3) and gains 0.97-1.03 on half (20
min, 0.05 K noise, 0.02 K ADC steps: the generator's defaults). Each line: "within" inside the
issue's bound of the oracle (2.5x without the flow; 1.5x and 15 % of the raw fast sensor's
error with it), "weak" beyond it, "BAD" worse than the raw fast sensor, "REFUSED"
(exit 3); "DISHONEST" marks a result beyond the bound that the model check called adequate.
"shared sheath part": the error of the gas seen through the part of the sheaths that both
sensors share, over the oracle's (field_oracle.common_part_error): what an estimate that
undoes all but that part still misses. "blame" (tracked results): the oracle given our stages
on the true schedule, and the true stages on our schedule (field_oracle.schedule_blame), over
the oracle's: near 1 in the first, our schedule is the error; in the second, our stages.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Container

import numpy as np

import field_independent as fi
from dualprobe.io import EstimationError
from dualprobe.workflows.characterise import characterise_arrays
from field_oracle import common_part_error, oracle, schedule_blame, worst_factor


def sweep(seed: int, count: int, column: str = "", only: Container[int] | None = None) -> None:
    """``column``: "" (none), "flow" (the mass flow) or "velocity" (mass flow x gas: what the
    time constants follow, eq. 1, as a velocity model would give it); ``only``: the draws
    (0 .. count-1) to run, every one where None."""
    with_flow = bool(column)
    rng = np.random.default_rng(seed)
    for k in range(count):
        tau = round(float(rng.uniform(3, 8)), 2)
        ratio = round(float(rng.uniform(2, 4)), 2)
        m = round(float(rng.uniform(0.3, 0.7)), 2)
        rate = float(rng.choice([10.0, 20.0]))
        drawn = [round(float(v), 2) for v in rng.uniform(0.2, 0.8, 2)]
        sheaths = (drawn[0], drawn[1])
        if rng.random() < 0.3:
            sheaths = (sheaths[0], 0.0) if rng.random() < 0.5 else (0.0, sheaths[1])
        drawn = ([round(float(v), 3) for v in rng.uniform(0.97, 1.03, 2)]
                 if rng.random() < 0.5 else [1.0, 1.0])
        gains = (drawn[0], drawn[1])
        case = seed * 100 + k
        if only is not None and k not in only:
            continue
        rec = fi.record(case, tau=tau, ratio=ratio, m=m, rate=rate, sheaths=sheaths,
                        gains=gains)
        target = rec.gas  # already in sensor 1's calibration
        best = oracle(rec.t, rec.t1, rec.t2, target, rec.tau1, rec.tau2,
                      (rec.noise, rec.noise), sheath1=rec.sheath1 if sheaths[0] else None,
                      sheath2=rec.sheath2 if sheaths[1] else None,
                      static2=(gains[1] / gains[0], 0.0), gases=("rw",)).rmse
        raw = float(np.sqrt(np.mean((rec.t1 - target) ** 2)))
        # what leaving the sheaths' shared part undone costs, over the oracle (which undoes it)
        common = common_part_error(rec.t, target, rec.sheath1 if all(sheaths) else None,
                                   rec.sheath2 if all(sheaths) else None) / best
        label = (f"{case}: tau {tau} ratio {ratio} m {m} {rate:g} Hz sheaths {sheaths} "
                 f"gains {gains}")
        start = time.perf_counter()
        try:
            result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t,
                                         reconstruction="smoother",
                                         flow=_column(rec, gains[0], column),
                                         flow_column=column or None)
        except EstimationError as exc:
            print("REFUSED", label, str(exc)[:100], flush=True)
            continue
        elapsed = time.perf_counter() - start  # the characterisation's, not the studies'
        assert result.gas_estimate is not None and result.model_check is not None
        ours = float(np.sqrt(np.mean((result.gas_estimate - target) ** 2)))
        model = result.estimate.flow_model
        evidence = model.evidence if model is not None else {}
        within = (ours <= 1.5 * best and ours <= 0.15 * raw) if with_flow else ours <= 2.5 * best
        verdict = "BAD" if ours > raw else ("within" if within else "weak")
        # per-row element time constants: RMS relative error and the worst row's factor
        per_row = result.time_constants_per_row()
        ratios = np.concatenate([per_row[0] / rec.tau1, per_row[1] / rec.tau2])
        tau_rms = float(np.sqrt(np.mean((ratios - 1.0) ** 2)))
        worst = worst_factor(ratios)
        adequate = result.model_check.adequate
        flag = " DISHONEST" if not within and adequate else ""
        blame = ""
        if model is not None and model.kind == "tracked":
            found = _found_static(result.estimate.details)
            stages = result.estimate.time_constants
            parts = schedule_blame(rec.t, rec.t1, rec.t2, target,
                                   (rec.tau1, rec.tau2, rec.sheath1 if sheaths[0] else None,
                                    rec.sheath2 if sheaths[1] else None),
                                   (rec.noise, rec.noise), (gains[1] / gains[0], 0.0),
                                   (stages[0], stages[1]), model.psi, found)
            blame = (f" blame: our stages on the true schedule {parts[0] / best:.2f}x, the "
                     f"true stages on ours {parts[1] / best:.2f}x")
        print(f"{verdict}{flag} {label}: {ours / best:.2f}x (oracle {best:.3f} K, raw / ours "
              f"{raw / ours:.1f}) {model.kind if model else None} m "
              f"{model.exponent if model else math.nan:.3f} sheathed path "
              f"{evidence.get('sheathed_path', 0.0):g} psi_noise "
              f"{evidence.get('psi_noise', math.nan):.3f} freed "
              f"{evidence.get('freed_share', 0.0):.2f} misfit "
              f"{evidence.get('misfit_tracked', math.nan):.2f} orders "
              f"{[len(x) for x in result.estimate.time_constants]} adequate {adequate} fits "
              f"{result.model_check.fits} tau rms {tau_rms:.3f} worst {worst:.1f}x "
              f"shared sheath part {common:.2f}x{blame} {elapsed:.0f} s",
              flush=True)


def _found_static(details: dict[str, object]) -> tuple[float, float]:
    """Sensor 2's (gain, offset) as the oracle removes them, from the estimate's affine static
    model (``T1 = g T2 + o`` in sensor 1's calibration; unit gain without one)."""
    gain, offset = details.get("gain_ratio"), details.get("offset")
    if details.get("static_model") != "affine" or not isinstance(gain, float | int) \
            or not isinstance(offset, float | int):
        return (1.0, 0.0)
    return (1.0 / gain, -offset / gain)


def _column(rec: fi.Recording, gain: float, column: str) -> np.ndarray | None:
    if column == "velocity":
        return rec.mass_flow * rec.gas / gain  # rec.gas is in sensor 1's calibration
    return rec.mass_flow if column == "flow" else None


if __name__ == "__main__":
    sweep(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3] if len(sys.argv) > 3 else "")
