"""The gas level of the flow law's level term (:func:`dualprobe.estimation.field.flow_law`):
``tau ~ flow^-m exp(b dT + c dT^2)``, ``dT = T - T_ref``, T the gas level from sensor 1.

:func:`gas_level` makes the level (sensor 1's inverse, first or second order, smoothed),
:func:`candidates` the levels searched (several smoothings, and the reading),
:func:`search` fits (m, b, c) for one level by the scheduled SVF fit's misfit, and
:func:`sharper` searches again with sensor 1's order-2 inverse once its stages are known.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import scipy.optimize
import scipy.signal

from dualprobe.estimation import engine, flow
from dualprobe.estimation.engine import Fit
from dualprobe.estimation.orders import sensor_order_fits

__all__ = ["Found", "candidates", "gas_level", "one_sided_misfit", "search", "sharper"]

# (the optimum of (m, b x span, c x span^2), the schedule of those parameters, the level's mean,
# its 5-95 % span)
Found = tuple[scipy.optimize.OptimizeResult, Callable[[np.ndarray], np.ndarray], float, float]

_BOUND = 1.0  # |b| x the 5-95 % level range: tau changing by e^1 with the level is no gas
# |c| x the range squared: a gas following (T / T_ref)^-n over 460-700 K gives 0.01-0.02 (b
# 0.12-0.17). Bounded at 1 like b, c's square let psi span e^9 at the clip and a fit "explain"
# a 10 Hz pair to 0.0035 times the noise with 632 / 1325 s.
_CURVATURE_BOUND = 0.1
# The level's deviation from its mean, in 5-95 % ranges: an order-2 inverse's noise (50 Hz, a
# jittered clock) puts rows beyond any gas level (clipped at 1.5, real load steps were cut:
# one pair went from 1.01x to 2.34x the oracle).
_CLIP = 3.0
_NO_FIT = 1e30  # the search's misfit where no fit exists
_SHARPER = (1.0, 2.0, 4.0)  # the order-2 inverse smoothed over tf / these
_SHARP = (4.0, 16.0)  # the sharper first-order levels: smoothed over tf / these (candidates)


def sharper(
    t1: np.ndarray, t2: np.ndarray, fit: Fit, stages: tuple[float, ...],
    signal: flow.FlowSignal, start: np.ndarray, psi: np.ndarray,
) -> Found | None:
    """The level term searched again from ``start`` with a sharper level when sensor 1 came
    out second order (``stages``, at psi = 1; ``fit`` the fit with schedule ``psi``): its
    order-2 inverse with those stages scheduled, smoothed over the fit's filter time constant
    or a half or a quarter of it, whichever explains the signals best. Why: the first-order
    inverse of a sheathed sensor lags the gas by the sheath, and the level's lag and
    smoothing decide how well psi follows the gas. On a 0.82 s sheath in front of a 6.5 s
    element (separate generator, 10 Hz, 0.05 K), the true stages' inverse smoothed over 0.3 s
    left psi 0.28 % RMS off in log and the stages right (0.83 / 1.02 s for 0.82 / 1.01); the
    first-order one smoothed over tf 0.5 % and stages that looked shared (1.34 / 1.57 s), and
    the pair fell back to first order at 3.96x the oracle (now 1.02x). None when sensor 1 is
    first order or no fit exists."""
    if len(stages) != 2 or fit.hysteresis or not all(math.isfinite(v) for v in stages):
        return None
    lag, second = (stages[0] + stages[1]) / psi, stages[0] * stages[1] / psi**2
    found = [search(t1, t2, fit, signal, start, gas_level(t1, lag, fit.ts, fit.tf / share,
                                                           second))
             for share in _SHARPER]
    options = [f for f in found if f is not None]
    return min(options, key=lambda f: float(f[0].fun)) if options else None


def candidates(t1: np.ndarray, tau: np.ndarray, ts: float, tf: float,
               ) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The gas levels the level term is searched with, (usual, sharper): sensor 1's
    first-order inverse with the per-row time constant ``tau`` smoothed over the filter time
    constant, and its reading; and the inverse smoothed over a quarter and a sixteenth of tf.
    The caller takes the better usual level unless a sharper one explains the signals
    significantly better. Why the reading: the inverse alone at 10 Hz gave m within
    0.011-0.030 of the truth on 7 pairs (the reading 0.028-0.060); on a 2 Hz pair with a
    2.2 s element the inverse is coarse (m 0.590 for 0.65; the better of the two, 0.647). Why
    sharper: smoothed over tf, the level misses the gas's fast load changes (100 K within a
    second through the combustion path), where psi is seen: three drive-cycle pairs whose
    sensors follow (mass flow x T)^-m kept a misfit of 4.1-6.3 times the noise and m 0.05-0.06
    too large; with a sharper level, 0.96-1.28 and within 0.006-0.017 (the true gas as the
    level: 0.92-1.04 and within 0.001). Why only on evidence: with near-equal sheaths the
    stages hang on the level, and the sharper one, hardly better in misfit (1.47 -> 1.08 on
    580 effective rows), moved 0.79 / 0.84 s sheaths to 1.9 / 2.0 s (2.8x -> 3.4x the
    oracle)."""
    usual = [gas_level(t1, tau, ts, tf), np.asarray(t1, dtype=float)]
    return usual, [gas_level(t1, tau, ts, tf / share) for share in _SHARP]


