"""psi from the joint MAP of the gas, both sensors' states and log psi (no flow signal).

Given each sensor's stage time constants at psi = 1, the schedule ``tau(t) = tau / psi(t)`` is
refined by maximising the joint posterior of: the gas at the rows (a random walk of intensity
``q``), every stage's state (exact chains of first-order stages driven by the gas interpolated
linearly between rows), log psi at knots (hat functions; a random walk of ``step_std`` per
knot) and the static map of sensor 2 onto sensor 1; the rows are the sensors' outputs plus
white noise. Unlike the cross-relation (:mod:`dualprobe.estimation.tracking`,
:mod:`dualprobe.estimation.crossfit`), whose filtered derivative columns carry amplified
noise, this uses each row with its own noise, so psi is found where the gas moves and left to
its prior where it does not (where it does not matter either).

Solved by sparse Gauss-Newton with a Levenberg damping on psi and the static map only; after
every step the states are re-solved for the new psi (a linear least-squares problem), so each
accepted step is evaluated on the constraint manifold (variable projection in effect: joint
steps with the hard dynamics rows were rejected by their second-order violations, 15
iterations without progress on a drive cycle).

Measured (simulated 30-min drive cycles at 10 Hz, sheathed pairs, tests/python field cases):
given the true stage time constants the gas is 1.22x the oracle's error; given the
time constants of the cross-relation fit, 1.23-2.1x (near-equal sheaths: 3.7x, the physics
limit). The time constants themselves are not freed here: with them free, the joint MAP
drifts (both sheaths shrank 30 % below the truth while the cost kept falling, gas 1.2x ->
1.9x), the known bias of maximising over latent states instead of marginalising them.
"""

from __future__ import annotations

import contextlib
import contextvars
import functools
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from dualprobe.estimation.banded import GramBand, band_solver
from dualprobe.estimation.damping import damped_search
from dualprobe.estimation.reuse import reused
from dualprobe.estimation.sparse_ldl import GramLDL

__all__ = ["PatternStore", "PsiMap", "map_psi", "sharing"]

_EPS = 1e-4  # K: the dynamics rows' weight (exact sensors up to 0.1 mK)
# The knot steps' heavy tail ends here (log psi per knot): a larger step is weighted as this
# one, so beyond it the prior is Gaussian again (sd sqrt(step_std^2 + cap^2); step_std is
# about 0.018 with knots every tf/8). Why: with the tail unbounded, psi overshot at load
# steps, by up to 23x for under a second (pair 810 of field_sweep.py 7 12 noflow). Measured
# on 36 sweep pairs (README): at 0.03 the geometric mean went 2.16x -> 2.09x the oracle and
# 25 pairs were within 2.5x, not 24 (810 2.00x -> 1.68x, its worst row 23.5x -> 2.2x the
# truth; 202 2.52x -> 1.44x; 802 3.57x -> 3.32x), the worst loss 5005 2.09x -> 2.17x. At 0.1
# the gains were a third as large; no tail (Gaussian steps) lost one pair's sheathed path
# (5307 1.98x -> 6.02x); 0.3 changed almost nothing.
_STEP_CAP = 0.03
# The Levenberg damping of the knots and the static map (times J'J's diagonal; the states are
# not damped). From psi = 1 it starts at _DAMPING_START; a reweighting's run, which starts
# from the last optimum, at _DAMPING_RESTART: the optimum's own damping ended at 1e-8-1e-6,
# and from 1e-3 its first four or five steps were held back (their gains grew 4-10x each:
# 183, 1268, 4839, 7529 on a 20 min, 20 Hz record). Above the floor: steps at 1e-9 were mostly
# rejected, two or three trials each before one was taken at 1e-6. After a rejected trial the
# damping that was taken is kept for the next step, not lowered again only to be rejected
# (until 2026-12-08 the tail of a run alternated 1e-7 rejected, 1e-6 taken). Measured on three
# of one record's MAPs: 143 -> 100 trials (each a factorisation, a solve and a linearisation).
_DAMPING_START = 1e-3
_DAMPING_RESTART = 1e-7
_DAMPING_FLOOR = 1e-8
# A run stops when a step gains less than this (as before, also below 1e-7 of the cost): the
# cost is a sum of squared normalised residuals, so 0.05 is a twentieth of one row's noise;
# the tails converge linearly (gains 0.36, 0.22, 0.15, 0.09, ...), and the sheath profile
# needs the cost to about 0.3 (sheath_profile._JOINT_GAIN), which the damping's path alone
# moves by as much (the same MAP ended 0.3 apart under the damping schedules tried).
_COST_TOLERANCE = 0.05


