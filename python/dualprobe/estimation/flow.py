"""Time constants that follow the gas flow (paper eq. 1): which law, and its exponent.

With a flow signal v(t) (any positive flow-like quantity: only ratios matter) each sensor's
time constants are ``tau_i(t) = tau_i,ref / psi(t)`` with one ``psi`` common to both sensors
(their ratio stays constant, eq. 5): ``psi = (v/v_ref)^m`` (power law, eq. 1), a free monotone
curve of v, or 1 (constant). The scheduled cross-relation (design.md 1.5) is linear in the time
constants for a given psi, so:

* **power law**: m minimises the smallest generalised eigenvalue mu(m) of the scheduled GTLS
  (the fit's misfit in units of the noise: a profile criterion in m), on a grid over
  [-0.5, 1.5] (physical exponents are 0.3-0.7; the wider range lets the data say when they are
  not), then bounded Brent to 1e-4;
* **curve**: psi a combination of ``CURVE_KNOTS`` hat functions of log v (knots at flow
  quantiles), each a scheduled static column, solved jointly; kept only where it is monotone
  (the time constants fall as the flow rises) and normalised to psi(v_ref) = 1;
* **constant**: no schedule.

The kind is chosen by evidence, not by default: a richer law must lower the misfit by more
than ``GAP_THRESHOLD`` standard deviations of the noise-only spread (the test the order and
static-model selections use) and change the time constants over the record's 5-95 % flow range
by more than ``PRACTICAL_CHANGE`` (5 %), or, changing them less, explain the data (misfit within
the noise band) where the simpler model does not: a record mostly at one flow whose excursions
the law is needed for (300 s at 2 Hz, the velocity within 3 % over 90 % of it: the law changed
tau by 2.3 % there and took the misfit from 4.71 to 0.98 times the noise; reported constant,
the gas was 2.8x the oracle). v_ref is the median flow of the record.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dualprobe.estimation.settings import GAP_THRESHOLD
from dualprobe.models.minimise import grid_then_brent

__all__ = [
    "CURVE_KNOTS",
    "EXPONENT_GRID",
    "KINDS",
    "PRACTICAL_CHANGE",
    "FlowCurve",
    "FlowSignal",
    "check_flow",
    "curve_basis",
    "curve_from_theta",
    "decided",
    "evidence",
    "search_exponent",
]

KINDS = ("constant", "power_law", "curve")
EXPONENT_GRID = np.linspace(-0.5, 1.5, 21)  # coarse scan before Brent (step 0.1)
EXPONENT_TOLERANCE = 1e-4
PRACTICAL_CHANGE = 0.05  # a law must change tau by >= 5 % over the 5-95 % flow range
CURVE_KNOTS = 5  # hat functions of log flow for the free curve (quantiles 2..98 %)


@dataclass(frozen=True)
class FlowSignal:
    """A validated flow column: positive, finite, varying; ``reference`` its median."""

    values: np.ndarray
    column: str | None
    reference: float
    factor: np.ndarray | None = None  # a fixed factor per row (the gas level's, field._level)

    @functools.cached_property
    def log_ratio(self) -> np.ndarray:
        """``log(v / v_ref)``, once per signal: the searches evaluate hundreds of exponents, and
        ``exp(m log_ratio)`` costs a third of a power (0.5 s of a 4.6 s characterisation)."""
        return np.asarray(np.log(self.values / self.reference))

    def psi(self, exponent: float) -> np.ndarray:
        """The schedule ``(v / v_ref)^m`` (time constants scale as its inverse), times
        ``factor`` when there is one."""
        law = np.exp(exponent * self.log_ratio)
        return law if self.factor is None else law * self.factor

    @property
    def span(self) -> tuple[float, float]:
        """5 % and 95 % quantiles of the flow (the range the record informs)."""
        lo, hi = np.quantile(self.values, [0.05, 0.95])
        return float(lo), float(hi)

    def change(self, exponent: float) -> float:
        """Relative change of a power-law time constant over the 5-95 % flow range."""
        lo, hi = self.span
        return float((hi / lo) ** abs(exponent) - 1.0)


def check_flow(values: np.ndarray, column: str | None, length: int) -> FlowSignal:
    """Validate a flow column; raises ValueError with one line (zeros, negatives, NaN, no
    variation, a wrong length)."""
    v = np.asarray(values, dtype=float)
    name = f"flow column {column!r}" if column else "flow"
    if v.ndim != 1 or v.size != length:
        raise ValueError(f"{name}: expected {length} values, got shape {v.shape}")
    bad = np.flatnonzero(~np.isfinite(v))
    if bad.size:
        raise ValueError(f"{name}: row {int(bad[0])} is not a finite number")
    bad = np.flatnonzero(v <= 0.0)
    if bad.size:
        raise ValueError(f"{name}: row {int(bad[0])} is {v[bad[0]]:g}; a flow must be > 0 "
                         "(any positive flow-like quantity: only its ratios matter)")
    lo, hi = np.quantile(v, [0.05, 0.95])
    if not hi > lo * (1.0 + 1e-6):
        raise ValueError(f"{name} does not vary (5-95 % range {lo:g} to {hi:g}): a flow law "
                         "needs a record in which the flow changes")
    return FlowSignal(v, column, float(np.median(v)))


def evidence(simple: float, rich: float, effective_rows: float) -> float:
    """How many noise standard deviations the richer model's misfit ``rich`` lies below the
    simpler one's (smallest generalised eigenvalues; with the right noise model the noise-only
    value is 1 and scatters by sqrt(2/N_eff); a misfit above 1 is the reference)."""
    return (simple / max(rich, 1.0) - 1.0) * math.sqrt(effective_rows / 2.0)


def decided(signal: FlowSignal, exponent: float, simple: float, rich: float,
            effective_rows: float) -> bool:
    """Whether a power law of ``exponent`` (misfit ``rich``) is chosen over the simpler model
    (misfit ``simple``): significantly better, and of practical size or needed to explain the
    data (module docstring)."""
    if not evidence(simple, rich, effective_rows) > GAP_THRESHOLD:
        return False
    needed = evidence(simple, 1.0, effective_rows) > GAP_THRESHOLD >= evidence(
        rich, 1.0, effective_rows)
    return signal.change(exponent) > PRACTICAL_CHANGE or needed


def search_exponent(
    misfit: Callable[[float], float], grid: np.ndarray = EXPONENT_GRID,
    tolerance: float = EXPONENT_TOLERANCE,
) -> tuple[float, np.ndarray]:
    """Exponent minimising ``misfit(m)``: the grid, then bounded Brent between the best grid
    point's neighbours. Returns (m, the grid's misfits); NaN when no grid point fits."""
    return grid_then_brent(misfit, grid, tolerance)


# --------------------------------------------------------------------------------------------
# The free curve: hat functions of log flow
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FlowCurve:
    """psi as a piecewise-linear function of log flow through ``knots`` (flow values) with
    ``values`` (psi at the knots, psi(v_ref) = 1); constant beyond the end knots."""

    knots: np.ndarray
    values: np.ndarray

    def psi(self, flow: np.ndarray) -> np.ndarray:
        return np.interp(np.log(flow), np.log(self.knots), self.values)

    @property
    def monotone(self) -> bool:
        """psi rises with the flow (time constants fall) over the whole curve."""
        return bool(np.all(np.diff(self.values) > 0.0))


def curve_basis(flow: FlowSignal, knots: int = CURVE_KNOTS) -> tuple[np.ndarray, np.ndarray]:
    """(knot flows (K,), basis weights (N, K)): hat functions of log flow at the 2-98 %
    quantiles, the end hats extended flat (weights sum to 1 everywhere)."""
    at = np.quantile(flow.values, np.linspace(0.02, 0.98, knots))
    at = np.maximum.accumulate(at * (1.0 + 1e-9 * np.arange(knots)))  # strictly increasing
    x = np.log(flow.values)
    grid = np.log(at)
    weights = np.zeros((x.size, knots))
    for k in range(knots):
        unit = np.zeros(knots)
        unit[k] = 1.0
        weights[:, k] = np.interp(x, grid, unit)
    return at, weights


def curve_from_theta(theta: np.ndarray, knots: np.ndarray, reference: float) -> FlowCurve:
    """The curve of a basis fit: the static coefficients are ``-a_k`` (theta normalised to a
    last entry of -1), psi(v) = sum a_k B_k(v), renormalised to psi(v_ref) = 1."""
    count = knots.size
    a = -np.asarray(theta, dtype=float)[-count:]
    at_ref = float(np.interp(math.log(reference), np.log(knots), a))
    values = a / at_ref if at_ref != 0.0 else np.full(count, math.nan)
    return FlowCurve(knots=np.asarray(knots, dtype=float), values=values)