def one_sided_misfit(fit: Fit) -> float:
    """The misfit of an order-2 fit with a second stage on one sensor only, the better side:
    no stage can be common to both sensors, so none can absorb a missing level (the sub-models
    of :func:`dualprobe.estimation.orders.sensor_order_fits`)."""
    subs = sensor_order_fits(fit, ((2, 1), (1, 2)))
    values = [sub.mu for sub in subs.values()]
    finite = [v for v in values if math.isfinite(v)]
    return min(finite) if finite else math.inf


def search(
    t1: np.ndarray, t2: np.ndarray, fit: Fit, signal: flow.FlowSignal, start: np.ndarray,
    level: np.ndarray, *, one_sided: bool = False,
) -> Found | None:
    """Nelder-Mead over (m, b x span, c x span^2) of the scheduled fit's misfit for one gas
    level: (the optimum, the schedule of those parameters, the level's mean, its 5-95 % span);
    None when the level does not vary or no fit is finite. ``one_sided`` (an order-2 ``fit``):
    the misfit is :func:`one_sided_misfit`'s."""
    reference = float(np.mean(level))
    lo, hi = np.quantile(level, [0.05, 0.95])
    span = float(hi - lo)
    if not span > 0.0:
        return None
    # b * span: the log change over the level range; clipped where an order-2 inverse's noise
    # (50 Hz, jittered clock) puts a row beyond any gas level, so c's square cannot blow up
    deviation = np.clip((level - reference) / span, -_CLIP, _CLIP)

    log_ratio = signal.log_ratio

    def schedule(p: np.ndarray) -> np.ndarray:
        # psi = (v / v_ref)^m exp(-log_tau), one exp per trial (the search's hot path)
        log_tau = (float(p[1]) + float(p[2]) * deviation) * deviation
        return np.exp(float(p[0]) * log_ratio - log_tau)

    def misfit(p: np.ndarray) -> float:
        # a large finite value, not inf: Nelder-Mead subtracts the simplex's values
        if abs(float(p[1])) > _BOUND or abs(float(p[2])) > _CURVATURE_BOUND:
            return _NO_FIT
        res = engine.fit(t1, t2, fit.ts, tf=fit.tf, order=fit.order, static=fit.static,
                         sigma=fit.sigma, schedule=schedule(p), windows=fit.windows or None)
        if res is None:
            return _NO_FIT
        value = one_sided_misfit(res) if one_sided else res.misfit
        return value if math.isfinite(value) else _NO_FIT

    start = np.asarray(start, dtype=float)
    best = scipy.optimize.minimize(
        misfit, start, method="Nelder-Mead",
        options={"initial_simplex": start + np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0],
                                                      [0.0, 0.1, 0.0], [0.0, 0.0, 0.05]]),
                 "xatol": 1e-3, "fatol": 1e-3 * max(fit.misfit, 1.0), "maxfev": 140})
    if not float(best.fun) < _NO_FIT:
        return None
    return best, schedule, reference, span


def gas_level(t1: np.ndarray, tau: np.ndarray, ts: float, smoothing: float,
               second: np.ndarray | None = None) -> np.ndarray:
    """The gas level for the level term: sensor 1's first-order inverse ``T1 + tau T1'`` with
    the power law's per-row time constant (order 2 with ``second``, the per-row product of the
    stages, ``tau`` their sum: ``+ second T1''``), smoothed zero-phase over ``smoothing``
    seconds (the fit's filter time constant: what the SVF resolves; it keeps the inverse's noise
    to a fraction of a kelvin, 1e-3 of psi). Sensor 1's reading lags the gas by its time
    constant, hundreds of kelvin on load steps through the combustion path; on four drive cycles
    whose sensors follow (mass flow x T)^-m the misfit with the reading was 1.7-6.1 times the
    noise and m off by 0.03-0.06; with the true gas 1.1-2.6 and within 0.01 of the truth."""
    slope = np.gradient(t1, ts)
    raw = t1 + tau * slope
    if second is not None:  # an order-2 inverse: second = the product of the stages
        raw = raw + second * np.gradient(slope, ts)
    a = math.exp(-ts / max(smoothing, ts))
    return np.asarray(scipy.signal.filtfilt([1.0 - a], [1.0, -a], raw))