@dataclass(frozen=True)
class PsiMap:
    """``psi`` (N,) per row (time constants ``tau / psi``), the static map (gain, offset) with
    ``y2 = gain * x + offset`` (x in sensor 1's scale), the final cost (sum of squared
    normalised residuals) and the iterations taken."""

    psi: np.ndarray
    static: tuple[float, float]
    cost: float
    iterations: int


def _chain(taus: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact step of a chain of first-order stages (1 or 2; ``taus`` (N-1, S), the first sees
    the input) for an input linear between the rows: x+ = M x + g0 u + g1 u+."""
    n, size = taus.shape
    if size == 1:
        z = h / taus[:, 0]
        a = np.exp(-z)
        c = -np.expm1(-z) / z  # mean of exp over the step
        return a[:, None, None], (c - a)[:, None], (1.0 - c)[:, None]
    a_, b_ = taus[:, 0], taus[:, 1]
    ea, eb = np.exp(-h / a_), np.exp(-h / b_)
    hd = h * (1.0 / b_ - 1.0 / a_)
    small = np.abs(hd) < 1e-8
    rel = np.where(small, 1.0 + 0.5 * hd, np.expm1(hd) / np.where(small, 1.0, hd))
    m = np.zeros((n, 2, 2))
    m[:, 0, 0], m[:, 1, 1], m[:, 1, 0] = ea, eb, (h / b_) * eb * rel

    def forced(u0: np.ndarray, u1: np.ndarray) -> np.ndarray:
        # particular solution of a ramp input: each stage lags by its own and earlier taus
        s = (u1 - u0) / h
        p0 = np.stack([u0 - s * a_, u0 - s * (a_ + b_)], axis=1)
        return p0 + (s * h)[:, None] - np.einsum("nij,nj->ni", m, p0)

    one, zero = np.ones(n), np.zeros(n)
    return m, forced(one, zero), forced(zero, one)


@dataclass(frozen=True)
class _Linear:
    """The residuals at given log psi knots and static map: ``a @ states + c``; ``zeta`` log
    psi at the intervals' midpoints; ``chains`` each sensor's step (:func:`_chain`) there;
    ``band`` the lower band of ``a' a`` where formed."""

    a: sp.csc_matrix
    c: np.ndarray
    zeta: np.ndarray
    chains: tuple[tuple[np.ndarray, np.ndarray, np.ndarray], ...]
    band: np.ndarray | None = None


class _Problem:
    def __init__(self, t: np.ndarray, y: tuple[np.ndarray, np.ndarray],
                 stages: tuple[np.ndarray, np.ndarray], sigma: tuple[float, float], q: float,
                 spacing: int, step_std: float) -> None:
        self.y, self.stages, self.sigma = y, stages, sigma
        self.h = np.diff(t)
        self.n = t.size
        self.sizes = (stages[0].size, stages[1].size)
        self.nx = 1 + sum(self.sizes)
        # the priors' weights: scalars, or per increment / knot step once reweighted
        self.prior: float | np.ndarray = 1.0 / np.sqrt(q * self.h)
        self.step: float | np.ndarray = 1.0 / step_std
        # the weak prior on every knot's level (map_psi's level_std): off until reweighting
        self.level, self.centre_z = 0.0, 0.0
        self.knots = math.ceil((self.n - 1) / spacing) + 1
        pos = (np.arange(self.n - 1) + 0.5) / spacing  # log psi at the interval midpoints
        j = np.floor(pos).astype(int)
        f = pos - j
        right = np.minimum(j + 1, self.knots - 1)
        # each interval's two knots and their hat-function weights
        self.pair, self.weight = np.stack([j, right], axis=1), np.stack([1.0 - f, f], axis=1)
        self.centre = float(np.mean(y[0]))
        self.patterns = _patterns(self)
        shared = self.patterns
        self.position, self.csc, self.count = shared.position, shared.csc, shared.count
        self.total = self.count + 2 * self.knots - 1  # the residuals: then the knots' priors

    def zeta(self, z: np.ndarray) -> np.ndarray:
        """log psi at the intervals' midpoints from the knots' (linear between them)."""
        return self.weight[:, 0] * z[self.pair[:, 0]] + self.weight[:, 1] * z[self.pair[:, 1]]

    def _pattern(self) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray], int]:
        """The state Jacobian's fixed sparsity: which value that :meth:`linear` lists goes to
        each place of CSC storage, the CSC indices and pointers, and the rows before the
        knots' priors."""
        n, nx = self.n, self.nx
        k_all, k = np.arange(n), np.arange(n - 1)
        out1, out2 = self.sizes[0], self.sizes[0] + self.sizes[1]
        rows = [k_all, n + k_all]
        cols = [k_all * nx + out1, k_all * nx + out2]
        count, base = 2 * n, 1
        for size in self.sizes:
            for j in range(size):
                r = count + k
                rows += [r, r, r] + [r] * size
                cols += ([(k + 1) * nx + base + j, k * nx, (k + 1) * nx]
                         + [k * nx + base + i for i in range(size)])
                count += n - 1
            base += size
        rows += [count + k, count + k]
        cols += [(k + 1) * nx, k * nx]
        count += n - 1
        row, col = np.concatenate(rows), np.concatenate(cols)
        # the CSC position of every value: no two values share a place (one per row and column)
        where = sp.csc_matrix((np.arange(1.0, row.size + 1.0), (row, col)),
                              shape=(count + 2 * self.knots - 1, n * nx))
        return where.data.astype(np.int64) - 1, (where.indices, where.indptr), count

    def linear(self, z: np.ndarray, static: np.ndarray) -> _Linear:
        """Residuals ``a x + c`` for these log psi knots and static map (linear in the states)."""
        n = self.n
        zeta = self.zeta(z)
        gain, offset = float(static[0]), float(static[1])
        vals = [np.full(n, 1.0 / self.sigma[0]), np.full(n, gain / self.sigma[1])]
        chains = tuple(_chain(np.exp(-zeta)[:, None] * taus[None, :], self.h)
                       for taus in self.stages)
        for (m, g0, g1), size in zip(chains, self.sizes, strict=True):
            for j in range(size):
                vals += [np.full(n - 1, 1.0 / _EPS), -g0[:, j] / _EPS, -g1[:, j] / _EPS]
                vals += [-m[:, j, i] / _EPS for i in range(size)]
        prior = np.broadcast_to(self.prior, (n - 1,))
        vals += [prior, -prior]
        data = np.concatenate(vals)
        a = sp.csc_matrix((data[self.position], *self.csc), shape=(self.total, n * self.nx))
        c = np.zeros(self.total)
        c[:n] = -(self.y[0] - self.centre) / self.sigma[0]
        c[n:2 * n] = (gain * self.centre + offset - self.y[1]) / self.sigma[1]
        c[self.count:self.count + self.knots - 1] = (z[1:] - z[:-1]) * self.step
        c[self.count + self.knots - 1:] = (z - self.centre_z) * self.level
        return _Linear(a, c, zeta, chains)

    def system(self, x: np.ndarray, z: np.ndarray, static: np.ndarray,
               linear: _Linear | None = None,
               ) -> tuple[np.ndarray, sp.csc_matrix, sp.csc_matrix, np.ndarray]:
        """Residuals and their Jacobians: states (sparse), log psi knots (sparse), static
        (``linear``: :meth:`linear` at z and static, when already at hand)."""
        n, nx = self.n, self.nx
        lin = self.linear(z, static) if linear is None else linear
        s = x.reshape(n, nx)
        k = np.arange(n - 1)
        zrows: list[np.ndarray] = []
        zvals: list[np.ndarray] = []
        u0, u1 = s[:-1, 0], s[1:, 0]
        count, base = 2 * n, 1
        for taus, size, (mm, g0, g1) in zip(self.stages, self.sizes, lin.chains, strict=True):
            # d/dzeta of the chain's prediction p = M x + g0 u0 + g1 u1, analytic: the step
            # depends on h / tau only, and every tau scales with exp(-zeta), so d/dzeta is
            # h d/dh at fixed tau; for x' = A x + B u that gives hA p + g1 (u0 - u1) + hB u1,
            # i.e. stage j: (h / tau_j) (its input at the step's end - p_j) + g1_j (u0 - u1).
            # Why not central differences (until 2026-12-07): two more chains per MAP step,
            # 8 % of a sheathed path's time (pair 30705: 153 -> 141 s; its sheath the same to
            # 1e-6 relative, its gas to 5 mK, RMS 0.1 mK); the two agree to ~3e-9 of the
            # largest entry (test_psi_map).
            pred = (np.einsum("nij,nj->ni", mm, s[:-1, base:base + size])
                    + g0 * u0[:, None] + g1 * u1[:, None])
            rate = (self.h * np.exp(lin.zeta))[:, None] / taus[None, :]
            feed = np.column_stack([u1, pred[:, :-1]])
            slope = rate * (feed - pred) + g1 * (u0 - u1)[:, None]
            for j in range(size):
                zrows.append(count + k)
                zvals.append(-slope[:, j] / _EPS)
                count += n - 1
            base += size
        # each dynamics row's derivative in its interval's log psi, spread over that interval's
        # two knots (the hat functions)
        pair, weight = self.pair, self.weight
        value, row = np.concatenate(zvals), np.concatenate(zrows)
        kk = np.arange(self.knots - 1)
        every = np.arange(self.knots)
        steps = np.broadcast_to(self.step, kk.shape)
        drive = sp.csr_matrix(
            (np.concatenate([value * np.tile(weight[:, 0], len(zvals)),
                             value * np.tile(weight[:, 1], len(zvals)),
                             steps, -steps, np.full(self.knots, self.level)]),
             (np.concatenate([row, row, self.count + kk, self.count + kk,
                              self.count + kk.size + every]),
              np.concatenate([np.tile(pair[:, 0], len(zvals)), np.tile(pair[:, 1], len(zvals)),
                              kk + 1, kk, every]))),
            shape=(self.total, self.knots)).tocsc()
        static_jac = np.zeros((self.total, 2))
        static_jac[n:2 * n, 0] = (s[:, self.sizes[0] + self.sizes[1]] + self.centre) / self.sigma[1]
        static_jac[n:2 * n, 1] = 1.0 / self.sigma[1]
        return lin.a @ x + lin.c, lin.a, drive, static_jac

    def states_for(self, z: np.ndarray, static: np.ndarray, x: np.ndarray,
                   ) -> tuple[np.ndarray, _Linear]:
        """The states that minimise the cost for this psi and static map (linear; solved as a
        correction of ``x``, which keeps the rounding to the correction's size), and the
        linearisation there."""
        lin = self.linear(z, static)
        # the states row by row: block-tridiagonal, banded as they are
        band = self.patterns.states_gram.band(lin.a.data)
        solve = band_solver(band, lambda: lin.a.T @ lin.a)
        # kept with the linearisation: the joint J'J's states block (_gauss_newton)
        return x + solve(-(lin.a.T @ (lin.a @ x + lin.c))), replace(lin, band=band)

    def joint_gram_of(self, jacobian: sp.csc_matrix) -> GramLDL:
        """J'J's pattern for the joint Jacobian of states and knots (CSC), built at its first
        use and kept while the pattern holds."""
        jacobian.sum_duplicates()  # the pattern needs each (row, column) once; a no-op if so
        shared = self.patterns
        if shared.joint_gram is None or not shared.joint_gram.fits(jacobian):
            shared.joint_gram = GramLDL(jacobian.indices, jacobian.indptr, jacobian.shape[1])
        return shared.joint_gram


