"""The banded Cholesky solver of sparse SPD systems (estimation/banded.py) against dense LAPACK
solves, and its SuperLU fallback where the matrix is not positive definite."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualprobe.estimation.banded import GramBand, band_solver, bordered_solver, lower_band


def _time_series_jacobian(rng: np.random.Generator, rows: int, per_row: int, knots: int,
                          in_time: bool = True) -> sp.csc_matrix:
    """J of a chain (each residual couples a row's unknowns with the next row's) with knots
    that each reach a run of rows: the states of psi_map row by row and a schedule's knots,
    each knot's column amid its rows (``in_time``) or all after the states (as psi_map holds
    them)."""
    n = rows * per_row
    blocks = []
    for k in range(rows - 1):
        block = np.zeros((per_row, n + knots))
        block[:, k * per_row:(k + 2) * per_row] = rng.normal(size=(per_row, 2 * per_row))
        block[:, n + min(knots - 1, k * knots // rows)] = rng.normal(size=per_row)
        blocks.append(block)
    jac = sp.csc_matrix(np.vstack([*blocks, np.eye(n + knots)]))
    keys = np.concatenate([np.repeat(np.arange(rows, dtype=float), per_row),
                           (np.arange(knots) + 0.5) * rows / knots])
    return jac[:, np.argsort(keys, kind="stable")].tocsc() if in_time else jac


def _time_series_system(rng: np.random.Generator, rows: int, per_row: int, knots: int,
                        ) -> sp.csc_matrix:
    """J'J of :func:`_time_series_jacobian`."""
    jac = _time_series_jacobian(rng, rows, per_row, knots)
    return (jac.T @ jac).tocsc()


def _never() -> sp.spmatrix:
    raise AssertionError("the fallback's matrix was built for a positive definite system")


def test_spd_systems_are_solved_as_dense_lapack_solves_them() -> None:
    # tolerance: both are backward stable and the condition number is about 40, so rounding
    # stays near 1e-14; 1e-9 only allows for a different order of the sums
    rng = np.random.default_rng(3)
    matrix = _time_series_system(rng, 200, 3, 20)
    rhs = rng.normal(size=(matrix.shape[0], 3))
    dense = np.linalg.solve(matrix.toarray(), rhs)
    band = lower_band(matrix)
    # a knot sits amid the 11 rows of 3 unknowns it reaches, so its half-bandwidth is about
    # 6 rows' worth (19 measured): narrow
    assert band.shape[0] <= 25
    # the band is the matrix's lower triangle, diagonal by diagonal
    for offset in range(band.shape[0]):
        np.testing.assert_array_equal(band[offset, :matrix.shape[0] - offset],
                                      matrix.diagonal(-offset))
    solve = band_solver(band, _never)
    np.testing.assert_allclose(solve(rhs), dense, rtol=1e-9, atol=1e-9 * np.abs(dense).max())
    np.testing.assert_allclose(solve(rhs[:, 0]), dense[:, 0], rtol=1e-9,
                               atol=1e-9 * np.abs(dense).max())


def test_a_matrix_that_is_not_positive_definite_is_solved_by_lu() -> None:
    rng = np.random.default_rng(4)
    matrix = _time_series_system(rng, 50, 2, 5)
    indefinite = (matrix - sp.identity(matrix.shape[0]) * 2.0 * matrix.diagonal().max()).tocsc()
    rhs = rng.normal(size=matrix.shape[0])
    np.testing.assert_allclose(band_solver(lower_band(indefinite), lambda: indefinite)(rhs),
                               np.linalg.solve(indefinite.toarray(), rhs), rtol=1e-8)


def test_the_gram_band_is_the_band_of_the_sparse_product() -> None:
    # tolerance: the same products summed in another order (at most ~10 terms per entry of
    # magnitude ~1): rounding near 1e-15, 1e-12 allows for it and nothing more
    rng = np.random.default_rng(5)
    jac = _time_series_jacobian(rng, 120, 3, 12)
    gram = GramBand(jac.indices, jac.indptr, jac.shape[1])
    expected = lower_band((jac.T @ jac).tocsc())
    got = gram.band(jac.data)
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=0.0, atol=1e-12)
    assert gram.fits(jac)
    # new values in the same pattern: the band follows them
    again = jac.copy()
    again.data = rng.normal(size=again.data.size)
    np.testing.assert_allclose(gram.band(again.data), lower_band((again.T @ again).tocsc()),
                               rtol=0.0, atol=1e-12)
    # another pattern does not fit
    other = _time_series_jacobian(rng, 120, 3, 11)
    assert not gram.fits(other)


def _bordered(rng: np.random.Generator, border: int, size: int) -> sp.csc_matrix:
    """An SPD matrix of ``border`` unknowns coupled to all, then ``size`` banded ones (the
    tracking pencil's derivative columns and knots)."""
    band = sp.diags([rng.normal(size=size - j) for j in range(4)], list(range(4)),
                    shape=(size, size))
    rest = (band @ band.T + sp.identity(size)).tocsc()
    edge = rng.normal(size=(size, border))
    corner = edge.T @ edge + np.eye(border) * size
    return sp.bmat([[sp.csc_matrix(corner), sp.csc_matrix(edge.T)],
                    [sp.csc_matrix(edge), rest]]).tocsc()


def test_a_bordered_banded_system_is_solved_as_dense_lapack_solves_it() -> None:
    # tolerance as above: well conditioned (the band's identity and the corner's weight),
    # rounding near 1e-14
    rng = np.random.default_rng(6)
    for border in (0, 2, 5):
        matrix = _bordered(rng, border, 300)
        rhs = rng.normal(size=matrix.shape[0])
        np.testing.assert_allclose(bordered_solver(matrix, border)(rhs),
                                   np.linalg.solve(matrix.toarray(), rhs), rtol=1e-9,
                                   atol=1e-12)
    # not positive definite: the LU of the whole matrix
    matrix = _bordered(rng, 2, 100)
    indefinite = (matrix - sp.identity(102) * 2.0 * matrix.diagonal().max()).tocsc()
    rhs = rng.normal(size=102)
    np.testing.assert_allclose(bordered_solver(indefinite, 2)(rhs),
                               np.linalg.solve(indefinite.toarray(), rhs), rtol=1e-8)
