"""Standard uncertainties of a pair characterisation and what the data cannot pin down.

The final model (orders, static model, hysteresis split, flow law) is refitted by the core with
the block moments kept (:func:`dualprobe.estimation.engine.fit`, ``block_length``), and every
reported quantity gets a delete-one-block jackknife (:mod:`dualprobe.estimation.uncertainty`):
each sensor's time constants (per stage, heating/cooling), the gain ratio and offset, and the
flow exponent, which is re-optimised in every replicate (the replicate's misfit on a small grid
of exponents around the estimate, a parabola through its minimum, the parameters interpolated
there). The same is done at half and at twice the filter time constant; a significant change
with the setting enters the uncertainty and flags the value.

A value is *identifiable* when its standard uncertainty is below ``RELATIVE_LIMIT`` (30 %) of
it, it does not move with the filter time constant, and the model explains the data (misfit
within ``GAP_THRESHOLD`` noise standard deviations); otherwise the reasons say which failed.
A schedule from a free curve or from tracking is taken as given here (its own uncertainty is
not propagated: stated in the reasons).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from dualprobe.estimation import engine
from dualprobe.estimation.engine import Fit
from dualprobe.estimation.field import FlowModel
from dualprobe.estimation.flow import FlowSignal
from dualprobe.estimation.result import PairEstimate
from dualprobe.estimation.settings import GAP_THRESHOLD
from dualprobe.estimation.uncertainty import (
    Jackknife,
    Layout,
    block_length,
    filter_memory,
    jackknife,
    parameters,
    settings_sensitivity,
)

__all__ = ["RELATIVE_LIMIT", "SETTING_SHARE", "Confidence", "confidence"]

RELATIVE_LIMIT = 0.3  # standard uncertainty above 30 % of the value: not identifiable
_GRID_HALF = 3  # exponent grid points either side of the estimate per replicate
_TF_VARIANTS = (0.5, 2.0)
# A value whose standard uncertainty from the filter setting alone (tf/2 .. 2 tf) exceeds this
# share of it is not determined: it depends on an arbitrary weighting of frequencies by more
# than the 5 % the per-row time constants are held to. Seen on a flow-following pair with
# near-equal sheaths (0.54 / 0.61 s) whose sheaths follow the flow with their own exponents
# (0.44, 0.52; the element 0.47): second stages 1.36 +- 0.04 and 2.66 +- 0.30 s (11 %),
# dominant 3.39 / 4.83 s for 1.54 / 3.88, the model "adequate" and a gas 17.7 K off (raw fast
# sensor 13 K); first order: 5.4 K, flagged as a misfit. Resolved stages move by 0-1 % of their
# value (sheaths of 0.1-0.8 s at 2-50 Hz, with or without their own exponents).
SETTING_SHARE = 0.05
# A smaller move is significant on long records (model error far below the noise) but does
# not matter: a 0.3 s element at 100 Hz moved by 0.1 % and was reported 'not identifiable',
# its reconstruction 'not reliable' at the oracle's accuracy (0.408 K against 0.408 K).


@dataclass(frozen=True)
class Confidence:
    """Standard uncertainties by parameter name (``tau1_0`` = sensor 1's dominant time
    constant, ``tau1_1`` its second stage, ``..._heat``/``_cool``, ``gain_ratio``, ``offset``,
    ``exponent``), the jackknife's and the setting's shares, and per-name identifiability with
    reasons in words."""

    values: dict[str, float]
    std: dict[str, float]
    jackknife_std: dict[str, float]
    settings_std: dict[str, float]
    identifiable: dict[str, bool]
    reasons: dict[str, list[str]]
    blocks: int
    block_length: int
    notes: list[str] = field(default_factory=list)


def _layout(estimate: PairEstimate, fit: Fit) -> Layout:
    orders = estimate.identifiability.get("sensor_orders")
    if isinstance(orders, (list, tuple)) and len(orders) == 2:
        pair = (int(orders[0]), int(orders[1]))
    else:
        pair = (len(estimate.time_constants[0]), len(estimate.time_constants[1]))
    return Layout(orders=pair, hysteresis=fit.hysteresis, affine=fit.static == "affine")


def _refit(t1: np.ndarray, t2: np.ndarray, like: Fit, tf: float, psi: np.ndarray | None,
           length: int) -> Fit | None:
    return engine.fit(t1, t2, like.ts, tf=tf, order=like.order, static=like.static,
                      hysteresis=like.hysteresis, sigma=like.sigma, schedule=psi,
                      windows=like.windows or None, block_length=length)


def _fixed_schedule(t1: np.ndarray, t2: np.ndarray, like: Fit, layout: Layout, tf: float,
                    psi: np.ndarray | None, length: int) -> Jackknife | None:
    fit = _refit(t1, t2, like, tf, psi, length)
    if fit is None or fit.blocks is None:
        return None
    return jackknife(fit.blocks, lambda moments: parameters(engine.solve(fit, moments), layout),
                     full=parameters(fit, layout))


def _parabola_minimum(x: np.ndarray, y: np.ndarray) -> float:
    """Abscissa of the minimum of the parabola through the best point and its neighbours."""
    finite = np.isfinite(y)
    if np.count_nonzero(finite) < 3:
        return math.nan
    i = int(np.clip(np.nanargmin(np.where(finite, y, np.nan)), 1, x.size - 2))
    c = np.polyfit(x[i - 1 : i + 2], y[i - 1 : i + 2], 2)
    if not (c[0] > 0.0 and np.all(np.isfinite(c))):
        return float(x[i])
    return float(np.clip(-c[1] / (2.0 * c[0]), x[0], x[-1]))


def _with_exponent(t1: np.ndarray, t2: np.ndarray, like: Fit, layout: Layout, tf: float,
                   signal: FlowSignal, exponent: float, step: float,
                   length: int) -> Jackknife | None:
    """Jackknife of [parameters, exponent] with the exponent re-optimised per replicate."""
    grid = exponent + step * np.arange(-_GRID_HALF, _GRID_HALF + 1)
    fits = [_refit(t1, t2, like, tf, signal.psi(float(m)), length) for m in grid]
    if any(f is None or f.blocks is None for f in fits):
        return None
    totals = [np.sum(f.blocks, axis=0) for f in fits]  # type: ignore[union-attr]

    def estimate(drop: int | None) -> np.ndarray:
        solved = [engine.solve(f, total - (0 if drop is None else f.blocks[drop]))  # type: ignore[union-attr]
                  for f, total in zip(fits, totals, strict=True)]
        misfits = np.array([s.misfit for s in solved])
        m = _parabola_minimum(grid, misfits)
        if not math.isfinite(m):
            return np.full(len(layout.names()) + 1, math.nan)
        j = int(np.clip(np.searchsorted(grid, m) - 1, 0, grid.size - 2))
        w = (m - grid[j]) / (grid[j + 1] - grid[j])
        p = (1.0 - w) * parameters(solved[j], layout) + w * parameters(solved[j + 1], layout)
        return np.concatenate((p, [m]))

    full = estimate(None)
    blocks = fits[0].blocks.shape[0]  # type: ignore[union-attr]
    reps = np.array([estimate(b) for b in range(blocks)])
    ok = np.all(np.isfinite(reps), axis=1)
    count = int(np.count_nonzero(ok))
    if count < max(6, blocks // 2):
        std = np.full(full.shape, math.inf)
    else:
        good = reps[ok]
        std = np.sqrt((count - 1) / count * np.sum((good - good.mean(axis=0)) ** 2, axis=0))
    return Jackknife(full, std, reps)


def _exponent_step(t1: np.ndarray, t2: np.ndarray, like: Fit, signal: FlowSignal,
                   exponent: float, effective_rows: float) -> float:
    """Grid step for the per-replicate exponent search: about the exponent's standard
    uncertainty from the misfit's curvature (a change of the misfit by mu / N_eff), within
    0.002-0.05."""
    from dualprobe.estimation.field import exponent_misfit

    misfit = exponent_misfit(t1, t2, like, signal)
    h = 0.02
    values = [misfit(exponent - h), misfit(exponent), misfit(exponent + h)]
    curvature = (values[0] - 2.0 * values[1] + values[2]) / h**2
    if not (curvature > 0.0 and math.isfinite(curvature)):
        return 0.05
    sigma = math.sqrt(max(values[1], 1.0) / (effective_rows * curvature))
    return float(np.clip(sigma, 0.002, 0.05))


def confidence(
    t1: np.ndarray,
    t2: np.ndarray,
    estimate: PairEstimate,
    model: FlowModel,
    signal: FlowSignal | None,
) -> Confidence:
    """Standard uncertainties and identifiability of an ``ok`` estimate (module docstring)."""
    fit = estimate.details["fit"]
    assert isinstance(fit, Fit)
    layout = _layout(estimate, fit)
    names = layout.names()
    power = model.kind == "power_law" and signal is not None
    if power:
        names = [*names, "exponent"]
    length = block_length(t1.size, filter_memory(fit.order, fit.tf) / fit.ts)
    psi = model.psi if model.scheduled else None
    n_eff = float(estimate.details.get("effective_samples", fit.rows))  # type: ignore[arg-type]
    notes: list[str] = []

    def run(tf: float) -> Jackknife | None:
        if power:
            assert signal is not None
            step = _exponent_step(t1, t2, fit, signal, model.exponent, n_eff)
            return _with_exponent(t1, t2, fit, layout, tf, signal, model.exponent, step, length)
        return _fixed_schedule(t1, t2, fit, layout, tf, psi, length)

    base = run(fit.tf)
    if base is None:
        nan = dict.fromkeys(names, math.nan)
        return Confidence(nan, dict.fromkeys(names, math.inf), nan, nan,
                          dict.fromkeys(names, False),
                          {n: ["no uncertainty could be computed"] for n in names}, 0, length)
    variants = [j for j in (run(fit.tf * k) for k in _TF_VARIANTS) if j is not None]
    sensitivity = settings_sensitivity(base, variants)
    total = np.sqrt(base.std**2 + sensitivity.systematic**2)
    misfit_statistic = (fit.misfit - 1.0) * math.sqrt(n_eff / 2.0)
    identifiable: dict[str, bool] = {}
    reasons: dict[str, list[str]] = {}
    for i, name in enumerate(names):
        value, std = float(base.estimate[i]), float(total[i])
        why = []
        scale = abs(value) if name != "offset" else math.inf  # an offset may be ~0
        if not math.isfinite(std) and base.failed > 0:
            # the refits without one stretch each fail (the blocks themselves are enough)
            why.append(f"the fit fails on {base.failed} of {base.blocks} refits that each "
                       f"leave out {length} rows: it rests on a few stretches of the record or "
                       "on a model that does not hold (try --order 1, or dualprobe diagnose)")
        elif not math.isfinite(std):
            why.append(f"the record holds too few independent stretches for an uncertainty "
                       f"({base.blocks} blocks of {length} rows; record longer or with more "
                       "temperature changes)")
        elif name not in ("offset", "exponent") and std > RELATIVE_LIMIT * scale:
            why.append(f"relative standard uncertainty {std / max(scale, 1e-300):.0%} "
                       f"> {RELATIVE_LIMIT:.0%}")
        if sensitivity.systematic[i] > SETTING_SHARE * scale:
            why.append(f"the estimate moves with the filter time constant (tf/2 .. 2 tf) by "
                       f"{sensitivity.systematic[i] / scale:.0%} (more than {SETTING_SHARE:.0%})")
        if misfit_statistic > GAP_THRESHOLD and name != "offset":
            why.append(f"the model leaves a misfit of {fit.misfit:.3g} times the noise")
        identifiable[name] = not why
        reasons[name] = why
    if model.kind in ("curve", "tracked"):
        notes.append(f"the {model.kind} schedule is taken as given: its own uncertainty is "
                     "not in these standard deviations")
    return Confidence(
        values={n: float(base.estimate[i]) for i, n in enumerate(names)},
        std={n: float(total[i]) for i, n in enumerate(names)},
        jackknife_std={n: float(base.std[i]) for i, n in enumerate(names)},
        settings_std={n: float(sensitivity.systematic[i]) for i, n in enumerate(names)},
        identifiable=identifiable, reasons=reasons, blocks=base.blocks, block_length=length,
        notes=notes,
    )