class _Patterns:
    """What a problem's sparsity alone fixes: the state Jacobian's pattern
    (:meth:`_Problem._pattern`) and J'J straight from J's values, for the states' Jacobian
    (its pattern is fixed; banded row by row) and the joint one with the knots (checked
    against its pattern at every use; each knot reaches the states of two spans, so its band
    would be wide: sparse LDL')."""

    def __init__(self, problem: _Problem) -> None:
        self.position, self.csc, self.count = problem._pattern()
        self.states_gram = GramBand(*self.csc, problem.n * problem.nx)
        self.joint_gram: GramLDL | None = None


class PatternStore:
    """The last problem's patterns, kept for the next problem of the same size while this
    store is active (:func:`sharing`). Why: the sheathed path solves some 40 MAPs of one size
    one after the other (a 20 Hz record: 0.14 s per problem's pattern and 0.2-0.5 s per J'J
    pattern, 14 s of its 180 s, test_sheathed_finer.py); the factorisation from the same
    pattern is bit for bit the same. One kept, dropped before another is built; the owner
    (:class:`~dualprobe.estimation.map_schedule.MapSchedule`) frees it with itself, so
    nothing outlives that record's MAPs (kept per thread for the whole characterisation,
    the bench's tracked row peaked at 496 MB, not 371)."""

    def __init__(self) -> None:
        self.key: tuple[object, ...] | None = None
        self.patterns: _Patterns | None = None


