"""IVF batch search (pooled.py): the groups' pools scanned from a copy of the inverted lists
give the same rows, in the same order, as the pools of FAISS's own k = kp search."""

from __future__ import annotations

import numpy as np
import pytest

import aoc_cli.index.pooled as pooled
from aoc_cli.index import BeliefIndex


def beliefs(n: int = 30_000, d: int = 20, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    means = rng.standard_normal((40, d)) * 3
    which = rng.integers(0, 40, n)
    B = (means[which] + rng.standard_normal((n, d)) * rng.uniform(0.3, 1.0, 40)[which, None])
    B = B.astype(np.float32)
    B[rng.integers(0, n, n // 10)] = B[rng.integers(0, n, 50)][rng.integers(0, 50, n // 10)]
    B[rng.choice(n, 100, replace=False)] = B[7]
    return B  # a tenth of the rows duplicate 50 others, 100 more row 7: exact ties


def curve(B: np.ndarray, q: int, spread: float, seed: int) -> np.ndarray:
    """Queries along a segment from one row towards another (as the candidates of a control
    step): one centroid cannot certify them all, so the groups' pools are used."""
    rng = np.random.default_rng(seed)
    a, b = B[rng.integers(len(B), size=2)]
    t = np.linspace(0.0, spread, q)[:, None]
    return (a + t * (b - a) + 0.02 * rng.standard_normal((q, B.shape[1]))).astype(np.float32)


def assert_same_neighbours(d_a, r_a, d_b, r_b, rtol=1e-6, atol=1e-6):
    """Two k-nearest answers agree: the distances to a few float32 ulp; the rows position by
    position, except within a run of tied distances (there any order, and at the k-th
    distance any of the tied rows)."""
    np.testing.assert_allclose(d_a, d_b, rtol=rtol, atol=atol)
    tol = atol + rtol * np.abs(np.asarray(d_a, np.float64))
    for q in range(len(r_a)):
        d, kth = np.asarray(d_a[q], np.float64), float(d_a[q][-1])
        clear = np.ones(len(d), bool)  # positions whose distance ties with no other
        for j in range(len(d)):
            if (np.abs(d - d[j]) <= 2 * tol[q]).sum() > 1:
                clear[j] = False
        np.testing.assert_array_equal(r_a[q][clear], r_b[q][clear])
        inside = d < kth - 2 * tol[q, -1]  # strictly before the k-th: the same set of rows
        assert set(r_a[q][inside]) == set(r_b[q][inside]), q


@pytest.fixture(scope="module")
def ivf():
    B = beliefs()
    return B, BeliefIndex.build(B, kind="ivf")


@pytest.mark.parametrize("seed,spread,q", [(1, 0.3, 100), (2, 0.6, 100), (3, 1.0, 60), (4, 0.0, 100), (5, 0.6, 100)])
def test_list_pools_give_faiss_pools_answers(ivf, monkeypatch, seed, spread, q):
    B, ix = ivf
    Y = curve(B, q, spread, seed)
    if seed >= 4:  # queries on a row duplicated ~100 times: ties beyond the k-th
        Y[:10] = B[7]
        assert (B == B[7]).all(1).sum() > 42
    scanned = []
    real = pooled.list_dists
    monkeypatch.setattr(pooled, "list_dists", lambda *a: scanned.append(1) or real(*a))
    d_new, r_new = ix.search(Y, 42)
    saved = ix._pooled_lists
    ix._pooled_lists = (ix.index, ix.index.ntotal, None)  # FAISS's k = kp search of the groups
    try:
        d_old, r_old = ix.search(Y, 42)
    finally:
        ix._pooled_lists = saved
    if spread >= 0.3:
        assert scanned, "the groups' pools were not used"
    # own kernel vs FAISS: float32 distances summed in another order (and FAISS's SIMD
    # depends on the CPU), so rows may trade places only where their distances tie to a few ulp
    assert_same_neighbours(d_new, r_new, d_old, r_old)
    # and the answer is exact among the rows the batch search can see: recall against brute force
    D = ((B.astype(np.float64)[None] - Y.astype(np.float64)[:, None]) ** 2).sum(-1)
    truth = np.argsort(D, axis=1, kind="stable")[:, :42]
    recall = np.mean([len(set(f) & set(t)) / 42 for f, t in zip(r_new, truth)])
    assert recall >= 0.95


def test_the_lists_copy_holds_every_row_once_with_its_vector(ivf):
    B, ix = ivf
    offsets, ids, vecs = pooled._ivf_lists(ix)
    assert offsets[-1] == len(B) and np.array_equal(np.sort(ids), np.arange(len(B)))
    np.testing.assert_array_equal(vecs, B[ids])
