"""Where the order chosen by evidence drops an order-2 fit whose second stage moves with the
filter setting (workflows/checks.unsettled_stages): the gas of the first order it gives and of
the order-2 fit it dropped, against the oracle. A study, not a test.

    python tests/python/settling_study.py SEED COUNT

Draws as logger_sweep.py (sheaths on half the pairs, loggers' effects), with the mass flow.
"""

from __future__ import annotations

import sys

import numpy as np

from dualprobe.io import EstimationError
from dualprobe.workflows.characterise import characterise_arrays
from logger_sweep import drawn


def study(seed: int, count: int) -> None:
    for case, draw, rec, best in drawn(seed, count, False):
        label = f"{case}: " + " ".join(f"{key} {value}" for key, value in draw.items())
        line = []
        for order in ("auto", 2):
            try:
                result = characterise_arrays(rec.t1, rec.t2, rec.ts, time=rec.t,
                                             flow=rec.mass_flow, flow_column="mdot",
                                             order=order)
            except EstimationError as exc:
                line.append(f"{order}: REFUSED {str(exc)[:60]}")
                continue
            assert result.gas_estimate is not None and result.model_check is not None
            ours = float(np.sqrt(np.mean((result.gas_estimate - rec.gas) ** 2)))
            check = result.model_check
            why = str(result.estimate.identifiability.get("order_fallback", ""))
            conf = result.estimate.confidence
            moved = ({name: round(conf.settings_std.get(name, 0.0) / value, 3)
                      for name, value in conf.values.items() if name.endswith("_1")}
                     if conf is not None else {})
            taus = [[round(x, 3) for x in sensor] for sensor in result.estimate.time_constants]
            line.append(f"{order}: {ours / best:.2f}x taus {taus}"
                        f" mu {check.estimation_misfit:.3g} stat {check.estimation_statistic:.3g}"
                        f" adequate {check.adequate} moved {moved}"
                        + (" UNSETTLED" if "filter time constant" in why else ""))
            if order == "auto" and "filter time constant" not in why:
                break
        print(label, "|", " | ".join(line), flush=True)


if __name__ == "__main__":
    study(int(sys.argv[1]), int(sys.argv[2]))