# The active store: a context variable, so a thread of a Dask worker never shares one (a
# GramLDL keeps its factorisation's workspace).
_STORE: contextvars.ContextVar[PatternStore | None] = contextvars.ContextVar(
    "dualprobe_psi_patterns", default=None)


@contextlib.contextmanager
def sharing(store: PatternStore) -> Iterator[None]:
    """Within this block, :func:`map_psi` keeps its patterns in ``store``."""
    token = _STORE.set(store)
    try:
        yield
    finally:
        _STORE.reset(token)


def _patterns(problem: _Problem) -> _Patterns:
    """The patterns for this problem's size (rows, stages, knots): from the active store where
    it holds that size's, else built (and kept there, where a store is active)."""
    store = _STORE.get()
    if store is None:
        return _Patterns(problem)
    key = (problem.n, problem.sizes, problem.knots)
    if store.key != key or store.patterns is None:
        store.key, store.patterns = None, None  # free the last before building
        store.patterns, store.key = _Patterns(problem), key
    return store.patterns


def _damped_step(gram: GramLDL, values: np.ndarray, b: np.ndarray, grad: np.ndarray,
                 damping: float, state_count: int) -> np.ndarray:
    """Solve (J'J + damping diag on the parameters) step = -J'r, with the static map's two
    dense columns by a Schur complement (the sparse part by sparse LDL'; ``values`` J'J's
    stored upper triangle in ``gram``'s pattern, built once for the search's trials)."""
    sparse_count = gram.size
    where = gram.diagonal[state_count:]
    damped = values.copy()
    damped[where] += damping * np.maximum(values[where], 1e-12)
    solve = gram.solver(damped)
    cross, corner = b[:sparse_count], b[sparse_count:]
    corner = corner + np.diag(damping * np.maximum(np.diag(corner), 1e-12))
    solved = solve(np.column_stack([-grad[:sparse_count], cross]))
    base, z = solved[:, 0], solved[:, 1:]
    schur = corner - cross.T @ z
    tail = np.linalg.solve(schur, -grad[sparse_count:] - cross.T @ base)
    return np.concatenate([base - z @ tail, tail])


