"""Step 1 per action (aoc_cli.index.search.strata): the nearest rows of each action, against a brute
force; a rare action far from a query is among its candidates (the k nearest rows hold none);
the row selection and the evaluation's IVF structure restrict it alike."""

from __future__ import annotations

import numpy as np
import pytest

from aoc_cli.decompose import decompose
from aoc_cli.errors import AocError
from aoc_cli.index.search.batch import BatchSearch
from aoc_cli.index.search import BeliefIndex
from aoc_cli.index.search.strata import PerAction, candidate_search


def _corpus(n=600, seed=0):
    """Beliefs in two clusters: action 1 (rare, 10%) far from most action-0 rows."""
    rng = np.random.default_rng(seed)
    actions = (rng.random(n) < 0.1).astype(np.int64)
    beliefs = rng.standard_normal((n, 6)) + 4.0 * actions[:, None]
    return beliefs.astype(np.float32), actions


def _nearest_of(beliefs, queries, mask, per):
    d = np.linalg.norm(queries[:, None, :].astype(np.float64) - beliefs[None].astype(np.float64),
                       axis=2)
    d[:, ~mask] = np.inf
    return np.sort(np.argsort(d, axis=1, kind="stable")[:, :per], axis=1)


def test_per_action_candidates_are_each_actions_nearest_rows():
    beliefs, actions = _corpus()
    index = BeliefIndex.build(beliefs, kind="flat")
    search = PerAction(index, actions)
    queries = np.random.default_rng(1).standard_normal((40, 6)).astype(np.float32)  # action 0's side
    dist, rows = search.search(queries, 20)
    assert rows.shape == (40, 20) and search.per(20) == 10
    assert np.all(np.diff(dist, axis=1) >= 0)                        # ascending
    for a in (0, 1):
        got = np.sort(np.where(actions[rows] == a, rows, -1), axis=1)[:, -10:]
        assert np.array_equal(got, _nearest_of(beliefs, queries, actions == a, 10))
    # the k nearest rows overall of these queries hold (almost) no rare action
    _, plain = index.search(queries, 20)
    assert (actions[plain] == 1).mean() < 0.05
    assert np.all((actions[rows] == 1).sum(1) == 10)
    # and the decomposition then weighs the rare action: the scores are no longer all 0
    dec = decompose(beliefs, queries, k=20, index=search)
    assert ((dec.rows >= 0) & (actions[np.maximum(dec.rows, 0)] == 1)).any()
    assert np.all((dec.rows >= 0).sum(1) <= 7)                       # still <= d_b + 1 rows


def test_selection_short_strata_and_the_evaluation_ivf():
    beliefs, actions = _corpus(2000, seed=2)
    queries = np.random.default_rng(3).standard_normal((30, 6)).astype(np.float32) + 1.0
    index = BeliefIndex.build(beliefs, kind="flat")
    keep = np.random.default_rng(4).random(len(beliefs)) < 0.5
    _, rows = PerAction(index, actions).search(queries, 16, keep)
    assert np.all(keep[rows])
    for a in (0, 1):
        got = np.sort(np.where(actions[rows] == a, rows, -1), axis=1)[:, -8:]
        assert np.array_equal(got, _nearest_of(beliefs, queries, keep & (actions == a), 8))
    # a stratum with fewer rows than asked: all of them, no padding beyond what exists
    few = actions.copy()
    few[np.flatnonzero(actions == 1)[3:]] = 0
    _, rows = PerAction(index, few).search(queries, 16)
    assert rows.shape == (30, 11) and np.all((few[rows] == 1).sum(1) == 3)
    # the evaluation's IVF structures: one per action (split), rows mapped back to the corpus's
    split = PerAction(BatchSearch(beliefs, seed=0), actions,
                      split=lambda rows: BatchSearch(beliefs[rows], seed=0))
    _, rows_ivf = split.search(queries, 16)
    _, rows_flat = PerAction(index, actions).search(queries, 16)
    assert np.mean(np.sort(rows_ivf, 1) == np.sort(rows_flat, 1)) > 0.95
    assert np.all((actions[rows_ivf] == 1).sum(1) == 8)
    _, rows_sel = split.search(queries, 16, keep)
    assert np.all(keep[rows_sel]) and np.all((actions[rows_sel] == 1).sum(1) == 8)
    # wrapped (as evaluate leaves the query's own episode out): each action's own search
    seen = []
    split.wrapped(lambda sub, rows: seen.append(len(rows)) or sub)
    assert sorted(seen) == sorted(np.bincount(actions).tolist())


def test_candidate_search_reads_the_index_record():
    beliefs, actions = _corpus(50)
    index = BeliefIndex.build(beliefs, kind="flat")
    assert candidate_search(index, None, None) is index        # an index that recorded none
    assert candidate_search(index, "nearest", actions) is index
    assert isinstance(candidate_search(index, "per_action", actions), PerAction)
    with pytest.raises(AocError, match="rebuild"):
        candidate_search(index, "sideways", actions)


def test_an_approximate_index_finds_a_far_action_exactly():
    """An IVF index restricted to a far action's rows visits lists near the query, where that
    action has few rows: the per-action search completes those queries exactly (the far
    action has over 4,096 rows, above which a restricted search is the index's own)."""
    beliefs, actions = _corpus(60000, seed=5)
    ivf = BeliefIndex.build(beliefs, kind="ivf", ivf_nlist=64, ivf_nprobe=1)
    q = np.zeros((1, 6), np.float32)                   # deep in action 0's cluster
    _, plain = ivf.search(q, 30, actions == 1)
    assert (plain < 0).any()                            # the restricted IVF search comes up short
    _, rows = PerAction(ivf, actions).search(q, 60)
    assert np.array_equal(np.sort(rows[actions[rows] == 1]),
                          _nearest_of(beliefs, q, actions == 1, 30)[0])


def test_the_index_rule_per_action_on_small_logs_only():
    from types import SimpleNamespace

    from aoc_cli.decompose.k_rule import SMALL_MAX_ROWS
    from aoc_cli.index import model_k

    def corpus(n):
        acts = (np.arange(n) % 10 == 0).astype(np.int64)        # the rare action: 10%
        return SimpleNamespace(n_rows=n, discrete=True, actions=acts, name="c")

    imitation, value = SimpleNamespace(mode="imitation", d_b=20), SimpleNamespace(mode="value", d_b=20)
    assert model_k(corpus(5000), imitation) == (126, "per_action")
    assert model_k(corpus(SMALL_MAX_ROWS + 10), imitation) == (210, "nearest")  # 21 / 0.1
    assert model_k(corpus(SMALL_MAX_ROWS + 10), imitation, "per_action") == (126, "per_action")
    assert model_k(corpus(5000), imitation, "nearest") == (42, "nearest")
    assert model_k(corpus(5000), value) == (42, "nearest")
