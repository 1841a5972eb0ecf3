"""Sheathed pairs without a flow signal: one fit of the cross-relation in the static map, both
sensors' second-order coefficients and log psi at knots.

The scheduled cross-relation (design.md 1.5) of two second-order sensors with time constants
``tau / psi(t)``, in SVF-filtered form (filter F of time constant tf):

    F[psi (g T2 + o - T1)] = a1 F'T1 + b1 F'[phi T1'] - a2 F'T2 - b2 F'[phi T2'],  phi = 1/psi

is linear in (g, o, a, b) for a known psi and in psi's knot values for known coefficients, but
not in both. :mod:`dualprobe.estimation.tracking` solves the first-order version as one
eigenproblem; with the second-order terms it degenerates on sheathed pairs (psi near 0 with
spikes), and a second-order refit on its psi needs psi within ~1 %. Here all unknowns are
fitted together by Levenberg-Marquardt, psi = exp(z) (positive by construction, phi =
exp(-z) consistent with it), a random-walk penalty on z and its mean fixed at 0 (the scale
belongs to the coefficients). The fit gives the stage time constants; psi itself is then
refined by :mod:`dualprobe.estimation.psi_map`, which weighs every row by its own noise.

Measured on six sheathed 30-min drive cycles (10 Hz, 0.05 K): sheath stages 0.59 s for a true
0.61 (0.115 for 0.19: a short sheath behind a 5 s element is weakly seen); with psi refined
and the engine's refit, the gas at 1.2-2.1x the oracle's error (near-equal sheaths 3.7x).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from dualprobe.estimation.banded import lower_band
from dualprobe.estimation.damping import damped_search
from dualprobe.estimation.knots import KnotLayout, knot_layout, overlap_band
from dualprobe.estimation.reuse import reused

__all__ = ["CrossFit", "fit_cross_relation"]

_ORDER = 3  # SVF order: second-order sensors need F, F' and F'' of the signals
_TAIL = 34.0  # filter memory kept per knot column, in tf (as in tracking)
_MAX_KNOTS = 3000  # long records get wider knots (set when the normal matrix was dense;
# kept, so results are unchanged, now that it is solved banded: _Normal)
_START_WEIGHT = 40.0  # tf: rows inside the filter's start-up transient get no weight
_PENALTIES = (1000.0, 300.0)  # random-walk weights on z, stiff first (a safe start), then final
_Z_LIMIT = 3.0  # |log psi| <= 3: time constants vary by at most e^3 about their mean


@dataclass(frozen=True)
class CrossFit:
    """``stages`` per sensor (the slow element first, then the sheath, 0 if none) at psi = 1,
    ``static`` (gain, offset) with T1 = gain T2 + offset, ``psi`` (N,), the final weighted cost
    and the iterations taken."""

    stages: tuple[tuple[float, float], tuple[float, float]]
    static: tuple[float, float]
    psi: np.ndarray
    cost: float
    iterations: int


_WINDOW_ELEMENTS = 2_000_000  # knot-column window entries a batch (16 MB of doubles)


def _knot_columns(signal: np.ndarray, layout: KnotLayout, hold: str, output: int,
                  ts: float, tf: float) -> sp.csc_matrix:
    """Filtered hat-weighted copies of ``signal``, one sparse column per knot."""
    from dualprobe import _core

    rows, cols, vals = [], [], []
    for first, last, _ in layout.batches(_WINDOW_ELEMENTS):
        pos, valid, clipped, hat = layout.hats(first, last)
        filtered = _core.svf_filter(hat * signal[clipped], ts, tf, _ORDER, hold)[:, output, :]
        owner = np.broadcast_to(np.arange(first, last)[:, None], pos.shape)
        rows.append(pos[valid])
        cols.append(owner[valid])
        vals.append(filtered[valid])
    return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(signal.size, layout.knots))


def _windows(knots: sp.csc_matrix, layout: KnotLayout, first: int, last: int,
             scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Columns [first, last) of ``knots`` (canonical: one entry per row and column) as dense
    windows over their layout rows: each entry times ``scale`` of its row, and as it stands.
    Both from one set of flat positions (a flat scatter; the two-index one and its repetition
    for the second window were 10 of 117 s of a 50 Hz record's characterisation)."""
    lo, hi = knots.indptr[first], knots.indptr[last]
    column = np.repeat(np.arange(last - first), np.diff(knots.indptr[first : last + 1]))
    rows = knots.indices[lo:hi]
    flat = column * layout.length + (rows - layout.start[first + column])
    values = knots.data[lo:hi]
    scaled, bare = (np.zeros((last - first, layout.length)) for _ in range(2))
    scaled.reshape(-1)[flat] = values * scale[rows]
    bare.reshape(-1)[flat] = values
    return scaled, bare


