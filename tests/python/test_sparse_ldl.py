"""J'J of a fixed sparse pattern and its sparse LDL' solver (estimation/sparse_ldl.py) against
the sparse product and dense LAPACK solves, with the fallback where the LDL' has a zero pivot."""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from dualprobe.estimation.banded import GramBand
from dualprobe.estimation.sparse_ldl import GramLDL
from test_banded import _time_series_jacobian


def test_the_stored_upper_triangle_is_that_of_the_sparse_product() -> None:
    # tolerance: the same products summed in another order (at most ~10 terms per entry of
    # magnitude ~1): rounding near 1e-15, 1e-12 allows for it and nothing more
    rng = np.random.default_rng(7)
    jac = _time_series_jacobian(rng, 120, 3, 12, in_time=False)
    gram = GramLDL(jac.indices, jac.indptr, jac.shape[1])
    for _ in range(2):  # new values in the same pattern: the triangle follows them
        expected = sp.triu((jac.T @ jac).tocsc()).toarray()
        values = gram.values(jac.data)
        np.testing.assert_allclose(gram.matrix(values).toarray(), expected, rtol=0.0,
                                   atol=1e-12)
        np.testing.assert_allclose(values[gram.diagonal], np.diag(expected), rtol=0.0,
                                   atol=1e-12)
        jac = jac.copy()
        jac.data = rng.normal(size=jac.data.size)
    assert gram.fits(jac)
    other = _time_series_jacobian(rng, 120, 3, 11, in_time=False)
    assert not gram.fits(other)


def test_a_leading_block_s_band_gives_the_same_triangle_bit_for_bit() -> None:
    # exact equality, no tolerance: the band sums each entry's products in the same order as
    # the joint pairs do (sparse_ldl.GramLDL.values), so not one bit may differ
    rng = np.random.default_rng(9)
    states = 120 * 3
    jac = _time_series_jacobian(rng, 120, 3, 12, in_time=False)  # the states, then the knots
    gram = GramLDL(jac.indices, jac.indptr, jac.shape[1])
    leading = jac[:, :states].tocsc()
    band = GramBand(leading.indices, leading.indptr, states)
    for _ in range(2):  # the split is kept for the next values of the pattern
        expected = gram.values(jac.data)
        np.testing.assert_array_equal(gram.values(jac.data, band.band(leading.data)), expected)
        jac = jac.copy()
        jac.data = rng.normal(size=jac.data.size)
        leading = jac[:, :states].tocsc()
    # and it is the product's triangle (the same tolerance as above)
    np.testing.assert_allclose(gram.matrix(gram.values(jac.data, band.band(leading.data)))
                               .toarray(), sp.triu((jac.T @ jac).tocsc()).toarray(), rtol=0.0,
                               atol=1e-12)


def test_damped_systems_are_solved_as_dense_lapack_solves_them() -> None:
    # tolerance: both are backward stable and the condition number of J'J is about 40, so
    # rounding stays near 1e-14; 1e-9 only allows for another elimination order
    rng = np.random.default_rng(8)
    jac = _time_series_jacobian(rng, 200, 3, 20, in_time=False)
    gram = GramLDL(jac.indices, jac.indptr, jac.shape[1])
    values = gram.values(jac.data)
    dense = (jac.T @ jac).toarray()
    rhs = rng.normal(size=(dense.shape[0], 3))
    for damping in (0.0, 1e-3, 10.0):  # refactorised in the same pattern at every damping
        damped = values.copy()
        damped[gram.diagonal] *= 1.0 + damping
        expected = np.linalg.solve(dense + np.diag(damping * np.diag(dense)), rhs)
        solve = gram.solver(damped)
        scale = np.abs(expected).max()
        np.testing.assert_allclose(solve(rhs), expected, rtol=1e-9, atol=1e-9 * scale)
        np.testing.assert_allclose(solve(rhs[:, 1]), expected[:, 1], rtol=1e-9,
                                   atol=1e-9 * scale)


def test_a_zero_pivot_is_solved_by_lu() -> None:
    # [[0, 1], [1, 0]]: nonsingular, but LDL' without pivoting divides by its first diagonal
    jac = sp.csc_matrix(np.ones((2, 2)))
    gram = GramLDL(jac.indices, jac.indptr, 2)
    values = np.zeros(3)
    values[gram.diagonal] = 0.0
    values[np.setdiff1d(np.arange(3), gram.diagonal)] = 1.0
    np.testing.assert_allclose(gram.solver(values)(np.array([2.0, 5.0])), [5.0, 2.0])
    # and the next factorisation in the pattern is LDL' again, refactorised from scratch
    values[gram.diagonal] = 2.0
    np.testing.assert_allclose(gram.solver(values)(np.array([1.0, 1.0])), [1.0 / 3, 1.0 / 3])
