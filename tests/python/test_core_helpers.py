"""The compiled helpers behind the estimation's and reconstruction's offline pieces, against
independent NumPy/SciPy computations: the SVF cascade on arbitrary rows, its discretisation, and
the smoother's posterior variances from a banded Cholesky factor."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from dualprobe import _core
from dualprobe.reference import svf as reference


@pytest.mark.parametrize(("m", "hold"), [(1, "foh"), (2, "foh"), (3, "foh"), (3, "zoh")])
def test_svf_filter_matches_the_reference_cascade(m: int, hold: str) -> None:
    rng = np.random.default_rng(m)
    u = np.cumsum(rng.standard_normal((3, 400)), axis=1)
    out = _core.svf_filter(u, 0.1, 0.7, m, hold)
    disc = reference.discretise_filter(0.7, 0.1, m, hold)
    for row in range(3):
        states = reference.filter_states(u[row], disc)  # at rest before the row
        expected = disc.derivative_map @ states
        # both exact discretisations of the same cascade; 1e-12 is a few hundred roundings
        np.testing.assert_allclose(out[row], expected, rtol=0, atol=1e-12 * np.abs(u).max())


def test_svf_discretisation_matches_the_reference() -> None:
    d = _core.svf_discretisation(0.05, 2.0, 3, "foh")
    r = reference.discretise_filter(2.0, 0.05, 3, "foh")
    for key in ("phi", "derivative_map", "state_covariance"):
        np.testing.assert_allclose(d[key], getattr(r, key), rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(np.ravel(d["ga"]), r.ga, rtol=1e-12)
    np.testing.assert_allclose(np.ravel(d["gb"]), r.gb, rtol=1e-12, atol=1e-16)


@pytest.mark.parametrize("kd", [1, 3, 11])
def test_banded_inverse_diagonal_matches_the_dense_inverse(kd: int) -> None:
    rng = np.random.default_rng(kd)
    n = 60
    full = np.zeros((n, n))
    for j in range(kd + 1):
        values = rng.standard_normal(n - j)
        full += np.diag(values, j) + (np.diag(values, -j) if j else 0)
    full = full @ full.T  # denser than kd: rebuild a banded SPD matrix instead
    band = np.zeros((n, n))
    for j in range(-kd, kd + 1):
        band += np.diag(np.diag(full, j), j)
    band += (np.abs(band).sum(axis=1).max() + 1.0) * np.eye(n)  # diagonally dominant: SPD
    ab = np.zeros((kd + 1, n))
    for j in range(kd + 1):
        ab[kd - j, j:] = np.diag(band, j)
    chol = scipy.linalg.cholesky_banded(ab, lower=False)
    got = _core.banded_inverse_diagonal(chol)
    np.testing.assert_allclose(got, np.diag(np.linalg.inv(band)), rtol=1e-11)


def test_banded_inverse_diagonal_refuses_a_bad_factor() -> None:
    with pytest.raises(ValueError):
        _core.banded_inverse_diagonal(np.zeros((2, 5)))
