"""The paper's difference-equation method (design.md 1.2, Hung et al. 2005) for
``characterise_pair(method="ls" | "tls" | "gtls")``, computed by the C++ core."""

from __future__ import annotations

import numpy as np

from dualprobe import _core
from dualprobe.estimation.result import PairEstimate

__all__ = ["characterise_difference"]


def characterise_difference(
    t1: np.ndarray, t2: np.ndarray, ts: float, method: str, sigma: tuple[float, float],
    sigma_source: str,
) -> PairEstimate:
    """First-order time constants by the difference equation; ``method`` ls | tls | gtls (GTLS
    falls back to TLS, its limit, when a noise level is 0)."""
    solver = method
    if method == "gtls" and not (sigma[0] > 0.0 and sigma[1] > 0.0):
        solver = "tls"  # noise-free data: GTLS needs a noise model, TLS is its limit
    raw = _core.estimate_difference(t1, t2, ts, solver, sigma[0], sigma[1], 1.0)
    result = {key: raw[key] for key in ("status", "beta", "tau1", "tau2")}
    engine = "core"
    status = str(result["status"])
    details: dict[str, object] = {"noise_std_source": sigma_source, "engine": engine,
                                  "solver": solver}
    taus = ((float(result["tau1"]),), (float(result["tau2"]),))
    if status != "ok":
        details["message"] = {
            "insufficient_excitation": "the differenced signals do not determine the time "
            "constants",
            "infeasible": "no feasible first-order pair fits (beta <= 0 or b outside (0, 1))",
        }.get(status, status.replace("_", " "))
    return PairEstimate(
        status=status, method=method, order=1, sample_interval=ts, time_constants=taus,
        beta=float(result["beta"]) if status == "ok" else None, noise_std=sigma,
        identifiability={}, details=details,
    )
