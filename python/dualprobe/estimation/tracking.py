"""Time constants that vary without a flow signal: a regularised cross-relation in time.

When no flow signal is given, the common factor of both sensors' time constants is tracked
over the record with their ratio held constant (paper eq. 5): ``tau_i(t) = tau_i / psi(t)``.
The scheduled cross-relation (design.md 1.5), ``psi (T2 - T1) = tau1 T1' - tau2 T2'`` (order 1;
order 2 adds ``d_i (phi T_i')'``), is linear in the unknowns when psi is expanded in hat
functions of time, ``psi(t) = sum_k a_k B_k(t)`` with knots every ``spacing`` samples: the
static column becomes one filtered column ``F(B_k (T2 - T1))`` per knot, the derivative
columns stay. The generalised TLS over all columns with a penalty on the first differences of
a (a random walk of psi), ``min v' (S + lambda R) v / v' C v``, is a sparse generalised
eigenproblem (banded knot block, a few dense derivative columns), solved by shift-invert
Lanczos. The penalty weight follows the discrepancy principle: the largest lambda whose
normalised misfit mu stays within the noise band of the best attainable fit, so the tracked
psi is as smooth as the data allow and exactly constant when the time constants do not vary.

Measured (simulated 30-min drive cycles, 10 Hz, 0.05 K, m = 0.5, ratio 3): the tracked element
time constants within 5-6 % RMS of the truth, reconstruction 1.15 K against the oracle's 0.87 K
and 8.6 K with constant time constants.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.optimize
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from dualprobe.estimation import engine


class TrackingError(RuntimeError):
    """The tracker found no solution (the caller keeps constant time constants)."""


# Filter of the SVF on a batch of rows: (R, L) inputs -> (R, L) outputs x_0 = F u, the filter
# at rest before each row (supplied by the engine: the compiled core's cascade).
RowFilter = Callable[[np.ndarray], np.ndarray]

_DENSE_LIMIT = 3000  # knots + derivative columns solved densely when Lanczos fails
_TAIL = 34.0  # filter memory kept per knot column, in tf: exp(-34) ~ 2e-15 of its peak
_MAX_KNOT_ELEMENTS = 4_000_000  # knot columns filtered per batch (memory: 32 MB of doubles)


@dataclass(frozen=True)
class KnotSystem:
    """Moments of the time-knot cross-relation: dense derivative columns first (D), then one
    static column per knot (K). ``band[j, k]`` = S[knot k, knot k + j]; ``cross`` (K, D);
    ``dense`` (D, D); noise: ``noise_dense`` (D, D), ``noise_cross`` (K, D),
    ``noise_band`` (2, K) (tridiagonal knot block); ``hat`` the knot weights at the samples."""

    spacing: int
    knots: int
    samples: int
    band: np.ndarray
    cross: np.ndarray
    dense: np.ndarray
    noise_dense: np.ndarray
    noise_cross: np.ndarray
    noise_band: np.ndarray
    projection: tuple[np.ndarray, np.ndarray]  # (S_zb (D + K, m), S_bb (m, m))

    def psi(self, coefficients: np.ndarray) -> np.ndarray:
        """psi at every sample from the knot coefficients (hat functions)."""
        position = np.arange(self.samples) / self.spacing
        return np.interp(position, np.arange(self.knots), coefficients)


def _knot_layout(samples: int, spacing: int, tail: int) -> tuple[int, int, np.ndarray]:
    knots = math.ceil((samples - 1) / spacing) + 1
    length = 2 * spacing + tail
    start = (np.arange(knots) - 1) * spacing  # support of knot k begins at knot k - 1
    return knots, length, start


def knot_system(
    dense_columns: np.ndarray,
    dense_weights: np.ndarray,
    difference: np.ndarray,
    spacing: int,
    tail: int,
    row_filter: RowFilter,
    free_responses: np.ndarray,
    row_noise: np.ndarray,
) -> KnotSystem:
    """Assemble the knot system.

    ``dense_columns`` (D, N): the derivative columns of the cross-relation (filtered, signed);
    ``dense_weights`` (D, N): their noise weights (1, or phi for the order-2 columns);
    ``difference`` (N,): the static signal (T2 - T1, or g T2 + o - T1) whose knot-weighted
    versions are filtered; ``free_responses`` (m, K0): the filter's free responses over the
    first rows (projected out); ``row_noise`` (D + 1, D + 1): the stationary per-row noise
    covariance of the unscheduled columns (static last).
    """
    d_count, samples = dense_columns.shape
    knots, length, start = _knot_layout(samples, spacing, tail)
    positions = np.arange(length)
    band_width = math.ceil(length / spacing)
    band = np.zeros((band_width, knots))
    cross = np.zeros((knots, d_count))
    basis_rows = free_responses.shape[1]
    z_b = np.zeros((d_count + knots, free_responses.shape[0]))
    z_b[:d_count] = dense_columns[:, :basis_rows] @ free_responses.T
    noise_cross = np.zeros((knots, d_count))
    noise_band = np.zeros((2, knots))
    batch = max(band_width, _MAX_KNOT_ELEMENTS // length)
    for first in range(0, knots, batch):
        last = min(first + batch, knots)
        extended = min(last + band_width, knots)  # neighbours the band pairs reach
        pos = start[first:extended, None] + positions[None, :]
        valid = (pos >= 0) & (pos < samples)
        clipped = np.clip(pos, 0, samples - 1)
        centre = start[first:extended, None] + spacing
        hat = np.where(valid, np.maximum(0.0, 1.0 - np.abs(pos - centre) / spacing), 0.0)
        columns = row_filter(hat * difference[clipped]) * valid
        own = last - first
        cross[first:last] = np.einsum("kl,dkl->kd", columns[:own], dense_columns[:, clipped[:own]])
        noise_cross[first:last] = np.einsum("kl,dkl->kd", hat[:own],
                                            dense_weights[:, clipped[:own]])
        noise_band[0, first:last] = np.sum(hat[:own] ** 2, axis=1)
        pairs = min(own, hat.shape[0] - 1)
        noise_band[1, first : first + pairs] = np.sum(
            hat[:pairs, spacing:] * hat[1 : pairs + 1, : length - spacing], axis=1)
        for j in range(min(band_width, hat.shape[0])):
            shift = j * spacing
            count = min(own, hat.shape[0] - j)
            band[j, first : first + count] = np.sum(
                columns[:count, shift:] * columns[j : j + count, : length - shift], axis=1)
        early = np.flatnonzero(start[first:last] < basis_rows)
        if early.size:
            inside = np.clip(pos[early], 0, basis_rows - 1)
            mask = valid[early] & (pos[early] < basis_rows)
            z_b[d_count + first + early] = np.einsum(
                "kl,mkl->km", columns[early] * mask, free_responses[:, inside])
    dense = dense_columns @ dense_columns.T
    noise_dense = (dense_weights @ dense_weights.T) * row_noise[:d_count, :d_count]
    noise_cross = noise_cross * row_noise[:d_count, d_count][None, :]
    noise_band = noise_band * row_noise[d_count, d_count]
    gram = free_responses @ free_responses.T
    return KnotSystem(spacing, knots, samples, band, cross, dense, noise_dense, noise_cross,
                      noise_band, (z_b, gram))


def _sparse_system(system: KnotSystem) -> tuple[sp.csc_matrix, sp.csc_matrix, sp.csc_matrix]:
    """(S, C, R) as sparse matrices in the order [dense columns, knots]; S with the start-up
    transients projected out, R the first-difference penalty on the knot coefficients."""
    k = system.knots
    d = system.dense.shape[0]
    width = system.band.shape[0]
    upper = sp.diags([system.band[j, : k - j] for j in range(width)], list(range(width)),
                     shape=(k, k))
    knot_block = (upper + sp.triu(upper, 1).T).tocsc()
    s = sp.bmat([[sp.csc_matrix(system.dense), sp.csc_matrix(system.cross.T)],
                 [sp.csc_matrix(system.cross), knot_block]]).tocsc()
    z_b, gram = system.projection
    used = np.flatnonzero(np.any(z_b != 0.0, axis=1))
    if used.size:
        correction = z_b[used] @ np.linalg.solve(gram, z_b[used].T)
        rows, cols = np.meshgrid(used, used, indexing="ij")
        s = (s - sp.csc_matrix((correction.ravel(), (rows.ravel(), cols.ravel())),
                               shape=s.shape)).tocsc()
    knot_noise = sp.diags([system.noise_band[1, : k - 1], system.noise_band[0],
                           system.noise_band[1, : k - 1]], [-1, 0, 1], shape=(k, k))
    c = sp.bmat([[sp.csc_matrix(system.noise_dense), sp.csc_matrix(system.noise_cross.T)],
                 [sp.csc_matrix(system.noise_cross), knot_noise]]).tocsc()
    diff = sp.diags([np.ones(k - 1), -np.ones(k - 1)], [0, 1], shape=(k - 1, k))
    r = sp.block_diag([sp.csc_matrix((d, d)), (diff.T @ diff)]).tocsc()
    return s, c, r


@dataclass(frozen=True)
class TrackSolution:
    penalty: float
    misfit: float  # smallest generalised eigenvalue (1: the noise level)
    vector: np.ndarray  # [dense coefficients, knot coefficients], psi normalised to mean 1


def solve_penalised(system: KnotSystem, penalty: float,
                    matrices: tuple[sp.csc_matrix, sp.csc_matrix, sp.csc_matrix] | None = None,
                    ) -> TrackSolution:
    """Smallest generalised eigenpair of ``(S + penalty R) v = mu C v`` (diagonally scaled;
    ``penalty`` relative to the scaled data term)."""
    s, c, r = matrices if matrices is not None else _sparse_system(system)
    scale = 1.0 / np.sqrt(np.maximum(s.diagonal(), np.finfo(float).tiny))
    dm = sp.diags(scale)
    a = (dm @ (s + penalty * r) @ dm).tocsc()
    m = (dm @ c @ dm).tocsc()
    m = m + sp.diags(1e-12 * max(float(m.diagonal().mean()), 1e-300) * np.ones(m.shape[0]))
    if not (np.all(np.isfinite(a.data)) and np.all(np.isfinite(m.data))):
        raise TrackingError("the tracking system is not finite (no excitation somewhere)")
    try:
        values, vectors = spl.eigsh(a, k=1, M=m, sigma=0.0, which="LM")
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


def choose_penalty(
    system: KnotSystem, effective_rows: float, *, band: float = 2.0,
    bounds: tuple[float, float] = (1e-3, 1e7), steps: int = 14,
) -> tuple[TrackSolution, TrackSolution, TrackSolution]:
    """(chosen, freest, stiffest): the discrepancy principle on log penalty. The chosen penalty
    is the largest whose misfit stays within ``band`` noise standard deviations
    (``sqrt(2 / effective_rows)`` relative) of the freest fit's (floored at 1, the noise)."""
    matrices = _sparse_system(system)
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


