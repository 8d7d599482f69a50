"""The distance over the cells both rows measured (aoc_cli.index.search.masked), and rule 7's
neighbourhood on a log with filled gaps: against a brute-force reference, on noisy features
whose held cells repeat an earlier state's values."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from aoc_cli.index.search.masked import MaskedIndex, brute_force, pack
from aoc_cli.index.search.neighbourhood import Neighbourhood, measured_cells


def _reference(x, m, q, qm):
    """(S, N) the masked mean distance, cell by cell in plain Python loops over numpy rows."""
    out = np.full((len(q), len(x)), np.inf)
    for i in range(len(q)):
        for j in range(len(x)):
            both = qm[i] & m[j]
            if both.any():
                out[i, j] = float(np.mean((q[i, both] - x[j, both]) ** 2))
    return out


def test_the_brute_force_distance_is_the_mean_over_the_common_cells():
    rng = np.random.default_rng(0)
    x, m = rng.normal(size=(40, 7)), rng.random((40, 7)) > 0.3
    m[3] = False                                       # a row with no measured cell
    q, qm = rng.normal(size=(9, 7)), rng.random((9, 7)) > 0.3
    got, want = brute_force(x, m, q, qm), _reference(x, m, q, qm)
    assert np.array_equal(np.isinf(got), np.isinf(want)) and np.isinf(got[:, 3]).all()
    fin = np.isfinite(want)
    assert np.allclose(got[fin], want[fin], rtol=1e-9, atol=1e-12)


def test_pack_counts_the_common_cells_of_wide_rows():
    rng = np.random.default_rng(1)
    a, b = rng.random((30, 130)) > 0.4, rng.random((30, 130)) > 0.4   # three 64-bit words
    common = np.bitwise_count(pack(a) & pack(b)).sum(1)
    assert (common == (a & b).sum(1)).all()


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(1, 300), d=st.integers(1, 70),
       gap=st.floats(0.0, 0.6), dup=st.booleans())
def test_the_k_nearest_are_the_brute_force_search_s(seed, n, d, gap, dup):
    """Inside, on and outside the log's spread, duplicates and rows with few common cells:
    the index's k nearest have the reference's distances (the candidates every row here)."""
    rng = np.random.default_rng(seed)
    x = rng.normal(size=(n, d))
    if dup:
        x[n // 2:] = x[: n - n // 2]                   # every row twice
    m = rng.random((n, d)) >= gap
    q = np.concatenate([x[:3], rng.normal(0, 4, size=(3, d))])[: max(1, min(6, n))]
    qm = rng.random(q.shape) >= gap
    k = min(10, n)
    dist, rows = MaskedIndex(x, m).search(q, qm, k)
    ref = brute_force(x, m, q, qm | ~qm.any(1, keepdims=True))   # none measured: every cell
    want = np.sort(ref, axis=1)[:, :k]
    fin = np.isfinite(want)
    assert np.array_equal(np.isfinite(dist), fin)
    # float32 inner products: a few ulp of the squared norms
    tol = 1e-5 * (1.0 + (x ** 2).sum(1).max() + (q ** 2).sum(1).max())
    assert np.allclose(dist[fin], want[fin], atol=tol)
    got = np.take_along_axis(ref, rows, 1)             # each returned row's true distance
    assert np.allclose(got[fin], dist[fin], atol=tol)
    assert (np.diff(dist, axis=1)[fin[:, 1:]] >= -tol).all()        # nearest first


def test_a_query_that_measured_no_cell_is_read_over_every_cell():
    """Every value filled (held from its history): over its measured cells every row would be
    infinitely far, so its filled values are read, as a query that measured them all."""
    rng = np.random.default_rng(5)
    x = rng.normal(size=(200, 6))
    m = rng.random(x.shape) >= 0.2
    q = rng.normal(size=(3, 6))
    index = MaskedIndex(x, m)
    none, every = index.search(q, np.zeros(q.shape, bool), 10), index.search(q, np.ones(
        q.shape, bool), 10)
    assert np.isfinite(none[0]).all()
    assert (none[1] == every[1]).all() and np.allclose(none[0], every[0], rtol=1e-12)


def test_the_candidates_hold_the_exact_nearest_on_a_log_with_held_gaps():
    """Fewer candidates than rows: the penalised inner product still ranks the exact 50
    nearest among its 400 candidates (states seen through noise, 15% of cells held)."""
    obs, measured, state = _held_log(seed=2)
    x = (obs - obs.mean(0)) / obs.std(0)
    index = MaskedIndex(x, measured, candidates=400)
    q = np.arange(0, len(x), 37)
    _, rows = index.search(x[q], measured[q], 50)
    ref = np.argsort(brute_force(x, measured, x[q], measured[q]), axis=1)[:, :50]
    recall = np.mean([np.isin(ref[i], rows[i]).mean() for i in range(len(q))])
    assert recall > 0.99, recall


def _held_log(seed=0, states=8, episodes=120, length=6, d=20, noise=0.3, gap=0.15, spread=3.0):
    """Episodes walking between well-separated states through noise; a gap cell holds the
    episode's previous value (as ``--impute hold``), never on an episode's first step.
    Returns (observations, measured, state)."""
    rng = np.random.default_rng(seed)
    centres = rng.normal(0, spread, size=(states, d))
    state = rng.integers(0, states, size=episodes * length)
    obs = centres[state] + rng.normal(0, noise, size=(len(state), d))
    measured = rng.random(obs.shape) >= gap
    measured[::length] = True
    for i in range(len(obs)):
        if i % length:
            obs[i, ~measured[i]] = obs[i - 1, ~measured[i]]
    return obs, measured, state


def test_leaving_the_held_cells_out_finds_the_state_s_own_rows():
    """Over every cell a held row sits between its state and the one it left; over the
    measured cells it sits with its own state's rows: purer neighbourhoods (states close
    beside the noise: measured 0.887 over every cell, 0.953 over the measured ones)."""
    obs, measured, state = _held_log(seed=3, spread=0.4)
    action, episode = np.zeros(len(obs), np.int64), np.repeat(np.arange(120), 6)
    plain = Neighbourhood(obs, action, episode, 1, nearest=40)
    masked = Neighbourhood(obs, action, episode, 1, nearest=40, measured=measured)
    assert plain.masked is None and masked.masked is not None
    purity = {}
    for name, hood in (("plain", plain), ("masked", masked)):
        rows = hood.rows(obs, measured if hood.masked is not None else None)
        purity[name] = float((state[rows] == state[:, None]).mean())
    assert purity["masked"] > purity["plain"] + 0.04, purity
    assert masked.describe()["distance"] == "measured cells"


def test_a_log_without_gaps_keeps_the_plain_search():
    obs, measured, _ = _held_log(seed=4, gap=0.0)
    hood = Neighbourhood(obs, np.zeros(len(obs), np.int64), np.zeros(len(obs), np.int64), 1,
                         measured=measured)
    assert hood.masked is None and hood.describe()["distance"] == "l2"


def test_measured_cells_reads_a_corpus_s_imputed_mask():
    class Stored:                                   # a store's Corpus
        imputed_mask = np.array([[True, False], [False, False]])

    class InMemory:                                 # a CorpusData
        imputed = np.zeros((2, 2), bool)

    assert (measured_cells(Stored()) == np.array([[False, True], [True, True]])).all()
    assert measured_cells(InMemory()) is None       # nothing filled: no mask
    with pytest.raises(ValueError, match="does not match"):
        MaskedIndex(np.zeros((3, 2)), np.ones((3, 3), bool))
