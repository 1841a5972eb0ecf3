"""The joint MAP of psi (dualprobe.estimation.psi_map) keeps a problem's sparsity patterns for
the next problem of the same size while a store is active (psi_map.sharing): the same MAP bit
for bit, and nothing kept outside a store."""

from __future__ import annotations

import numpy as np

from dualprobe.estimation import psi_map


def _pair(rows: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A random-walk gas read by two first-order sensors (2 s and 5 s, 10 Hz), held exactly
    between rows, with 0.05 K of noise: written here, apart from the MAP's chains."""
    rng = np.random.default_rng(11)
    ts = 0.1
    t = np.arange(rows) * ts
    gas = 600.0 + np.cumsum(rng.normal(0.0, 0.3, rows))
    out = []
    for tau in (2.0, 5.0):
        a = np.exp(-ts / tau)
        y = np.empty(rows)
        y[0] = gas[0]
        for k in range(1, rows):
            y[k] = a * y[k - 1] + (1.0 - a) * gas[k - 1]
        out.append(y + rng.normal(0.0, 0.05, rows))
    return t, out[0], out[1]


def _map(rows: int) -> psi_map.PsiMap:
    t, y1, y2 = _pair(rows)
    return psi_map.map_psi(t, y1, y2, [2.0], [5.0], (1.0, 0.0), (0.05, 0.05), 1.0, 10, 0.05)


def test_a_store_shares_patterns_between_maps_of_one_size_with_the_same_result() -> None:
    # exact equality, no tolerance: a kept pattern (and its symbolic factorisation) gives
    # the same numeric factorisation as a new one, so not one bit may differ
    alone = _map(400)
    store = psi_map.PatternStore()
    with psi_map.sharing(store):
        first = _map(400)
        kept = store.patterns
        second = _map(400)  # the same size: the kept patterns, J'J's included
        assert kept is not None and store.patterns is kept and kept.joint_gram is not None
        _map(300)  # another size: the last dropped, this one's kept
        assert store.patterns is not kept and store.key is not None and store.key[0] == 300
    for found in (first, second):
        np.testing.assert_array_equal(found.psi, alone.psi)
        assert (found.static, found.cost, found.iterations) == (
            alone.static, alone.cost, alone.iterations)
    assert psi_map._STORE.get() is None  # the block left no store active: nothing is kept