@dataclass(frozen=True)
class Tracking:
    """Time constants tracked over the record with their ratio constant.

    ``psi`` (N,) the common factor (mean 1): the time constants at row k are
    ``time_constants / psi[k]``; ``time_constants`` per sensor (order 2: both stages) at
    psi = 1; ``misfit`` the tracked fit's smallest generalised eigenvalue, ``misfit_constant``
    the same model's with psi constant (the stiffest penalty); ``spacing`` knots in samples."""

    psi: np.ndarray
    time_constants: tuple[tuple[float, ...], tuple[float, ...]]
    polynomials: tuple[tuple[float, ...], tuple[float, ...]]
    penalty: float
    misfit: float
    misfit_constant: float
    misfit_free: float
    spacing: int

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


def _setup(t1: np.ndarray, ts: float, tf: float, order: int
           ) -> tuple[int, int, RowFilter, np.ndarray]:
    """(knot spacing, filter tail, the row filter, the free responses) of a record."""
    from dualprobe import _core

    m = order + 1

    def row_filter(rows: np.ndarray) -> np.ndarray:
        return _core.svf_filter(rows, ts, tf, m, "foh")[:, 0, :]

    spacing = max(1, round(_SPACING_OF_TF * tf / ts))
    return spacing, math.ceil(_TAIL * tf / ts), row_filter, _free_responses(ts, tf, m, t1.size)


