"""The exact batch search by cells (cells.py) returns brute force's k nearest rows, ties by
the lower position, for k-means cells of a flat index and the inverted lists of an IVF."""

from __future__ import annotations

import faiss
import numpy as np
import pytest

from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search.cells import CellData, cells_search


def brute(B: np.ndarray, Y: np.ndarray, k: int, allowed=None):
    """(squared distances (Q, k), positions (Q, k)) by (float64 distance, position)."""
    d2 = ((Y.astype(np.float64)[:, None, :] - B.astype(np.float64)[None]) ** 2).sum(-1)
    if allowed is not None:
        d2[:, ~allowed] = np.inf
    order = np.lexsort((np.broadcast_to(np.arange(len(B)), d2.shape), d2), axis=1)[:, :k]
    return np.take_along_axis(d2, order, 1), order


def clustered(n: int, d: int = 20, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    means = rng.standard_normal((12, d)) * 2
    which = rng.integers(0, 12, n)
    return (means[which] + rng.standard_normal((n, d)) * rng.uniform(0.1, 1, 12)[which, None]).astype(np.float32)


def batch(B: np.ndarray, q: int, seed: int) -> np.ndarray:
    """Queries along a segment between two rows, with noise (one control step's candidates)."""
    rng = np.random.default_rng(seed)
    a, b = B[rng.integers(len(B), size=2)]
    t = np.linspace(0, 0.5, q)[:, None]
    return (a + t * (b - a) + 0.05 * rng.standard_normal((q, B.shape[1]))).astype(np.float32)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_kmeans_cells_give_brute_force_rows(seed):
    B = clustered(6000, seed=seed)
    cells = CellData.kmeans(B, seed)
    for Y in (batch(B, 50, seed), np.random.default_rng(seed).uniform(-3, 3, (9, 20)).astype(np.float32)):
        for k in (1, 7, 42):
            d2, pos = cells_search(Y, cells, k)
            t_d2, t_pos = brute(B, Y, k)
            np.testing.assert_allclose(d2, t_d2, rtol=1e-12)
            # positions equal except where two distances tie within rounding
            same = np.isclose(np.diff(t_d2, axis=1), 0, rtol=1e-12, atol=0)
            if not same.any():
                np.testing.assert_array_equal(pos, t_pos)


def test_ties_are_broken_by_the_lower_position_and_masks_are_respected():
    rng = np.random.default_rng(4)
    B = rng.integers(0, 3, (3000, 6)).astype(np.float32)  # integer rows: many exact ties
    Y = (rng.integers(0, 3, (30, 6)) + 0.5).astype(np.float32)
    cells = CellData.kmeans(B, 0)
    for k in (1, 5, 40):
        d2, pos = cells_search(Y, cells, k)
        t_d2, t_pos = brute(B, Y, k)
        np.testing.assert_array_equal(pos, t_pos)  # exact arithmetic: the same rows in order
        np.testing.assert_array_equal(d2, t_d2)
    allowed = rng.random(3000) < 0.3
    d2, pos = cells_search(Y, cells, 12, allowed)
    np.testing.assert_array_equal(pos, brute(B, Y, 12, allowed)[1])
    assert allowed[pos].all()


def test_ivf_cells_are_its_lists_and_the_batch_search_is_exact():
    B = clustered(8000, seed=5)
    B[:200] = B[7]  # 200 copies of one row: ties at every distance from it
    ix = BeliefIndex.build(B, kind="ivf", ivf_nlist=32, ivf_nprobe=2)
    cells = ix.cells()
    assert cells.centres.shape == (32, 20)
    stored, ids = cells.stored()
    assert np.array_equal(np.sort(ids), np.arange(8000))
    np.testing.assert_array_equal(stored, B[ids])  # every row once, cell by cell
    # the cells are FAISS's own lists (sorted in place), not a copy
    inv = ix.index.invlists
    first = int(np.flatnonzero(np.diff(cells.offsets))[0])
    codes = faiss.rev_swig_ptr(inv.get_codes(first), inv.list_size(first) * ix.index.code_size)
    assert np.shares_memory(cells.rows[first], codes)
    np.testing.assert_array_equal(codes.view(np.float32).reshape(-1, 20), cells.rows[first])
    # rho ascending within each cell, below the cell's radius
    for l in range(32):
        r = cells.rho[cells.offsets[l]:cells.offsets[l + 1]]
        assert (np.diff(r) >= 0).all() and (r <= cells.radius[l]).all()
    Y = np.concatenate([batch(B, 40, 6), B[7][None].repeat(3, 0) + 0.01])
    dist, rows = ix.search(Y, 42)  # through the index: exact, where nprobe 2 of 32 is not
    t_d2, t_pos = brute(B, Y, 42)
    np.testing.assert_allclose(dist, np.sqrt(t_d2), rtol=1e-9)
    np.testing.assert_array_equal(rows[-3:], t_pos[-3:])  # ties by the lower row
    assert (np.sort(rows, 1) == np.sort(t_pos, 1)).all()


def test_a_start_bound_from_the_previous_query_never_loses_rows():
    # queries far apart (the bound a predecessor gives is loose) and identical (it is exact)
    B = clustered(4000, seed=8)
    Y = np.concatenate([B[:3], B[:3], np.full((2, 20), 50.0, np.float32)])
    d2, pos = cells_search(Y, CellData.kmeans(B, 0), 10)
    np.testing.assert_array_equal(pos, brute(B, Y, 10)[1])


@pytest.mark.parametrize("kind", ["flat", "ivf"])
def test_row_beliefs_come_from_the_cells_with_the_arrays_values(kind):
    B = clustered(5000, seed=9)
    ix = BeliefIndex.build(B, kind=kind, ivf_nlist=16)
    rows = np.random.default_rng(0).integers(0, 5000, (7, 42))
    assert ix.row_beliefs(rows) is None  # no cells before the first batch search
    ix.search(batch(B, 20, 1), 5)
    np.testing.assert_array_equal(ix.row_beliefs(rows), B[rows.ravel()])
    assert ix.resample(2.0).row_beliefs(rows) is None  # derived: rows are not positions


def test_many_queries_are_searched_in_chunks_with_the_same_answer(monkeypatch):
    import aoc_cli.index.search.cells as cells_module

    B = clustered(3000, seed=10)
    cells = CellData.kmeans(B, 0)
    Y = batch(B, 50, 3)
    whole = cells_search(Y, cells, 6)
    monkeypatch.setattr(cells_module, "QUERY_CHUNK", 7)
    chunked = cells_search(Y, cells, 6)
    np.testing.assert_array_equal(chunked[1], whole[1])
    np.testing.assert_array_equal(chunked[1], brute(B, Y, 6)[1])
