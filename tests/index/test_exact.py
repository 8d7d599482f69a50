"""The index-free exact search (what `decompose` uses without an index) returns exactly the
neighbours, distances and tie order of a flat index's batch search, and builds nothing."""

from __future__ import annotations

import numpy as np
import pytest

from aoc_cli.decompose import decompose
from aoc_cli.errors import AocError
from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search import exact
from aoc_cli.index.search.exact import nearest_rows

from tests.index.test_batch_search import Beliefs, brute_force


@pytest.fixture(scope="module")
def beliefs():
    return Beliefs(20_000, seed=3)


@pytest.fixture(scope="module")
def index(beliefs):
    return BeliefIndex.build(beliefs.rows, kind="flat")


@pytest.mark.parametrize("length", [0.05, 0.5, 2.0])
def test_equals_the_flat_index_batch_search_exactly(beliefs, index, length, monkeypatch):
    # count the queries the centre's pool could not certify: the slice scan must run too
    scanned = []
    slice_knn = exact._slice_knn
    monkeypatch.setattr(exact, "_slice_knn", lambda *a: (scanned.append(len(a[6])), slice_knn(*a)))
    for _ in range(3):
        queries = beliefs.control_step(100, length)
        d_ix, r_ix = index.search(queries, 42)
        d_ex, r_ex = nearest_rows(beliefs.rows, queries, 42)
        assert np.array_equal(r_ex, r_ix)  # same rows in the same order
        assert np.array_equal(d_ex, d_ix)  # the same float64 distances, bit for bit
        _, truth = brute_force(beliefs.rows, queries, 42)
        assert (np.sort(r_ex, axis=1) == truth).all()
    if length >= 2.0:
        assert sum(scanned) > 0


def test_ties_go_to_the_lower_row_as_in_the_index():
    rng = np.random.default_rng(1)
    base = rng.standard_normal((3_000, 6)).astype(np.float32)
    rows = np.concatenate([base, base, base])  # every belief three times
    queries = base[:40] + np.float32(0.01)
    _, r_ix = BeliefIndex.build(rows, kind="flat").search(queries, 14)
    _, r_ex = nearest_rows(rows, queries, 14)
    assert np.array_equal(r_ex, r_ix)
    # each distance's copies come lowest row first
    assert (r_ex[:, 0] < 3_000).all() and (r_ex[:, 1] == r_ex[:, 0] + 3_000).all()


def test_selection_as_mask_or_rows_and_float64_beliefs(beliefs, index):
    rng = np.random.default_rng(4)
    mask = rng.random(len(beliefs.rows)) < 0.5
    queries = beliefs.control_step(50, 1.0)
    _, r_ix = index.search(queries, 21, selection=mask)
    _, r_mask = nearest_rows(beliefs.rows, queries, 21, selection=mask)
    _, r_ids = nearest_rows(beliefs.rows.astype(np.float64), queries, 21,
                            selection=np.flatnonzero(mask)[::-1])
    assert np.array_equal(r_mask, r_ix) and np.array_equal(r_ids, r_ix)
    assert mask[r_mask].all()


def test_single_query_small_corpus_and_padding(beliefs):
    one = beliefs.control_step(1, 0.1)[0]
    d, r = nearest_rows(beliefs.rows, one, 10)
    d_b, truth = brute_force(beliefs.rows, one[None], 10)
    assert (np.sort(r, axis=1) == truth).all()
    np.testing.assert_allclose(d, d_b, rtol=1e-7, atol=1e-9)
    d, r = nearest_rows(beliefs.rows[:5], one, 8)  # fewer rows than asked: padded
    assert (r[0, 5:] == -1).all() and np.isinf(d[0, 5:]).all() and sorted(r[0, :5]) == list(range(5))


def test_bad_input_is_a_clear_error(beliefs):
    with pytest.raises(AocError, match="k must be at least 1"):
        nearest_rows(beliefs.rows, beliefs.rows[:2], 0)
    with pytest.raises(AocError, match="shape"):
        nearest_rows(beliefs.rows, np.zeros((2, 3)), 4)
    with pytest.raises(AocError, match="no corpus rows"):
        nearest_rows(beliefs.rows, beliefs.rows[:2], 4, selection=np.zeros(len(beliefs.rows), bool))
    with pytest.raises(AocError, match="lie in"):
        nearest_rows(beliefs.rows, beliefs.rows[:2], 4, selection=np.array([len(beliefs.rows)]))


def test_decompose_without_an_index_equals_it_with_one(beliefs, index):
    values = np.random.default_rng(5).standard_normal(len(beliefs.rows))
    for length in (0.1, 2.0):
        queries = beliefs.control_step(100, length).astype(np.float64)
        with_index = decompose(beliefs.rows, queries, values=values, index=index)
        without = decompose(beliefs.rows, queries, values=values)
        assert np.array_equal(without.neighbours, with_index.neighbours)
        assert np.array_equal(without.rows, with_index.rows)
        np.testing.assert_array_max_ulp(without.weights, with_index.weights, maxulp=4)
        np.testing.assert_array_max_ulp(without.value, with_index.value, maxulp=4)
        np.testing.assert_array_max_ulp(without.residual, with_index.residual, maxulp=4)