def search_static(
    t1: np.ndarray, t2: np.ndarray, ts: float, *, tf: float, sigma: tuple[float, float],
    start: tuple[float, float], max_evaluations: int = 80,
) -> tuple[float, float]:
    """The static map (g, o) of sensor 2 onto sensor 1 for tracking (order 1): the minimum of
    the tracked misfit at a fixed penalty (``_STATIC_SEARCH_PENALTY``) over (g, o), by
    Nelder-Mead from ``start`` (e.g. windowed constant fits, whose medians are within ~1e-3)."""
    u1 = np.asarray(t1, dtype=float)
    spacing, tail, row_filter, free = _setup(u1, ts, tf, 1)
    ones = np.ones(u1.size)

    def misfit(x: np.ndarray) -> float:
        gain, offset = float(x[0]), float(x[1])
        if not gain > 0.0:
            return math.inf
        u2 = gain * np.asarray(t2, dtype=float) + offset
        noise = _row_noise(ts, tf, 1, (sigma[0], gain * sigma[1]))
        dense, weights = _dense_columns(u1, u2, ts, tf, 1, ones)
        system = knot_system(dense, weights, u2 - u1, spacing, tail, row_filter, free, noise)
        try:
            return solve_penalised(system, _STATIC_SEARCH_PENALTY).misfit
        except TrackingError:
            return math.inf

    g0, o0 = start
    span = max(float(np.std(u1)), 1e-3)  # offset steps in the data's own scale
    simplex = np.array([[g0, o0], [g0 * 1.004, o0], [g0, o0 + 0.01 * span]])
    result = scipy.optimize.minimize(misfit, x0=np.array([g0, o0]), method="Nelder-Mead",
                                     options={"initial_simplex": simplex, "xatol": 1e-5,
                                              "fatol": 1e-3, "maxfev": max_evaluations})
    return float(result.x[0]), float(result.x[1])


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
) -> Tracking:
    """Track the common factor of both sensors' time constants over the record (module
    docstring). ``static`` = (g, o): sensor 2 mapped to sensor 1's calibration, g T2 + o;
    ``effective_rows`` sets the discrepancy band; order 2 refines phi = 1/psi in ``passes``."""

    gain, offset = static
    u2 = gain * np.asarray(t2, dtype=float) + offset
    u1 = np.asarray(t1, dtype=float)
    s = (sigma[0], gain * sigma[1])
    spacing, tail, row_filter, free = _setup(u1, ts, tf, order)
    phi = np.ones(u1.size)
    # order 2: a first-order pass gives phi for the second-order columns, then refine
    for current in [1] * (order == 2) + [order] * (passes if order == 2 else 1):
        noise = _row_noise(ts, tf, current, s)
        dense, weights = _dense_columns(u1, u2, ts, tf, current, phi)
        system = knot_system(dense, weights, u2 - u1, spacing, tail, row_filter, free, noise)
        chosen, freest, stiffest = choose_penalty(system, effective_rows)
        psi = system.psi(-chosen.vector[dense.shape[0]:])
        phi = 1.0 / np.maximum(psi, 1e-3)
    coefficients = chosen.vector[: dense.shape[0]]
    polys = []
    for i in range(2):
        c = coefficients[order * i : order * (i + 1)] * tf ** np.arange(1, order + 1)
        polys.append(tuple(float(v) / (gain if i else 1.0) for v in c))
    taus = tuple(engine.polynomial_time_constants(p) for p in polys)
    return Tracking(psi, (taus[0], taus[1]), (polys[0], polys[1]), chosen.penalty,
                    chosen.misfit, stiffest.misfit, freest.misfit, spacing)
