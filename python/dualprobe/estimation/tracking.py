"""Time constants that vary without a flow signal: a regularised cross-relation in time.

When no flow signal is given, the common factor of both sensors' time constants is tracked
over the record with their ratio held constant (paper eq. 5): ``tau_i(t) = tau_i / psi(t)``.
The scheduled cross-relation (design.md 1.5), ``psi (T2 - T1) = tau1 T1' - tau2 T2'`` (order 1;
order 2 adds ``d_i (phi T_i')'``), is linear in the unknowns when psi is expanded in hat
functions of time, ``psi(t) = sum_k a_k B_k(t)`` with knots every ``spacing`` samples: the
static column becomes one filtered column ``F(B_k (T2 - T1))`` per knot, the derivative
columns stay. The generalised TLS over all columns with a penalty on the first differences of
a (a random walk of psi), ``min v' (S + lambda R) v / v' C v``, is a sparse generalised
eigenproblem (banded knot block, a few dense derivative columns; its moments:
:mod:`dualprobe.estimation.knots`), solved by shift-invert Lanczos. The penalty weight
follows the discrepancy principle: the largest lambda whose normalised misfit mu stays within
the noise band of the best attainable fit, so the tracked psi is as smooth as the data allow
and exactly constant when the time constants do not vary.

Measured (simulated 30-min drive cycles, 10 Hz, 0.05 K, m = 0.5, ratio 3): the tracked element
time constants within 5-6 % RMS of the truth, reconstruction 1.15 K against the oracle's 0.87 K
and 8.6 K with constant time constants.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from dualprobe.estimation import engine
from dualprobe.estimation.banded import bordered_solver
from dualprobe.estimation.knots import (
    KnotSystem,
    RowFilter,
    knot_parts,
    knot_system,
    sparse_system,
)
from dualprobe.estimation.reuse import reused


class TrackingError(RuntimeError):
    """The tracker found no solution (the caller keeps constant time constants)."""


_START_SEED = 20261207  # the Lanczos start vector's seed (solve_penalised)
_DENSE_LIMIT = 3000  # knots + derivative columns solved densely when Lanczos fails
_TAIL = 34.0  # filter memory kept per knot column, in tf: exp(-34) ~ 2e-15 of its peak


@dataclass(frozen=True)
class TrackSolution:
    penalty: float
    misfit: float  # smallest generalised eigenvalue (1: the noise level)
    vector: np.ndarray  # [dense coefficients, knot coefficients], psi normalised to mean 1


def _checked_inverse(a: sp.csc_matrix, dense: int) -> spl.LinearOperator:
    """``a``'s inverse for the shift-invert Lanczos (``dense`` derivative columns first, then
    the banded knots: :func:`banded.bordered_solver`), raising RuntimeError on a non-finite
    solve: a nearly singular pencil otherwise hands ARPACK infinities, which it iterates on
    (LAPACK's DLASCL complaining on the terminal) before failing or returning garbage."""
    inverse = bordered_solver(a, dense)

    def solve(x: np.ndarray) -> np.ndarray:
        y = inverse(np.asarray(x, dtype=float))
        if not np.all(np.isfinite(y)):
            raise RuntimeError("the tracking pencil is singular")
        return y

    return spl.LinearOperator(a.shape, matvec=solve, dtype=float)


def solve_penalised(system: KnotSystem, penalty: float,
                    matrices: tuple[sp.csc_matrix, sp.csc_matrix, sp.csc_matrix] | None = None,
                    ) -> TrackSolution:
    """Smallest generalised eigenpair of ``(S + penalty R) v = mu C v`` (diagonally scaled;
    ``penalty`` relative to the scaled data term)."""
    s, c, r = matrices if matrices is not None else sparse_system(system)
    # A knot column can be exactly zero: knots at every row (a rate near 1 / tf) on a logger's
    # quantised readings, where both sensors read the same step (T2 - T1 = 0). Its scale is
    # floored (its value then rests on the penalty's neighbours) instead of made infinite,
    # which failed every such track (a 2 Hz record's even/odd halves: psi_noise unknown).
    diagonal = s.diagonal()
    floor = max(1e-12 * float(np.mean(diagonal)), np.finfo(float).tiny)
    scale = 1.0 / np.sqrt(np.maximum(diagonal, floor))
    dm = sp.diags(scale)
    a = (dm @ (s + penalty * r) @ dm).tocsc()
    m = (dm @ c @ dm).tocsc()
    m = m + sp.diags(1e-12 * max(float(m.diagonal().mean()), 1e-300) * np.ones(m.shape[0]))
    if not (np.all(np.isfinite(a.data)) and np.all(np.isfinite(m.data))):
        raise TrackingError("the tracking system is not finite (no excitation somewhere)")
    # ARPACK's start, fixed: left to SciPy (1.15+) it is drawn from fresh OS entropy at every
    # call, so two runs of one record differed (1.0-1.1e-5 K in the gas of a 50 Hz record).
    # The same distribution as SciPy's own draw, from a fixed seed: the same numbers every run.
    start = np.random.default_rng(_START_SEED).uniform(-1.0, 1.0, a.shape[0])
    try:
        values, vectors = spl.eigsh(a, k=1, M=m, sigma=0.0, which="LM", v0=start,
                                    OPinv=_checked_inverse(a, system.dense.shape[0]))
    except (spl.ArpackError, spl.ArpackNoConvergence, RuntimeError):
        # shift-invert Lanczos can stall on nearly singular pencils: the dense solver for
        # moderate sizes, else no tracking
        if a.shape[0] > _DENSE_LIMIT:
            raise TrackingError("the tracking eigenproblem did not converge") from None
        try:
            values, vectors = scipy.linalg.eigh(a.toarray(), m.toarray(),
                                                subset_by_index=[0, 0])
        except (np.linalg.LinAlgError, ValueError):
            raise TrackingError("the tracking eigenproblem has no solution") from None
    v = vectors[:, 0] * scale
    d = system.dense.shape[0]
    psi_mean = float(np.mean(system.psi(-v[d:])))
    return TrackSolution(penalty, float(values[0]), v / psi_mean)


_LOWEST = 1e-3  # the penalty search's lower bound


def choose_penalty(
    system: KnotSystem, effective_rows: float, *, band: float = 2.0,
    bounds: tuple[float, float] = (_LOWEST, 1e7), steps: int = 14,
) -> tuple[TrackSolution, TrackSolution, TrackSolution]:
    """(chosen, freest, stiffest): the discrepancy principle on log penalty. The chosen penalty
    is the largest whose misfit stays within ``band`` noise standard deviations
    (``sqrt(2 / effective_rows)`` relative) of the freest fit's (floored at 1, the noise)."""
    matrices = sparse_system(system)
    lo, hi = math.log(bounds[0]), math.log(bounds[1])
    freest = solve_penalised(system, bounds[0], matrices)
    stiffest = solve_penalised(system, bounds[1], matrices)
    target = max(freest.misfit, 1.0) * (1.0 + band * math.sqrt(2.0 / effective_rows))
    if stiffest.misfit <= target:
        return stiffest, freest, stiffest
    best = freest
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        trial = solve_penalised(system, math.exp(mid), matrices)
        if trial.misfit <= target:
            lo, best = mid, trial
        else:
            hi = mid
    return best, freest, stiffest


# --------------------------------------------------------------------------------------------
# The tracker: columns from the compiled SVF cascade, penalty by the discrepancy principle
# --------------------------------------------------------------------------------------------

PRACTICAL_VARIATION = 0.05  # psi must span >= 5 % (5-95 % quantiles) to count as varying
_SPACING_OF_TF = 0.5  # knots every tf/2: resolves flow changes the filter itself resolves
# ... unless psi moves more than this from knot to knot (RMS of log psi's steps): then the flow
# changes faster than the knots, and they are set every tf/4. On the separate generator's
# drive cycles without the flow (2026-11-29): 0.03-0.14 on 8 pairs that tf/4 leaves within
# 0.03x of the oracle ratio (and tf/4 costs two 5 Hz pairs their noise check: halves at
# 2.5 Hz), 0.27 on a pair with m 0.68 and psi 0.4-3 whose gas went 3.38x -> 2.40x the
# oracle's error at tf/4 (per-row time constants 15 % -> 11 % off).
_ROUGH_STEP = 0.2
FINE_SPACING_OF_TF = 0.5 * _SPACING_OF_TF  # the refined knots (also the caller's retry)


@dataclass(frozen=True)
class Tracking:
    """Time constants tracked over the record with their ratio constant.

    ``psi`` (N,) the common factor (mean 1): the time constants at row k are
    ``time_constants / psi[k]``; ``time_constants`` per sensor (order 2: both stages) at
    psi = 1; ``misfit`` the tracked fit's smallest generalised eigenvalue, ``misfit_constant``
    the same model's with psi constant (the stiffest penalty); ``spacing`` knots in samples;
    ``static`` the map (g, o) of sensor 2 onto sensor 1 it was tracked with;
    ``spacing_of_tf`` the knot spacing asked for, in tf."""

    psi: np.ndarray
    time_constants: tuple[tuple[float, ...], tuple[float, ...]]
    polynomials: tuple[tuple[float, ...], tuple[float, ...]]
    penalty: float
    misfit: float
    misfit_constant: float
    misfit_free: float
    spacing: int
    static: tuple[float, float]
    spacing_of_tf: float = _SPACING_OF_TF

    @property
    def knot_step(self) -> float:
        """RMS step of log psi from knot to knot (NaN where psi is not positive)."""
        knots = self.psi[:: self.spacing]
        if knots.size < 2 or not np.all(knots > 0.0):
            return math.nan
        return float(np.sqrt(np.mean(np.diff(np.log(knots)) ** 2)))

    @property
    def variation(self) -> float:
        """Relative span of psi between its 5 % and 95 % quantiles."""
        lo, hi = np.quantile(self.psi, [0.05, 0.95])
        return float(hi / lo - 1.0) if lo > 0.0 else math.inf


def _row_noise(ts: float, tf: float, order: int, sigma: tuple[float, float]) -> np.ndarray:
    """Stationary per-row noise covariance of the unscheduled unit-layout columns
    ``[x_1..x_n(T1), -x_1..x_n(T2), x_0(T2) - x_0(T1)]`` (design.md 1.4)."""
    from dualprobe import _core

    disc = _core.svf_discretisation(ts, tf, order + 1, "foh")
    lmap = np.asarray(disc["derivative_map"])[: order + 1]
    cov_x = lmap @ np.asarray(disc["state_covariance"]) @ lmap.T
    size = 2 * order + 1
    m1 = np.zeros((size, order + 1))
    m2 = np.zeros((size, order + 1))
    for j in range(1, order + 1):
        m1[j - 1, j] = 1.0
        m2[order + j - 1, j] = -1.0
    m1[-1, 0], m2[-1, 0] = -1.0, 1.0
    c = sigma[0] ** 2 * (m1 @ cov_x @ m1.T) + sigma[1] ** 2 * (m2 @ cov_x @ m2.T)
    return 0.5 * (c + c.T)


def _free_responses(ts: float, tf: float, m: int, samples: int) -> np.ndarray:
    """The cascade's free responses ``(k h)^j exp(-k h) / j!`` over the rows where they exceed
    1e-18 of their peak ((60 + 2m) tf): every start-up transient of a column lies in their span."""
    count = min(samples, math.ceil((60.0 + 2.0 * m) * tf / ts) + 1)
    r = np.arange(count) * (ts / tf)
    return np.array([r**j / math.factorial(j) * np.exp(-r) for j in range(m)])


def _dense_columns(
    t1: np.ndarray, t2: np.ndarray, ts: float, tf: float, order: int, phi: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Derivative columns of the scheduled relation and their noise weights: order 1
    ``[x_1(T1), -x_1(T2)]``, order 2 ``[x_1(T1), y_1(T1), -x_1(T2), -y_1(T2)]`` with
    ``y_1 = tf s F(tf phi s T)`` (design.md 1.5)."""
    from dualprobe import _core

    m = order + 1
    columns, weights = [], []
    for sign, x in ((1.0, t1), (-1.0, t2)):
        derivatives = _core.svf_filter(x - x[0], ts, tf, m, "foh")[0]
        columns.append(sign * derivatives[1])
        weights.append(np.ones(x.size))
        if order == 2:
            drive = np.zeros(x.size)
            drive[:-1] = np.diff(x) * (tf / ts) * phi[:-1]
            columns.append(sign * _core.svf_filter(drive, ts, tf, m, "zoh")[0][1])
            weights.append(phi)
    return np.array(columns), np.array(weights)


# A static map that is only nearly right (gain ratio off by 1e-3, i.e. 0.6 K at 600 K) lets a
# free psi fit anything by taking any sign where g T2 + o - T1 crosses zero; at a fixed, moderately
# stiff penalty the same error shows as misfit instead: on a 0.97/1.03 drive cycle the misfit at
# this penalty is 1.09 at the true map and 20-100 at 1e-3 off in g (min within 1.2e-4 of the
# true g at 40, 3.5e-4 at 400).
_STATIC_SEARCH_PENALTY = 40.0


def _setup(t1: np.ndarray, ts: float, tf: float, order: int,
           spacing_of_tf: float = _SPACING_OF_TF) -> tuple[int, int, RowFilter, np.ndarray]:
    """(knot spacing, filter tail, the row filter, the free responses) of a record."""
    from dualprobe import _core

    m = order + 1

    def row_filter(rows: np.ndarray) -> np.ndarray:
        return _core.svf_filter(rows, ts, tf, m, "foh")[:, 0, :]

    spacing = max(1, round(spacing_of_tf * tf / ts))
    return spacing, math.ceil(_TAIL * tf / ts), row_filter, _free_responses(ts, tf, m, t1.size)


@reused
def search_static(
    t1: np.ndarray, t2: np.ndarray, ts: float, *, tf: float, sigma: tuple[float, float],
    start: tuple[float, float], max_evaluations: int = 80, unit_gain: bool = False,
) -> tuple[float, float]:
    """The static map (g, o) of sensor 2 onto sensor 1 for tracking (order 1): the minimum of
    the tracked misfit at a fixed penalty (``_STATIC_SEARCH_PENALTY``) over (g, o), by
    Nelder-Mead from ``start`` (e.g. windowed constant fits, whose medians are within ~1e-3).
    The knot columns are filtered once: every trial map's system is a combination of the
    parts T2 - r, 1 and T1 - r (:class:`dualprobe.estimation.knots.KnotParts`; r centres the
    parts so that their combination loses no digits). ``unit_gain``: the offset alone, with
    g = 1 (from the start's offset at the record's mean level)."""
    u1 = np.asarray(t1, dtype=float)
    v2 = np.asarray(t2, dtype=float)
    spacing, tail, row_filter, free = _setup(u1, ts, tf, 1)
    ones = np.ones(u1.size)
    level = float(np.mean(u1))
    dense, weights = _dense_columns(u1, v2, ts, tf, 1, ones)  # sensor 2's column scales with g
    parts = knot_parts(dense, weights, [v2 - level, ones, u1 - level], spacing, tail,
                       row_filter, free)

    def misfit(x: np.ndarray) -> float:
        gain, offset = float(x[0]), float(x[1])
        if not gain > 0.0:
            return math.inf
        noise = _row_noise(ts, tf, 1, (sigma[0], gain * sigma[1]))
        # g T2 + o - T1 = g (T2 - r) + (o + (g - 1) r) - (T1 - r)
        system = parts.system([gain, offset + (gain - 1.0) * level, -1.0],
                              np.array([1.0, gain]), noise)
        try:
            return solve_penalised(system, _STATIC_SEARCH_PENALTY).misfit
        except TrackingError:
            return math.inf

    g0, o0 = start
    span = max(float(np.std(u1)), 1e-3)  # offset steps in the data's own scale
    if unit_gain:
        # g T2 + o = T2 + o' at the level r: o' = o + (g - 1) r
        o1 = o0 + (g0 - 1.0) * level
        found = scipy.optimize.minimize_scalar(
            lambda o: misfit(np.array([1.0, o])), bracket=(o1 - 0.01 * span, o1 + 0.01 * span),
            options={"xtol": 1e-6, "maxiter": max_evaluations})
        return 1.0, float(found.x)
    simplex = np.array([[g0, o0], [g0 * 1.004, o0], [g0, o0 + 0.01 * span]])
    result = scipy.optimize.minimize(misfit, x0=np.array([g0, o0]), method="Nelder-Mead",
                                     options={"initial_simplex": simplex, "xatol": 1e-5,
                                              "fatol": 1e-3, "maxfev": max_evaluations})
    return float(result.x[0]), float(result.x[1])


# Where both sensors read alike and steady (T2 - T1 and both slopes within the noise) nothing
# pins psi, and the random walk carries it through the noise: on a drive cycle with m = 0.68
# (psi 0.4-3) 23 of 12,000 rows dipped to -0.06 at idle, and the pair, tracked to 1.12 times
# the noise, was rejected for it. Up to this share of rows is floored; beyond it a
# non-positive psi is a real failure (a wrong static offset lets psi take any sign).
_UNPINNED_SHARE = 0.01


def _floored(psi: np.ndarray) -> np.ndarray:
    """psi with non-positive values on at most ``_UNPINNED_SHARE`` of the rows: every value
    below the 1 % quantile of its positive values raised to it (the dip's positive shoulders
    too, whose time constants would be as absurd); else unchanged, for the caller to reject."""
    low = psi <= 0.0
    if not low.any() or low.mean() > _UNPINNED_SHARE:
        return psi
    return np.maximum(psi, float(np.quantile(psi[~low], _UNPINNED_SHARE)))


@reused
def track(
    t1: np.ndarray,
    t2: np.ndarray,
    ts: float,
    *,
    tf: float,
    order: int,
    sigma: tuple[float, float],
    effective_rows: float,
    static: tuple[float, float] = (1.0, 0.0),
    passes: int = 2,
    spacing_of_tf: float | None = None,
    penalty_share: float = 1.0,
) -> Tracking:
    """Track the common factor of both sensors' time constants over the record (module
    docstring). ``static`` = (g, o): sensor 2 mapped to sensor 1's calibration, g T2 + o;
    ``effective_rows`` sets the discrepancy band; order 2 refines phi = 1/psi in ``passes``;
    knots every ``spacing_of_tf`` tf (None: tf/2, or tf/4 where psi moves by more than
    ``_ROUGH_STEP`` from knot to knot at tf/2); ``penalty_share``: the penalty the
    discrepancy principle chose times this (a freer psi, :mod:`dualprobe.estimation.adaptive`)."""

    def at(fraction: float) -> Tracking:
        return _track(t1, t2, ts, tf=tf, order=order, sigma=sigma, effective_rows=effective_rows,
                      static=static, passes=passes, spacing_of_tf=fraction,
                      penalty_share=penalty_share)

    if spacing_of_tf is not None:
        return at(spacing_of_tf)
    coarse = at(_SPACING_OF_TF)
    if coarse.spacing < 2 or not coarse.knot_step > _ROUGH_STEP:
        return coarse
    try:
        fine = at(FINE_SPACING_OF_TF)
    except TrackingError:
        return coarse
    # (coarse's psi is positive here: a knot step is only defined where it is)
    return fine if np.all(fine.psi > 0.0) else coarse


def _track(
    t1: np.ndarray, t2: np.ndarray, ts: float, *, tf: float, order: int,
    sigma: tuple[float, float], effective_rows: float, static: tuple[float, float],
    passes: int, spacing_of_tf: float, penalty_share: float = 1.0,
) -> Tracking:
    """:func:`track` with the knots every ``spacing_of_tf`` tf."""
    gain, offset = static
    u2 = gain * np.asarray(t2, dtype=float) + offset
    u1 = np.asarray(t1, dtype=float)
    s = (sigma[0], gain * sigma[1])
    spacing, tail, row_filter, free = _setup(u1, ts, tf, order, spacing_of_tf)
    phi = np.ones(u1.size)
    # order 2: a first-order pass gives phi for the second-order columns, then refine
    for current in [1] * (order == 2) + [order] * (passes if order == 2 else 1):
        noise = _row_noise(ts, tf, current, s)
        dense, weights = _dense_columns(u1, u2, ts, tf, current, phi)
        system = knot_system(dense, weights, u2 - u1, spacing, tail, row_filter, free, noise)
        chosen, freest, stiffest = choose_penalty(system, effective_rows)
        if penalty_share != 1.0:
            chosen = solve_penalised(system, max(chosen.penalty * penalty_share, _LOWEST))
        psi = system.psi(-chosen.vector[dense.shape[0]:])
        phi = 1.0 / np.maximum(psi, 1e-3)
    psi = _floored(psi)
    coefficients = chosen.vector[: dense.shape[0]]
    polys = []
    for i in range(2):
        c = coefficients[order * i : order * (i + 1)] * tf ** np.arange(1, order + 1)
        polys.append(tuple(float(v) / (gain if i else 1.0) for v in c))
    taus = tuple(engine.polynomial_time_constants(p) for p in polys)
    return Tracking(psi, (taus[0], taus[1]), (polys[0], polys[1]), chosen.penalty,
                    chosen.misfit, stiffest.misfit, freest.misfit, spacing, (gain, offset),
                    spacing_of_tf)


@reused
def split_noise(
    t1: np.ndarray, t2: np.ndarray, ts: float, *, tf: float, sigma: tuple[float, float],
    static: tuple[float, float], effective_rows: float, spacing_of_tf: float | None = None,
) -> float:
    """The part of a first-order tracked log psi that follows the noise, RMS: the record's even
    and odd rows (the same gas and flow, independent noise) tracked apart, each with its own
    penalty by the discrepancy principle at half the effective rows, and half the RMS difference
    of their log psi (the two differ by their noise, each about twice the whole record's in
    variance). The model error that both halves absorb alike is not in it: a lower bound on
    psi's error. ``spacing_of_tf``: the whole record's knots (``Tracking.spacing_of_tf``),
    kept by the halves (None: chosen for them as for the whole record). NaN when a half cannot
    be tracked or its psi is not positive."""
    u1, u2 = np.asarray(t1, dtype=float), np.asarray(t2, dtype=float)
    logs = []
    for rows in (slice(0, None, 2), slice(1, None, 2)):
        try:
            half = track(u1[rows], u2[rows], 2.0 * ts, tf=tf, order=1, sigma=sigma,
                         effective_rows=0.5 * effective_rows, static=static,
                         spacing_of_tf=spacing_of_tf)
        except TrackingError:
            return math.nan
        if not np.all(half.psi > 0.0):
            return math.nan
        logs.append(np.log(half.psi))
    return half_difference(logs[0], logs[1])


def half_difference(first: np.ndarray, second: np.ndarray) -> float:
    """Half the RMS difference of two halves' log psi over their common length: the noise in
    the whole record's log psi, each half carrying about twice its variance."""
    n = min(first.size, second.size)
    difference = first[:n] - second[:n]
    return float(0.5 * np.sqrt(np.mean(difference * difference)))