def _trial(problem: _Problem, state: tuple[np.ndarray, np.ndarray, np.ndarray],
           gram: GramLDL, values: np.ndarray, coupling: np.ndarray, grad: np.ndarray,
           damping: float,
           ) -> tuple[tuple[np.ndarray, ...], float]:
    """One damped step from ``state`` (states, log psi knots, static map), the states then
    re-solved for the new psi: the new (state, residuals, Jacobians) and its cost."""
    x, z, mapping = state
    step = _damped_step(gram, values, coupling, grad, damping, x.size)
    z_new = z + step[x.size:x.size + problem.knots]
    map_new = mapping + step[x.size + problem.knots:]
    x_new, lin = problem.states_for(z_new, map_new, x + step[:x.size])
    res, a_x, a_z, a_s = problem.system(x_new, z_new, map_new, lin)
    return (x_new, z_new, map_new, res, a_x, a_z, a_s, lin.band), float(res @ res)


def _gauss_newton(problem: _Problem, x: np.ndarray, z: np.ndarray, mapping: np.ndarray,
                  iterations: int, lin: _Linear, damping: float,
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, int]:
    """Damped Gauss-Newton from (states, log psi knots, static map) under the problem's
    present prior weights, the damping starting at ``damping``: the optimum, its cost and the
    iterations taken."""
    res, a_x, a_z, a_s = problem.system(x, z, mapping, lin)
    band = lin.band  # a_x'a_x (lin: states_for's at z and mapping, which x was solved from)
    cost = float(res @ res)
    done = 0
    while done < iterations:
        done += 1
        sparse = sp.hstack([a_x, a_z]).tocsc()
        coupling = np.vstack([sparse.T @ a_s, a_s.T @ a_s])
        grad = np.concatenate([sparse.T @ res, a_s.T @ res])
        gram = problem.joint_gram_of(sparse)
        attempt = functools.partial(_trial, problem, (x, z, mapping), gram,
                                    gram.values(sparse.data, band), coupling, grad)
        tried = damping
        accepted, cost_new, damping = damped_search(attempt, cost, damping, 10)
        if accepted is None:
            break
        gain = cost - cost_new
        x, z, mapping, res, a_x, a_z, a_s, band = accepted
        cost = cost_new
        if damping == tried:  # taken at once: lower it (else keep the damping that was taken)
            damping = max(damping / 10.0, _DAMPING_FLOOR)
        if gain < max(1e-7 * (cost + gain), _COST_TOLERANCE):
            break
    return x, z, mapping, cost, done


