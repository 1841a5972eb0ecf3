"""Sparse symmetric positive definite systems that are banded as their unknowns stand (states of
a time series, knots of a schedule): solved by banded Cholesky (LAPACK ``pbtrf`` through
:func:`scipy.linalg.cholesky_banded`), in O(N w^2) for N unknowns of half-bandwidth w.
SuperLU's fill-reducing ordering does not know the time axis. Used for the MAP of psi's
states row by row (:mod:`dualprobe.estimation.psi_map`), the cross-relation's knots
(:mod:`crossfit`) and the tracking pencil (:mod:`tracking`). Where a few unknowns each reach
many rows (psi's knots among the MAP's states) the band is wide but mostly zeros:
:mod:`dualprobe.estimation.sparse_ldl` factorises those."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spl

__all__ = ["GramBand", "Pattern", "band_solver", "bordered_solver", "by_target", "lower_band",
           "row_pairs"]


def lower_band(matrix: sp.spmatrix) -> np.ndarray:
    """The lower band of a symmetric sparse matrix in LAPACK's banded storage
    (``band[i - j, j] = matrix[i, j]``, i >= j), the unknowns in their order."""
    coo = sp.coo_matrix(matrix)
    row, col = coo.row, coo.col
    keep = row >= col
    offset, col = (row - col)[keep], col[keep]
    size = matrix.shape[0]
    width = int(offset.max(initial=0)) + 1
    # bincount sums duplicate entries as the matrix means them (np.add.at did, 5x slower)
    return np.bincount(offset * size + col, weights=coo.data[keep],
                       minlength=width * size).reshape(width, size)


def row_pairs(indices: np.ndarray, place: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Every pair of stored values of a sparse J (CSC row ``indices``) that share a row, once,
    as positions ``p``, ``q`` in J's stored values with ``place[p] > place[q]`` or ``p == q``
    (``place``: each stored value's unknown, in the order wanted): the pairs whose products
    sum to J'J's lower triangle in that order. Each (row, column) must be stored once."""
    by_row = np.argsort(indices, kind="stable")  # the stored values, row by row
    row = indices[by_row]
    starts = np.flatnonzero(np.r_[True, row[1:] != row[:-1]])
    lengths = np.diff(np.r_[starts, row.size])
    first, second = [], []
    longest = int(lengths.max(initial=0))
    for i in range(longest):
        for j in range(longest):
            rows = starts[lengths > max(i, j)]
            p, q = by_row[rows + i], by_row[rows + j]
            keep = place[p] > place[q] if i != j else np.ones(p.size, bool)
            first.append(p[keep])
            second.append(q[keep])
    return np.concatenate(first), np.concatenate(second)


def by_target(p: np.ndarray, q: np.ndarray, target: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs ``p``, ``q`` and the entry ``target`` each adds to, in the order of the
    targets, pairs of one target in the order given. Why: the gathers ``data[p]``,
    ``data[q]`` then run through memory nearly in order (0.6 times the time measured on a
    20 Hz sheathed record's J'J), while ``np.bincount`` still adds each entry's products in
    the order given, so the sums are bit for bit those of the unsorted pairs."""
    order = np.argsort(target, kind="stable")
    return p[order], q[order], target[order]


class Pattern:
    """A sparse J's fixed CSC structure (row ``indices``, column pointers ``indptr``, columns),
    against which a later J is checked before values computed for it are reused."""

    def __init__(self, indices: np.ndarray, indptr: np.ndarray, columns: int) -> None:
        self.indices, self.indptr = np.asarray(indices), np.asarray(indptr)
        self.size = columns

    def fits(self, matrix: sp.csc_matrix) -> bool:
        """Whether ``matrix`` (CSC) has this pattern."""
        return (matrix.shape[1] == self.size and np.array_equal(matrix.indptr, self.indptr)
                and np.array_equal(matrix.indices, self.indices))


class GramBand(Pattern):
    """The lower band of ``J' J`` (banded storage, as :func:`lower_band`) for every sparse ``J``
    of one fixed pattern, straight from J's stored values: no sparse product, no sorting. Why:
    a Gauss-Newton loop forms J'J of the same pattern at every trial; the product and the
    band's read-out were a third of the joint MAP's time (:mod:`psi_map`). Built from J's CSC
    structure (``indices``, ``indptr``), the unknowns in their order; the pattern must hold
    each (row, column) once, as CSC storage does."""

    def __init__(self, indices: np.ndarray, indptr: np.ndarray, columns: int) -> None:
        super().__init__(indices, indptr, columns)
        col = np.repeat(np.arange(columns), np.diff(self.indptr))
        self.p, self.q = row_pairs(self.indices, col)
        offset = col[self.p] - col[self.q]
        self.width = int(offset.max(initial=0)) + 1
        self.p, self.q, self.target = by_target(self.p, self.q, offset * columns + col[self.q])

    def band(self, data: np.ndarray) -> np.ndarray:
        """The lower band of J'J for J of this pattern with stored values ``data``."""
        return np.bincount(self.target, weights=np.take(data, self.p) * np.take(data, self.q),
                           minlength=self.width * self.size).reshape(self.width, self.size)


def band_solver(band: np.ndarray, matrix: Callable[[], sp.spmatrix]
                ) -> Callable[[np.ndarray], np.ndarray]:
    """A solver of ``matrix x = b`` (b a vector or columns) from its lower band
    (:func:`lower_band`; not changed) by banded Cholesky; ``matrix`` builds the sparse matrix
    for the fallback only: where the matrix is not numerically positive definite, or not
    finite, SuperLU's LU with pivoting (a nearly singular step is then rejected by its cost).
    Why from the band: it is often at hand already (:class:`GramBand`, straight from a
    Jacobian's values)."""
    try:
        factor = scipy.linalg.cholesky_banded(band, lower=True)
    except (np.linalg.LinAlgError, ValueError):
        lu = spl.splu(sp.csc_matrix(matrix()))
        return lu.solve
    return lambda rhs: scipy.linalg.cho_solve_banded((factor, True), rhs)


def bordered_solver(matrix: sp.csc_matrix, border: int) -> Callable[[np.ndarray], np.ndarray]:
    """A solver of ``matrix x = b`` (b a vector) for a sparse SPD matrix whose first ``border``
    unknowns reach all others and whose rest is banded as it stands (the cross-relation's
    derivative columns and its knots, :mod:`dualprobe.estimation.tracking`): the banded block
    by banded Cholesky, the border by its Schur complement. Where the block is not numerically
    positive definite, or the complement is singular, SuperLU's LU of the whole matrix. Why:
    SuperLU's factorisation of the tracking pencil was 58 ms a call (144 calls, 8 s on a 30 min
    10 Hz record); the band's is well under that."""
    a = sp.csc_matrix(matrix)
    if not 0 <= border < a.shape[0]:
        return spl.splu(a).solve
    block = a[border:, border:]
    cross = a[border:, :border].toarray()
    corner = a[:border, :border].toarray()
    try:
        factor = scipy.linalg.cholesky_banded(lower_band(block), lower=True)
        inner = scipy.linalg.cho_solve_banded((factor, True), cross)
        schur = scipy.linalg.cho_factor(corner - cross.T @ inner)
    except (np.linalg.LinAlgError, ValueError):
        return spl.splu(a).solve

    def solve(rhs: np.ndarray) -> np.ndarray:
        top, rest = rhs[:border], rhs[border:]
        base = scipy.linalg.cho_solve_banded((factor, True), rest)
        head = scipy.linalg.cho_solve(schur, top - cross.T @ base)
        return np.concatenate([head, base - inner @ head])

    return solve
