"""The grouped scan of a flat index (control-step batches) returns the exact k nearest rows."""

from __future__ import annotations

import numpy as np
import pytest

from aoc_cli.index import BeliefIndex
from aoc_cli.index.pooled import exact_among as _exact_among
from aoc_cli.index.grouped import ScanData, grouped_search


def brute_force(beliefs: np.ndarray, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """k nearest rows by a full float64 distance matrix: (distances, sorted row sets)."""
    B, Q = beliefs.astype(np.float64), queries.astype(np.float64)
    d2 = np.maximum((Q * Q).sum(1)[:, None] - 2.0 * Q @ B.T + (B * B).sum(1)[None, :], 0.0)
    rows = np.argsort(d2, axis=1, kind="stable")[:, :k]
    return np.sqrt(np.take_along_axis(d2, rows, axis=1)), np.sort(rows, axis=1)


class Beliefs:
    """Beliefs like a model's: tanh of a random linear map of a 4-d latent (a mixture)."""

    def __init__(self, n: int, seed: int = 0):
        rng = np.random.default_rng(seed)
        self.rng = rng
        self.map = rng.standard_normal((4, 20)) / 2.0
        centres = rng.standard_normal((20, 4))
        self.latent = centres[rng.integers(0, 20, n)] + 0.5 * rng.standard_normal((n, 4))
        self.rows = self.embed(self.latent)

    def embed(self, latent: np.ndarray) -> np.ndarray:
        return np.tanh(latent @ self.map).astype(np.float32)

    def control_step(self, q: int, length: float) -> np.ndarray:
        """Q queries along a curve of the latent through a corpus row: the candidates of one
        control step (the action moves the belief along a curve)."""
        start = self.latent[self.rng.integers(len(self.latent))]
        direction, bend = self.rng.standard_normal((2, 4))
        direction *= length / np.linalg.norm(direction)
        bend *= 0.3 * length / np.linalg.norm(bend)
        s = np.sort(self.rng.uniform(-0.5, 0.5, q))[:, None]
        return self.embed(start + s * direction + np.cos(np.pi * s) * bend)


@pytest.fixture(scope="module")
def beliefs():
    return Beliefs(20_000)


@pytest.fixture(scope="module")
def corpus(beliefs):
    return beliefs.rows


@pytest.mark.parametrize("length", [0.05, 0.5, 2.0])
def test_grouped_scan_equals_brute_force_on_spread_batches(beliefs, corpus, length):
    index = BeliefIndex.build(corpus, kind="flat")
    for _ in range(3):
        queries = beliefs.control_step(100, length)
        truth_d, truth_rows = brute_force(corpus, queries, 42)
        # the spread exceeds the k-th neighbour distance: one centroid pool cannot serve it
        spread = np.linalg.norm(queries - queries.mean(0), axis=1).max()
        if length >= 2.0:
            assert spread > np.median(truth_d[:, -1])
        out = grouped_search(queries, ScanData.of(corpus), 42)
        assert out is not None
        d2, pos = out
        assert (np.sort(pos, axis=1) == truth_rows).all()
        np.testing.assert_allclose(np.sqrt(d2), truth_d, rtol=1e-7, atol=1e-9)
        dist, rows = index.search(queries, 42)  # the same through the index
        assert (np.sort(rows, axis=1) == truth_rows).all()
        np.testing.assert_allclose(dist, truth_d, rtol=1e-7, atol=1e-9)


def test_grouped_scan_is_exact_for_scattered_queries_and_small_k(corpus):
    rng = np.random.default_rng(7)
    queries = rng.uniform(-1, 1, (37, 20)).astype(np.float32)  # no structure at all
    for k in (1, 5, 42):
        _, truth_rows = brute_force(corpus, queries, k)
        _, pos = grouped_search(queries, ScanData.of(corpus), k)
        assert (np.sort(pos, axis=1) == truth_rows).all()


def test_grouped_scan_respects_a_row_mask_and_copies(beliefs, corpus):
    index = BeliefIndex.build(corpus, kind="flat")
    rng = np.random.default_rng(8)
    allowed = rng.random(len(corpus)) < 0.4  # too many rows for the small-selection path
    queries = beliefs.control_step(100, 1.0)
    _, rows = index.search(queries, 42, selection=allowed)
    sub = np.flatnonzero(allowed)
    _, truth = brute_force(corpus[sub], queries, 42)
    assert (np.sort(rows, axis=1) == sub[truth]).all()
    # a re-sampled index: every row twice, so each neighbour comes with its copy
    double = index.resample(2.0)
    _, rows = double.search(queries, 42)
    _, truth = brute_force(corpus, queries, 21)
    assert (np.sort(rows, axis=1) == np.sort(np.repeat(truth, 2, axis=1), axis=1)).all()


def test_exact_among_and_grouped_scan_agree_on_the_distances(beliefs, corpus):
    queries = beliefs.control_step(60, 1.0)
    d2_all, pos_all = _exact_among(queries, corpus, 42)
    d2, pos = grouped_search(queries, ScanData.of(corpus), 42)
    assert (np.sort(pos, 1) == np.sort(pos_all, 1)).all()
    np.testing.assert_allclose(d2, d2_all, rtol=1e-9)


def test_ball_kernel_keeps_the_k_nearest_with_ties_and_counts_rows_under_the_bound():
    from aoc_cli.index.scan_kernels import ball_knn

    rng = np.random.default_rng(3)
    rows = rng.integers(0, 4, (300, 3)).astype(np.float64)  # many exact distance ties
    Y = rng.integers(0, 4, (9, 3)) + 0.25
    d2 = ((rows[None] - Y[:, None]) ** 2).sum(-1)
    k = 7
    kth = np.sort(d2, axis=1)[:, k - 1]
    G = 2
    D2 = np.zeros((300, G), np.float32)
    starts, members = np.array([0, 5, 9]), np.arange(9)
    inf = np.full(9, np.inf)
    by_row = np.arange(300)[None].repeat(9, 0)

    def run(u2, hi=inf):
        out_r, out_d = np.empty((9, k), np.int64), np.empty((9, k))
        found = ball_knn(D2, np.full(G, np.inf), starts, members, hi, -inf, Y, u2, rows,
                         Y.astype(np.float32), rows.astype(np.float32), k, out_r, out_d)
        return found, out_r, out_d

    for u2 in (kth, kth + 0.5, np.where(np.arange(9) == 4, kth - 0.01, kth + 0.01)):
        found, out_r, out_d = run(u2)
        assert found == ((d2 <= u2[:, None]).sum(1)).min()
        full = np.lexsort((by_row, d2), axis=1)[:, :k]
        ok = np.arange(9) != 4 if found < k else np.ones(9, bool)
        np.testing.assert_array_equal(out_r[ok], full[ok])  # nearest first, ties by row
        np.testing.assert_array_equal(out_d[ok], np.take_along_axis(d2, full, 1)[ok])
    # a row outside query 0's annulus (D2 above its bound) is never returned to it
    D2[full[0, 0], 0] = 5.0
    hi = inf.copy()
    hi[0] = 4.0
    found, out_r, _ = run(kth + 0.5, hi)
    rest = np.lexsort((np.arange(300), np.where(np.arange(300) == full[0, 0], np.inf, d2[0])))[:k]
    np.testing.assert_array_equal(out_r[0], rest)
    np.testing.assert_array_equal(out_r[1:], np.lexsort((by_row, d2), axis=1)[1:, :k])