@reused
def map_psi(t: np.ndarray, y1: np.ndarray, y2: np.ndarray, stages1: Sequence[float],
            stages2: Sequence[float], static: tuple[float, float], sigma: tuple[float, float],
            q: float, spacing: int, step_std: float, iterations: int = 30,
            reweightings: int = 0, level_std: float = 0.5) -> PsiMap:
    """The MAP schedule (module docstring). ``stages_i``: stage time constants at psi = 1, the
    stage that sees the gas first; ``static`` the start of y2 = gain x + offset; ``q`` the gas
    random walk's intensity (K^2/s); ``spacing`` rows between knots; ``step_std`` the prior
    standard deviation of log psi from knot to knot. psi starts at 1 (starting at the true psi
    gave the same optimum on a drive cycle: the start does not matter there).

    ``reweightings`` > 0 makes both priors heavy-tailed (Cauchy, by iteratively reweighted
    least squares from the last optimum): a gas increment ``dg`` over ``h`` is weighted
    ``1 / sqrt(q h + dg^2)`` and a knot step ``dz`` of log psi ``1 / sqrt(step_std^2 + dz^2)``
    up to ``|dz|`` = ``_STEP_CAP``, and as that one beyond it.
    Why: at load steps the gas moves by tens of kelvin and psi by a factor of 2 within a
    second, which Gaussian random walks make many-sigma events, so the MAP smeared psi there
    (README, "Heavy-tailed priors in the MAP").

    ``level_std`` (with ``reweightings``): every knot's log psi also gets a weak Gaussian prior
    about the median of the Gaussian-prior optimum. Why: where the gas stands still psi is
    unobservable, and the heavy-tailed steps let it drift without bound; at a 22 s idle start
    of a 30 min record log psi went to -5.4 (a 4 s element read as 1120 s, refused as
    implausible). An exhaust's velocity spans about 10x, so log psi stays within +-0.8 of its
    median for m up to 0.7: sd 0.5 costs that range at most 2.6 per knot, little beside the
    rows that observe it. Not 1 (until 2026-12-02): where the two readings cross while the
    gas holds (y1 - y2 and both slopes near 0), psi is unobservable for a few seconds, and
    there it went 17x above the truth and back (a 3.3 s element read as 56 s, the per-row
    time constants 74 % RMS off, the gas unaffected at 2.00x the oracle); at 0.5: 13 % (9.8 %
    with _STEP_CAP), and 36 sweep pairs within 0.03x of before or better (README). The
    median, not 0 (the stages' level), so that stages given at another level do not pull psi
    (on that record both gave the same fit, 9.1 times the noise; the drifting psi's 1.2 was
    an artefact: its 1/psi up to 230 at the start filled the misfit's noise term, and
    without those 30 s it misfit by 15.5)."""
    problem = _Problem(np.asarray(t, float), (np.asarray(y1, float), np.asarray(y2, float)),
                       (np.asarray(stages1, float), np.asarray(stages2, float)), sigma, q,
                       spacing, step_std)
    z = np.zeros(problem.knots)
    mapping = np.array(static, dtype=float)
    x, lin = problem.states_for(z, mapping, np.zeros(problem.n * problem.nx))
    x, z, mapping, cost, done = _gauss_newton(problem, x, z, mapping, iterations, lin,
                                              _DAMPING_START)
    for _ in range(reweightings):
        gas = x.reshape(problem.n, problem.nx)[:, 0]
        problem.prior = 1.0 / np.sqrt(q * problem.h + np.diff(gas) ** 2)
        problem.step = 1.0 / np.sqrt(step_std ** 2 + np.minimum(np.diff(z) ** 2, _STEP_CAP ** 2))
        problem.level, problem.centre_z = 1.0 / level_std, float(np.median(z))
        x, lin = problem.states_for(z, mapping, x)
        x, z, mapping, cost, more = _gauss_newton(problem, x, z, mapping, iterations, lin,
                                                  _DAMPING_RESTART)
        done += more
    zeta = problem.zeta(z)
    psi = np.exp(np.interp(np.arange(problem.n), np.arange(problem.n - 1) + 0.5, zeta))
    return PsiMap(psi, (float(mapping[0]), float(mapping[1])), cost, done)
