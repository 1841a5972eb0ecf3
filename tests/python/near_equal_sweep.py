"""Near-equal sheaths with the mass flow on the SEPARATE generator (field_independent.py): a
study, not a test.

    python tests/python/near_equal_sweep.py SEED COUNT [velocity]

(``velocity``: the gas velocity, mass flow x gas, as the column instead of the mass flow.)

Each case draws a sheath of 0.2-0.8 s and the other within 15 % of it, a fast element of
3-8 s, a ratio of 2-4, m 0.3-0.7 (10 Hz, 20 min, the generator's noise). Near-equal sheaths
nearly cancel from the cross-relation: only the flow law's shape fixes their common part
(README, "Near-equal sheaths with the flow"). Each line: the gas RMSE over the oracle's (which
knows the sheaths), the time constants found, the flow-regime split statistic and the check.
"""

from __future__ import annotations

import math
import sys

import numpy as np

import field_independent as fi
from dualprobe.io import EstimationError
from dualprobe.workflows.characterise import characterise_arrays
from field_oracle import oracle


def sweep(seed: int, count: int, velocity: bool = False) -> None:
    rng = np.random.default_rng(seed)
    for k in range(count):
        s, u = float(rng.uniform(0.2, 0.8)), float(rng.uniform(-0.15, 0.15))
        sheaths = (round(s, 2), round(s * (1 + u), 2))
        tau, ratio = round(float(rng.uniform(3, 8)), 2), round(float(rng.uniform(2, 4)), 2)
        m = round(float(rng.uniform(0.3, 0.7)), 2)
        case = seed * 100 + k
        rec = fi.record(case, tau=tau, ratio=ratio, m=m, rate=10.0, sheaths=sheaths)
        best = oracle(rec.t, rec.t1, rec.t2, rec.gas, rec.tau1, rec.tau2,
                      (rec.noise, rec.noise), sheath1=rec.sheath1, sheath2=rec.sheath2,
                      gases=("rw",)).rmse
        label = f"{case}: sheaths {sheaths} tau {tau} ratio {ratio} m {m}"
        try:
            result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t,
                                         reconstruction="smoother",
                                         flow=rec.mass_flow * rec.gas if velocity
                                         else rec.mass_flow,
                                         flow_column="velocity" if velocity else "mdot")
        except EstimationError as exc:
            print("REFUSED", label, str(exc)[:100], flush=True)
            continue
        assert result.gas_estimate is not None and result.model_check is not None
        model = result.estimate.flow_model
        evidence = model.evidence if model is not None else {}
        ours = float(np.sqrt(np.mean((result.gas_estimate - rec.gas) ** 2)))
        taus = [[round(x, 2) for x in row] for row in result.estimate.time_constants]
        print(f"{label}: {ours / best:.2f}x time constants {taus} split "
              f"{evidence.get('flow_split_statistic', math.nan):.1f} adequate "
              f"{result.model_check.adequate}", flush=True)


if __name__ == "__main__":
    sweep(int(sys.argv[1]), int(sys.argv[2]), sys.argv[3:] == ["velocity"])
