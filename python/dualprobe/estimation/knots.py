"""The knot system of the tracked cross-relation: its moments, assembled once per static map.

The scheduled cross-relation with psi expanded in hat functions of time (knots every
``spacing`` samples, :mod:`dualprobe.estimation.tracking`) has one filtered static column
``F(B_k d)`` per knot k, with d the static signal ``g T2 + o - T1``, beside a few dense
derivative columns. Its moments (banded knot block, knot-by-dense cross block, dense block,
the noise covariance and the start-up projection) are what the tracker's eigenproblem needs.

The static signal is linear in the static map, ``d = g T2 + o 1 - T1``, and the filter is
linear, so the moments are a quadratic form in (g, o, -1) over the moments of the three parts
T2, 1 and T1 (:class:`KnotParts`); the dense columns of sensor 2 scale with g. The static
search (``tracking.search_static``) filters the knot columns once and evaluates every trial
map from the parts, instead of filtering them again per trial.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

# Filter of the SVF on a batch of rows: (R, L) inputs -> (R, L) outputs x_0 = F u, the filter
# at rest before each row (supplied by the engine: the compiled core's cascade).
RowFilter = Callable[[np.ndarray], np.ndarray]

_MAX_KNOT_ELEMENTS = 4_000_000  # knot columns filtered per batch (memory: 32 MB of doubles)


@dataclass(frozen=True)
class KnotSystem:
    """Moments of the time-knot cross-relation: dense derivative columns first (D), then one
    static column per knot (K). ``band[j, k]`` = S[knot k, knot k + j]; ``cross`` (K, D);
    ``dense`` (D, D); noise: ``noise_dense`` (D, D), ``noise_cross`` (K, D),
    ``noise_band`` (2, K) (tridiagonal knot block); ``projection`` the start-up transients'
    moments (S_zb (D + K, m), S_bb (m, m)), projected out of S."""

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


@dataclass(frozen=True)
class KnotLayout:
    """Where each knot column lies: column k on rows ``start[k]`` to ``start[k] + length - 1``
    (those in the record), ``start[k + 1] = start[k] + spacing``; a knot's hat function peaks
    one spacing into its window and the rest is the filter's tail."""

    samples: int
    spacing: int
    knots: int
    length: int
    start: np.ndarray

    @property
    def reach(self) -> int:
        """Diagonals of the knot block whose windows overlap (the block's band)."""
        return math.ceil(self.length / self.spacing)

    def batches(self, elements: int) -> Iterator[tuple[int, int, int]]:
        """(first, last, extended): knots [first, last) a batch, about ``elements`` window
        entries each, with the neighbours up to ``extended`` that their band reaches."""
        batch = max(self.reach, elements // self.length)
        for first in range(0, self.knots, batch):
            last = min(first + batch, self.knots)
            yield first, last, min(last + self.reach, self.knots)

    def hats(self, first: int, last: int
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(rows, valid, clipped, hat) over the windows of knots [first, last): each window
        entry's row, whether it lies in the record, the row clipped into it, and the hat
        functions (0 outside)."""
        pos = self.start[first:last, None] + np.arange(self.length)[None, :]
        valid = (pos >= 0) & (pos < self.samples)
        centre = self.start[first:last, None] + self.spacing
        hat = np.where(valid, np.maximum(0.0, 1.0 - np.abs(pos - centre) / self.spacing), 0.0)
        return pos, valid, np.clip(pos, 0, self.samples - 1), hat


def knot_layout(samples: int, spacing: int, tail: int) -> KnotLayout:
    """Knots every ``spacing`` samples over the record, each column ``tail`` samples of filter
    memory past its hat function."""
    knots = math.ceil((samples - 1) / spacing) + 1
    start = (np.arange(knots) - 1) * spacing  # support of knot k begins at knot k - 1
    return KnotLayout(samples, spacing, knots, 2 * spacing + tail, start)


def overlap_band(left: np.ndarray, right: np.ndarray, spacing: int, width: int,
                 rows: int) -> np.ndarray:
    """``band[j, k]`` = <window k of ``left``, window k + j of ``right``> for windows (one a
    row) that start ``spacing`` apart, k < ``rows`` (the first windows; the rest are the
    neighbours they reach), j < ``width``: the band of a knot block, one row-wise dot per
    diagonal. A sparse product of the same columns took 3.3x as long (24,000 rows, 729
    knots)."""
    count, length = left.shape
    band = np.zeros((width, rows))
    for j in range(min(width, count)):
        shift = j * spacing
        reach = min(rows, count - j)
        band[j, :reach] = np.einsum("kl,kl->k", left[:reach, shift:],
                                    right[j : j + reach, : length - shift])
    return band


@dataclass(frozen=True)
class KnotParts:
    """The knot system's moments per part of the static signal ``d = sum_p c_p parts[p]``:
    ``band[p, q, j, k]`` = <column k of part p, column k + j of part q>, ``cross[p]`` (K, D),
    ``knot_start[p]`` (K, m) the knot columns' start-up moments; the dense columns' own moments
    ``dense`` (D, D), ``dense_start`` (D, m), ``dense_weights`` (D, D) the Gram of their noise
    weights; the hat functions' noise moments ``hat_cross`` (K, D) and ``hat_band`` (2, K)."""

    spacing: int
    knots: int
    samples: int
    band: np.ndarray
    cross: np.ndarray
    knot_start: np.ndarray
    dense: np.ndarray
    dense_start: np.ndarray
    dense_weights: np.ndarray
    hat_cross: np.ndarray
    hat_band: np.ndarray
    gram: np.ndarray

    def system(self, combination: Sequence[float], dense_scale: np.ndarray,
               row_noise: np.ndarray) -> KnotSystem:
        """The knot system of ``d = sum_p combination[p] parts[p]`` with the dense columns
        scaled by ``dense_scale`` (D,) and the stationary per-row noise covariance
        ``row_noise`` (D + 1, D + 1) of the unscheduled columns (static last)."""
        c = np.asarray(combination, dtype=float)
        scale = np.asarray(dense_scale, dtype=float)
        d_count = self.dense.shape[0]
        band = np.einsum("p,q,pqjk->jk", c, c, self.band)
        cross = np.einsum("p,pkd->kd", c, self.cross) * scale[None, :]
        z_b = np.vstack([self.dense_start * scale[:, None],
                         np.einsum("p,pkm->km", c, self.knot_start)])
        dense = self.dense * np.outer(scale, scale)
        noise_dense = self.dense_weights * row_noise[:d_count, :d_count]
        noise_cross = self.hat_cross * row_noise[:d_count, d_count][None, :]
        noise_band = self.hat_band * row_noise[d_count, d_count]
        return KnotSystem(self.spacing, self.knots, self.samples, band, cross, dense,
                          noise_dense, noise_cross, noise_band, (z_b, self.gram))


def knot_parts(
    dense_columns: np.ndarray,
    dense_weights: np.ndarray,
    parts: Sequence[np.ndarray],
    spacing: int,
    tail: int,
    row_filter: RowFilter,
    free_responses: np.ndarray,
) -> KnotParts:
    """Filter the knot columns of each part once and take their moments.

    ``dense_columns`` (D, N): the derivative columns of the cross-relation (filtered, signed);
    ``dense_weights`` (D, N): their noise weights (1, or phi for the order-2 columns);
    ``parts`` (P of (N,)): signals whose combination is the static signal (T2 - T1, or T2, 1
    and T1); ``free_responses`` (m, K0): the filter's free responses over the first rows
    (projected out).
    """
    d_count, samples = dense_columns.shape
    count = len(parts)
    layout = knot_layout(samples, spacing, tail)
    knots, band_width = layout.knots, layout.reach
    band = np.zeros((count, count, band_width, knots))
    cross = np.zeros((count, knots, d_count))
    basis_rows = free_responses.shape[1]
    knot_start = np.zeros((count, knots, free_responses.shape[0]))
    hat_cross = np.zeros((knots, d_count))
    hat_band = np.zeros((2, knots))
    for first, last, extended in layout.batches(_MAX_KNOT_ELEMENTS // count):
        pos, valid, clipped, hat = layout.hats(first, extended)
        columns = [row_filter(hat * part[clipped]) * valid for part in parts]
        own = last - first
        dense_here = dense_columns[:, clipped[:own]]
        for p, col in enumerate(columns):
            cross[p, first:last] = np.einsum("kl,dkl->kd", col[:own], dense_here)
        hat_cross[first:last] = np.einsum("kl,dkl->kd", hat[:own],
                                          dense_weights[:, clipped[:own]])
        hat_band[:, first:last] = overlap_band(hat, hat, spacing, 2, own)
        for p, col_p in enumerate(columns):
            for q, col_q in enumerate(columns):
                band[p, q, :, first:last] = overlap_band(col_p, col_q, spacing, band_width, own)
        early = np.flatnonzero(layout.start[first:last] < basis_rows)
        if early.size:
            inside = np.clip(pos[early], 0, basis_rows - 1)
            mask = valid[early] & (pos[early] < basis_rows)
            for p, col in enumerate(columns):
                knot_start[p, first + early] = np.einsum(
                    "kl,mkl->km", col[early] * mask, free_responses[:, inside])
    return KnotParts(
        spacing, knots, samples, band, cross, knot_start,
        dense=dense_columns @ dense_columns.T,
        dense_start=dense_columns[:, :basis_rows] @ free_responses.T,
        dense_weights=dense_weights @ dense_weights.T,
        hat_cross=hat_cross, hat_band=hat_band,
        gram=free_responses @ free_responses.T)


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
    """The knot system of one static signal ``difference`` (:func:`knot_parts` with one part;
    ``row_noise`` (D + 1, D + 1): the stationary per-row noise covariance of the unscheduled
    columns, static last)."""
    parts = knot_parts(dense_columns, dense_weights, [difference], spacing, tail, row_filter,
                       free_responses)
    return parts.system([1.0], np.ones(dense_columns.shape[0]), row_noise)


def sparse_system(system: KnotSystem) -> tuple[sp.csc_matrix, sp.csc_matrix, sp.csc_matrix]:
    """(S, C, R) as sparse matrices in the order [dense columns, knots]; S with the start-up
    transients projected out, R the first-difference penalty on the knot coefficients."""
    k = system.knots
    d = system.dense.shape[0]
    # a band wider than the knots (a short record: 90 s at 10 Hz has fewer knots than its
    # windows' reach) has no diagonals beyond the last knot
    width = min(system.band.shape[0], k)
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
