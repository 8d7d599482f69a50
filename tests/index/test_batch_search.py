"""The batch search of a flat index (control-step batches, cells.py) returns the exact k
nearest rows."""

from __future__ import annotations

import numpy as np
import pytest

from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search.pooled import exact_among as _exact_among
from aoc_cli.index.search.cells import CellData, cells_search


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
def test_batch_search_equals_brute_force_on_spread_batches(beliefs, corpus, length):
    index = BeliefIndex.build(corpus, kind="flat")
    for _ in range(3):
        queries = beliefs.control_step(100, length)
        truth_d, truth_rows = brute_force(corpus, queries, 42)
        # the spread exceeds the k-th neighbour distance: one centroid pool cannot serve it
        spread = np.linalg.norm(queries - queries.mean(0), axis=1).max()
        if length >= 2.0:
            assert spread > np.median(truth_d[:, -1])
        d2, pos = cells_search(queries, index.cells(), 42)
        assert (np.sort(pos, axis=1) == truth_rows).all()
        np.testing.assert_allclose(np.sqrt(d2), truth_d, rtol=1e-7, atol=1e-9)
        dist, rows = index.search(queries, 42)  # the same through the index
        assert (np.sort(rows, axis=1) == truth_rows).all()
        np.testing.assert_allclose(dist, truth_d, rtol=1e-7, atol=1e-9)


def test_batch_search_is_exact_for_scattered_queries_and_small_k(corpus):
    rng = np.random.default_rng(7)
    queries = rng.uniform(-1, 1, (37, 20)).astype(np.float32)  # no structure at all
    cells = CellData.kmeans(corpus)
    for k in (1, 5, 42):
        _, truth_rows = brute_force(corpus, queries, k)
        _, pos = cells_search(queries, cells, k)
        assert (np.sort(pos, axis=1) == truth_rows).all()


def test_batch_search_respects_a_row_mask_and_copies(beliefs, corpus):
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


def test_exact_among_and_the_cell_search_agree_on_the_distances(beliefs, corpus):
    queries = beliefs.control_step(60, 1.0)
    d2_all, pos_all = _exact_among(queries, corpus, 42)
    d2, pos = cells_search(queries, CellData.kmeans(corpus), 42)
    assert (np.sort(pos, 1) == np.sort(pos_all, 1)).all()
    np.testing.assert_allclose(d2, d2_all, rtol=1e-9)
