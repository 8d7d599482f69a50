"""exact_among (the compiled k-nearest pass over a pool, pooled.py): the brute-force answer,
float64 distances ascending, ties (duplicate rows) by the lower position."""

from __future__ import annotations

import numpy as np
import pytest

from aoc_cli.index.search.pooled import exact_among


def brute(Y, V, k):
    D = ((V.astype(np.float64)[None] - Y.astype(np.float64)[:, None]) ** 2).sum(-1)
    order = np.array([np.lexsort((np.arange(V.shape[0]), D[q]))[:k] for q in range(Y.shape[0])])
    return np.take_along_axis(D, order, axis=1), order


@pytest.mark.parametrize("seed", range(12))
def test_exact_among_is_brute_force_with_ties_by_position(seed):
    rng = np.random.default_rng(seed)
    d, P, Q, k = 20, int(rng.integers(50, 1500)), int(rng.integers(1, 40)), int(rng.integers(1, 50))
    V = (rng.standard_normal((P, d)) * rng.uniform(0.01, 10) + rng.uniform(-5, 5)).astype(np.float32)
    if seed % 2:  # many exact duplicates: ties at the k-th distance
        V[rng.integers(0, P, P // 3)] = V[rng.integers(0, P, 8)][rng.integers(0, 8, P // 3)]
    Y = (V[rng.integers(0, P, Q)] + 0.01 * rng.standard_normal((Q, d))).astype(np.float32)
    if seed % 3 == 0:
        Y[0] = V[0]  # a query on a row: distance 0
    d2, pos = exact_among(Y, V, k)
    want_d2, want_pos = brute(Y, V, k)
    np.testing.assert_array_equal(pos, want_pos)
    np.testing.assert_allclose(d2, want_d2, rtol=1e-12, atol=0)
    assert (np.diff(d2, axis=1) >= 0).all()


def test_exact_among_with_fewer_rows_than_k_returns_them_all():
    rng = np.random.default_rng(0)
    V = rng.standard_normal((5, 3)).astype(np.float32)
    Y = rng.standard_normal((2, 3)).astype(np.float32)
    d2, pos = exact_among(Y, V, 9)
    assert pos.shape == (2, 5)
    np.testing.assert_array_equal(pos, brute(Y, V, 5)[1])
