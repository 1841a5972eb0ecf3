"""Normal matrices J'J of one fixed sparse pattern, factorised by sparse LDL' (qdldl: AMD
ordering, symbolic factorisation once per pattern, numeric one per call). Why not the band
(:mod:`dualprobe.estimation.banded`): the joint MAP of psi (:mod:`psi_map`) couples each knot of
log psi with the states of the two spans it reaches, so in time order its band is about 70 wide
while each elimination touches about 12 unknowns; LAPACK's banded Cholesky works on the whole
band (measured on a 20 min 20 Hz record, 121 848 unknowns: 0.43 s a factorisation against
0.05 s here), and was most of the sheathed path's time."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import qdldl
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from dualprobe.estimation.banded import Pattern, by_target, row_pairs

__all__ = ["GramLDL"]


class GramLDL(Pattern):
    """The upper triangle of ``J' J`` (CSC) for every sparse ``J`` of one fixed pattern, from J's
    stored values (no sparse product), and its solver. Built from J's CSC structure
    (``indices``, ``indptr``, ``columns``); the pattern must hold each (row, column) once, as CSC
    storage does. Every diagonal entry is stored, so that damping can be added to any."""

    def __init__(self, indices: np.ndarray, indptr: np.ndarray, columns: int) -> None:
        super().__init__(indices, indptr, columns)
        col = np.repeat(np.arange(columns), np.diff(self.indptr))
        self.p, self.q = row_pairs(self.indices, col)  # col[p] >= col[q]
        every = np.arange(columns)
        # CSC order of the upper triangle: by column, then by row
        keys = np.concatenate([col[self.p] * columns + col[self.q], every * columns + every])
        unique, inverse = np.unique(keys, return_inverse=True)
        self.p, self.q, self.target = by_target(self.p, self.q, inverse[:self.p.size])
        self.diagonal = inverse[self.p.size:]  # where each column's diagonal entry is stored
        self.rows = unique % columns
        self.pointers = np.r_[0, np.cumsum(np.bincount(unique // columns, minlength=columns))]
        self._solver: qdldl.Solver | None = None
        self._split: tuple[int, tuple[np.ndarray, ...]] | None = None

    def values(self, data: np.ndarray, leading: np.ndarray | None = None) -> np.ndarray:
        """The stored values of J'J's upper triangle for J of this pattern with values ``data``.
        ``leading``: the lower band of the first L columns' own J'J (banded storage, (w, L),
        as :class:`dualprobe.estimation.banded.GramBand` gives it for those columns), already
        at hand: those entries are read from it, not summed again. Why: psi's MAP has just
        formed that band for its states (:mod:`psi_map`), and its pairs are over half of the
        joint ones. Bit for bit the same: the band sums each entry's products in the order
        they have here (both take a row's values in column order, the pairs by position in
        the row, then by row)."""
        if leading is None:
            return np.bincount(self.target, weights=np.take(data, self.p) * np.take(data, self.q),
                               minlength=self.rows.size)
        p, q, target, where, flat = self._outside(leading.shape[1])
        out = np.bincount(target, weights=np.take(data, p) * np.take(data, q),
                          minlength=self.rows.size)
        out[where] = leading.reshape(-1)[flat]
        return out

    def _outside(self, size: int) -> tuple[np.ndarray, ...]:
        """The pairs that reach beyond the first ``size`` columns, and where the entries
        within them are stored (``where``) and stand in their band (``flat``), kept."""
        if self._split is None or self._split[0] != size:
            col = np.repeat(np.arange(self.size), np.diff(self.indptr))
            beyond = col[self.p] >= size  # col[p] >= col[q]: the pair is within iff col[p] is
            column = np.repeat(np.arange(self.size), np.diff(self.pointers))
            where = np.flatnonzero(column < size)
            flat = (column[where] - self.rows[where]) * size + self.rows[where]
            self._split = (size, (self.p[beyond], self.q[beyond], self.target[beyond], where,
                                  flat))
        return self._split[1]

    def matrix(self, values: np.ndarray) -> sp.csc_matrix:
        """The upper triangle with these stored values, as a sparse matrix."""
        return sp.csc_matrix((values, self.rows, self.pointers), shape=(self.size, self.size))

    def solver(self, values: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """A solver of ``A x = b`` (b a vector or columns) for the symmetric A whose upper
        triangle has these stored values. Where the LDL' fails (a zero pivot: its solution is
        not finite) or A is not finite, SuperLU's LU with pivoting instead (a nearly singular
        step is then rejected by its cost, as the band's fallback does)."""
        upper = self.matrix(values)

        def lu() -> Callable[[np.ndarray], np.ndarray]:
            return spl.splu((upper + sp.triu(upper, 1).T).tocsc()).solve

        if not np.isfinite(values).all():
            return lu()
        try:
            if self._solver is None:
                self._solver = qdldl.Solver(upper, upper=True)
            else:
                self._solver.update(upper, upper=True)
        except (ValueError, RuntimeError):
            self._solver = None
            return lu()
        ldl = self._solver

        def solve(rhs: np.ndarray) -> np.ndarray:
            columns = rhs.reshape(rhs.shape[0], -1)
            out = np.column_stack([ldl.solve(np.ascontiguousarray(c)) for c in columns.T])
            if not np.isfinite(out).all():
                out = lu()(columns)
            return out.reshape(rhs.shape)

        return solve