def _gram_band(knots: sp.csc_matrix, weights: np.ndarray, layout: KnotLayout) -> np.ndarray:
    """The lower band of the knot columns' weighted Gram K' W K in LAPACK's banded storage
    (``band[d, j]`` = <column j + d, W column j>), from the columns as dense windows
    (:func:`knots.overlap_band`, batched as the columns were built). The sparse product took
    14 of the fit's 20 s on a 20 Hz record."""
    if not knots.has_canonical_format:  # windows are assigned, so duplicates must be summed
        knots = knots.copy()
        knots.sum_duplicates()
    k = knots.shape[1]
    width = min(k, layout.reach)
    band = np.zeros((width, k))
    for first, last, extended in layout.batches(_WINDOW_ELEMENTS):
        weighted, bare = _windows(knots, layout, first, extended, weights)
        band[:, first:last] = overlap_band(weighted, bare, layout.spacing, width, last - first)
    return band


class _Columns:
    def __init__(self, t1: np.ndarray, t2: np.ndarray, ts: float, tf: float, spacing: int) -> None:
        from dualprobe import _core

        self.layout = knot_layout(t1.size, spacing, math.ceil(_TAIL * tf / ts))
        self.ref = float(t1[0])
        self.x1, self.x2 = (_core.svf_filter(x - x[0], ts, tf, _ORDER, "foh")[0][1]
                            for x in (t1, t2))
        drives = []
        for x in (t1, t2):
            d = np.zeros(x.size)
            d[:-1] = np.diff(x) * (tf / ts)  # the derivative as a zero-order-held drive
            drives.append(_knot_columns(d, self.layout, "zoh", 1, ts, tf))
        self.y1, self.y2 = drives
        self.k1 = _knot_columns(t1 - self.ref, self.layout, "foh", 0, ts, tf)
        self.k2 = _knot_columns(t2 - self.ref, self.layout, "foh", 0, ts, tf)
        self.k0 = _knot_columns(np.ones(t1.size), self.layout, "foh", 0, ts, tf)
        self.knots = self.layout.knots

    def residual(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        g, o, a1, a2, b1, b2 = p[:6]
        psi, phi = np.exp(p[6:]), np.exp(-p[6:])
        static = g * (self.k2 @ psi) + o * (self.k0 @ psi) - self.k1 @ psi
        dyn = a1 * self.x1 + b1 * (self.y1 @ phi) - a2 * self.x2 - b2 * (self.y2 @ phi)
        return static - dyn, psi, phi

    def jacobian(self, p: np.ndarray, psi: np.ndarray, phi: np.ndarray
                 ) -> tuple[np.ndarray, sp.csc_matrix]:
        g, o, _, _, b1, b2 = p[:6]
        dense = np.column_stack([self.k2 @ psi, self.k0 @ psi, -self.x1, self.x2,
                                 -(self.y1 @ phi), self.y2 @ phi])
        knots = ((g * self.k2 + o * self.k0 - self.k1) @ sp.diags(psi)
                 + (b1 * self.y1 - b2 * self.y2) @ sp.diags(phi))
        return dense, knots.tocsc()


def _stage_pair(a: float, b: float) -> tuple[float, float]:
    """(slow, fast) time constants of 1 + a s + b s^2; a complex pair gives two equal halves
    (the nearest real pair), a negligible b a single stage."""
    if b <= 1e-6 * a * a:
        return a, 0.0
    disc = a * a - 4.0 * b
    if disc < 0.0:
        return a / 2.0, a / 2.0
    root = math.sqrt(disc)
    return (a + root) / 2.0, (a - root) / 2.0


class _Normal:
    """The damped normal equations of one Levenberg iteration, solved by their structure: six
    dense unknowns (g, o, a1, a2, b1, b2) bordering the knots' block, which is banded (each
    knot column reaches a filter tail's worth of its neighbours) plus the rank-one mean
    penalty. Banded Cholesky of the knot block and a 7 x 7 border system: O(K w^2) for K
    knots of band w, where the dense K x K solve was O(K^3) (0.35 s per trial at 1,200 knots,
    72 of the 188 s a 20-min record took)."""

    def __init__(self, dense: np.ndarray, knots: sp.csc_matrix, weights: np.ndarray,
                 rough: sp.spmatrix, penalty: float, mean: np.ndarray, stiff: float,
                 layout: KnotLayout) -> None:
        self.wd = dense * weights[:, None]  # the dense columns weighted (the gradient's too)
        self.a = dense.T @ self.wd
        self.b = np.asarray(knots.T @ self.wd)
        band = _gram_band(knots, weights, layout)
        # the random walk couples neighbours only: two diagonals, within the knot band (a
        # window spans more than two spacings)
        band[:2] += lower_band(penalty * rough)
        self.band = band
        self.mean, self.stiff = mean, stiff
        # the damping scales the full matrix's diagonal (the rank-one term's part included)
        self.diag = np.maximum(np.concatenate([np.diag(self.a), self.band[0]
                                               + stiff * mean * mean]), 1e-12)

    def solve(self, damp: float, grad: np.ndarray) -> np.ndarray:
        """(H + damp diag(H)) x = grad; LinAlgError when the knot block is not positive."""
        band = self.band.copy()
        band[0] += damp * self.diag[6:]
        factor = scipy.linalg.cholesky_banded(band, lower=True)
        g1, g2 = grad[:6], grad[6:]
        # y = M^-1 (g2 - B x - c u w) with w = u'y carried as a seventh border unknown
        rhs = np.column_stack([self.b, self.mean, g2])
        solved = scipy.linalg.cho_solve_banded((factor, True), rhs)
        mb, mu, mg = solved[:, :6], solved[:, 6], solved[:, 7]
        border = np.empty((7, 7))
        border[:6, :6] = self.a + np.diag(damp * self.diag[:6]) - self.b.T @ mb
        border[:6, 6] = -self.stiff * (self.b.T @ mu)
        border[6, :6] = self.mean @ mb
        border[6, 6] = 1.0 + self.stiff * (self.mean @ mu)
        rhs_border = np.concatenate([g1 - self.b.T @ mg, [self.mean @ mg]])
        # rows equilibrated: the stiff mean row is ~1e6 times the others, which alone made
        # LAPACK warn of ill-conditioning; one still ill-conditioned after that is a failed
        # step (the damping rises), not a warning on the user's screen (60 s drive cycles at
        # 10 Hz printed four; under pytest's filterwarnings = error they raised)
        scale = 1.0 / np.maximum(np.max(np.abs(border), axis=1), 1e-300)
        with warnings.catch_warnings():
            warnings.simplefilter("error", scipy.linalg.LinAlgWarning)
            try:
                xw = scipy.linalg.solve(border * scale[:, None], rhs_border * scale)
            except scipy.linalg.LinAlgWarning as ill:
                raise np.linalg.LinAlgError(str(ill)) from None
        y = mg - mb @ xw[:6] - self.stiff * mu * xw[6]
        return np.concatenate([xw[:6], y])


def _levenberg(cols: _Columns, p: np.ndarray, weights: np.ndarray, penalty: float,
               iterations: int) -> tuple[np.ndarray, float, int]:
    k = cols.knots
    walk = sp.diags([np.ones(k - 1), -np.ones(k - 1)], [0, 1], shape=(k - 1, k))
    rough = (walk.T @ walk).tocsc()
    mean = np.full(k, 1.0 / k)
    stiff = 1e6  # mean(z) = 0 as a stiff penalty (the scale is the coefficients')

    def cost(q: np.ndarray) -> float:
        r = cols.residual(q)[0]
        z = q[6:]
        return float(np.sum(weights * r * r) + penalty * z @ (rough @ z)
                     + stiff * (mean @ z) ** 2)

    f = cost(p)
    damping = 1e-3
    done = 0
    while done < iterations:
        done += 1
        r, psi, phi = cols.residual(p)
        dense, knots = cols.jacobian(p, psi, phi)
        normal = _Normal(dense, knots, weights, rough, penalty, mean, stiff, cols.layout)
        z = p[6:]
        grad = np.concatenate([normal.wd.T @ r,
                               knots.T @ (weights * r) + penalty * (rough @ z)
                               + stiff * mean * (mean @ z)])

        def attempt(damp: float, p: np.ndarray = p, normal: _Normal = normal,
                    grad: np.ndarray = grad) -> tuple[np.ndarray, float] | None:
            try:
                step = -normal.solve(damp, grad)
            except (np.linalg.LinAlgError, ValueError):
                return None
            trial = p + step
            trial[6:] = np.clip(trial[6:], -_Z_LIMIT, _Z_LIMIT)
            return trial, cost(trial)

        accepted, f_trial, damping = damped_search(attempt, f, damping, 12)
        if accepted is None:
            break
        gain = (f - f_trial) / f
        p, f = accepted, f_trial
        damping = max(damping / 5.0, 1e-9)
        if gain < 1e-7:
            break
    return p, f, done


@reused
def fit_cross_relation(t1: np.ndarray, t2: np.ndarray, ts: float, tf: float,
                       first_order: tuple[float, float], static: tuple[float, float],
                       iterations: int = 30) -> CrossFit:
    """The joint fit (module docstring) from a first-order constant fit: ``first_order`` its
    time constants, ``static`` its (gain, offset) with T1 = gain T2 + offset. Knots every tf/2
    (fewer on long records, at most ``_MAX_KNOTS``)."""
    a, b = np.asarray(t1, float), np.asarray(t2, float)
    n = a.size
    spacing = max(1, round(0.5 * tf / ts), math.ceil((n - 1) / (_MAX_KNOTS - 1)))
    cols = _Columns(a, b, ts, tf, spacing)
    weights = np.ones(n)
    weights[: math.ceil(_START_WEIGHT * tf / ts)] = 0.0
    gain, offset = static
    p = np.concatenate([[gain, offset - cols.ref * (1.0 - gain), first_order[0] / tf,
                         first_order[1] / tf * gain, 0.0, 0.0], np.zeros(cols.knots)])
    total = 0
    f = math.inf
    for penalty in _PENALTIES:
        p, f, used = _levenberg(cols, p, weights, penalty, iterations)
        total += used
    g = float(p[0])
    o = float(p[1]) + cols.ref * (1.0 - g)
    s1 = _stage_pair(float(p[2]) * tf, float(p[4]) * tf * tf)
    s2 = _stage_pair(float(p[3]) * tf / g, float(p[5]) * tf * tf / g)
    psi = np.interp(np.arange(n) / spacing, np.arange(cols.knots), np.exp(p[6:]))
    return CrossFit((s1, s2), (g, o), psi, f, total)
