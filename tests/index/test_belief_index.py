"""The FAISS belief index: exact and approximate search, selection, derived indexes, files."""

from __future__ import annotations

import json

import numpy as np
import pytest

from aoc_cli.errors import AocError
from aoc_cli.index.search import BeliefIndex, IndexConfig


def mixture(n: int, d: int = 20, centres: int = 50, seed: int = 0) -> np.ndarray:
    """Structured beliefs: a mixture of Gaussians with different spreads."""
    rng = np.random.default_rng(seed)
    means = rng.standard_normal((centres, d)) * 3
    scales = rng.uniform(0.3, 1.0, centres)
    which = rng.integers(0, centres, n)
    return (means[which] + rng.standard_normal((n, d)) * scales[which, None]).astype(np.float32)


def exact(beliefs: np.ndarray, queries: np.ndarray, k: int) -> np.ndarray:
    """Brute-force k nearest rows (float64)."""
    B = beliefs.astype(np.float64)
    Q = queries.astype(np.float64)
    d2 = (Q * Q).sum(1)[:, None] - 2 * Q @ B.T + (B * B).sum(1)[None, :]
    return np.argsort(d2, axis=1, kind="stable")[:, :k]


def recall(found: np.ndarray, truth: np.ndarray) -> float:
    return float(np.mean([len(set(f) & set(t)) / len(t) for f, t in zip(found, truth)]))


def control_step(beliefs: np.ndarray, q: int = 100, noise: float = 0.05, seed: int = 1) -> np.ndarray:
    """Queries like the candidates of one control step: a base belief plus small perturbations."""
    rng = np.random.default_rng(seed)
    base = beliefs[rng.integers(len(beliefs))]
    return base + noise * rng.standard_normal((q, beliefs.shape[1])).astype(np.float32)


@pytest.fixture(scope="module")
def corpus():
    return mixture(20_000)


@pytest.fixture(scope="module")
def built(corpus):
    """One index of each kind over the corpus, shared by the tests of this module."""
    cache = {}

    def get(kind: str) -> BeliefIndex:
        if kind not in cache:
            cache[kind] = BeliefIndex.build(corpus, kind=kind)
        return cache[kind]

    return get


def test_flat_search_is_exact_for_single_batched_and_spread_queries(corpus, built):
    index = built("flat")
    rng = np.random.default_rng(3)
    batches = [control_step(corpus, noise=n) for n in (0.01, 0.05, 0.2, 0.5)]  # pooled, grown, direct
    for queries in batches + [rng.standard_normal((30, 20)).astype(np.float32) * 3, corpus[:1]]:
        dist, rows = index.search(queries, 42)
        truth = exact(corpus, queries, 42)
        assert (np.sort(rows, 1) == np.sort(truth, 1)).all()
        np.testing.assert_allclose(dist, np.linalg.norm(corpus[rows] - queries[:, None], axis=-1), rtol=1e-5)
        assert (np.diff(dist, axis=1) >= 0).all()


@pytest.mark.parametrize("kind", ["hnsw", "ivf"])
def test_approximate_kinds_reach_recall_099_with_the_default_parameters(corpus, built, kind):
    index = built(kind)
    rng = np.random.default_rng(4)
    batches = [control_step(corpus, seed=s) for s in range(3)]
    batches.append(corpus[rng.integers(0, len(corpus), 100)] + 0.1 * rng.standard_normal((100, 20)).astype(np.float32))
    for queries in batches:
        _, rows = index.search(queries, 42)
        assert recall(rows, exact(corpus, queries, 42)) >= 0.99


@pytest.mark.parametrize("kind", ["flat", "hnsw", "ivf"])
def test_save_and_load_round_trip_gives_the_same_answers(corpus, kind, tmp_path):
    index = BeliefIndex.build(corpus[:5000], kind=kind)
    queries = control_step(corpus[:5000])
    before = index.search(queries, 10)
    path = tmp_path / "beliefs.faiss"
    index.save(path)
    assert json.loads((tmp_path / "beliefs.faiss.json").read_text())["kind"] == kind
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    for loaded in (BeliefIndex.load(path), BeliefIndex.load(path, beliefs=corpus[:5000])):
        assert loaded.kind == kind and loaded.size == 5000
        after = loaded.search(queries, 10)
        np.testing.assert_array_equal(before[1], after[1])
        np.testing.assert_allclose(before[0], after[0], rtol=1e-6)


def test_auto_kind_is_flat_for_small_corpora_and_approximate_for_large():
    config = IndexConfig()
    assert config.resolved_kind(10_000) == "flat"
    assert config.resolved_kind(600_000) == "ivf"
    assert config.resolved_kind(10_000_000) == "ivf"
    assert BeliefIndex.build(mixture(500, d=4)).kind == "flat"


@pytest.mark.parametrize("kind", ["flat", "hnsw", "ivf"])
def test_selection_by_mask_or_rows_never_returns_another_row(corpus, built, kind):
    index = built(kind)
    rng = np.random.default_rng(5)
    tags = rng.integers(0, 4, len(corpus))
    queries = control_step(corpus)
    for selection in (tags == 1, np.flatnonzero(tags == 2), np.flatnonzero(tags == 3)[:500]):
        prepared = index.select(selection)
        _, rows = index.search(queries, 42, selection=prepared)
        allowed = np.zeros(len(corpus), dtype=bool)
        allowed[selection] = True
        assert allowed[rows[rows >= 0]].all()
        sub = np.flatnonzero(allowed)
        truth = sub[exact(corpus[sub], queries, 42)]
        assert recall(rows, truth) >= (1.0 if kind == "flat" else 0.95)


def test_selection_that_leaves_no_rows_raises():
    index = BeliefIndex.build(mixture(100, d=3))
    with pytest.raises(AocError, match="leaves no corpus rows"):
        index.search(np.zeros((1, 3)), 5, selection=np.zeros(100, dtype=bool))
    with pytest.raises(AocError, match="one flag per row"):
        index.search(np.zeros((1, 3)), 5, selection=np.ones(7, dtype=bool))
    with pytest.raises(AocError, match=r"\[0, 100\)"):
        index.search(np.zeros((1, 3)), 5, selection=np.array([100]))
    other = index.subsample(0.5)
    with pytest.raises(AocError, match="another index"):
        other.search(np.zeros((1, 3)), 5, selection=index.select(np.arange(10)))


def test_resample_copies_rows_and_its_id_map_points_back_to_them():
    beliefs = mixture(1000, d=5)
    index = BeliefIndex.build(beliefs, kind="flat")
    mult = np.ones(1000)
    mult[:100] = 4.0  # "pi1" rows four times
    mult[900:] = 0.0
    derived = index.resample(mult)
    counts = np.bincount(derived.row_of, minlength=1000)
    assert (counts[:100] == 4).all() and (counts[100:900] == 1).all() and (counts[900:] == 0).all()
    assert derived.size == 400 + 800 and derived.n_rows == 1000
    np.testing.assert_array_equal(derived.vectors(np.arange(derived.size)), beliefs[derived.row_of])
    dist, rows = derived.search(beliefs[:3], 4)
    assert (rows[:, :4] == np.arange(3)[:, None]).all()  # a row's four copies come first
    np.testing.assert_allclose(dist, 0.0, atol=1e-6)


def test_subsample_keeps_an_exact_seeded_random_half():
    index = BeliefIndex.build(mixture(1000, d=5))
    frac = np.where(np.arange(1000) < 600, 0.5, 1.0)
    a = index.subsample(frac, seed=7)
    b = index.subsample(frac, seed=7)
    c = index.subsample(frac, seed=8)
    assert (a.row_of < 600).sum() == 300 and (a.row_of >= 600).sum() == 400
    np.testing.assert_array_equal(a.row_of, b.row_of)
    assert not np.array_equal(a.row_of, c.row_of)
    assert len(np.unique(a.row_of)) == a.size
    # a derived index of a derived index still maps to corpus rows
    quarter = a.subsample(0.5, seed=1)
    assert np.isin(quarter.row_of, a.row_of).all() and quarter.size == 350


def test_derived_index_saves_its_id_map(tmp_path):
    beliefs = mixture(300, d=4)
    derived = BeliefIndex.build(beliefs).resample(np.where(np.arange(300) < 30, 2.0, 1.0))
    derived.save(tmp_path / "d.faiss")
    loaded = BeliefIndex.load(tmp_path / "d.faiss", beliefs=beliefs)
    np.testing.assert_array_equal(loaded.row_of, derived.row_of)
    assert loaded.n_rows == 300


@pytest.mark.parametrize("kind", ["hnsw", "ivf"])
def test_resampling_an_approximate_index_keeps_its_kind(kind):
    beliefs = mixture(3000, d=8)
    derived = BeliefIndex.build(beliefs, kind=kind).subsample(0.5)
    assert derived.kind == kind and derived.size == 1500
    _, rows = derived.search(beliefs[derived.row_of[:5]], 1)
    assert (rows[:, 0] == derived.row_of[:5]).all()


def test_bad_resampling_and_search_input_raise():
    index = BeliefIndex.build(mixture(50, d=3))
    with pytest.raises(AocError, match="no corpus rows"):
        index.resample(0.0)
    with pytest.raises(AocError, match="non-negative"):
        index.resample(-1.0)
    with pytest.raises(AocError, match="one value per corpus row"):
        index.resample(np.ones(3))
    with pytest.raises(AocError, match=r"\[0, 1\]"):
        index.subsample(2.0)
    with pytest.raises(AocError, match="k must be at least 1"):
        index.search(np.zeros((1, 3)), 0)
    with pytest.raises(AocError, match="shape"):
        index.search(np.zeros((1, 4)), 3)
    with pytest.raises(AocError, match="NaN"):
        index.search(np.full((1, 3), np.nan), 3)
    with pytest.raises(AocError, match="unknown kind .lsh.: use auto, flat"):
        IndexConfig(kind="lsh")
    with pytest.raises(AocError, match="non-empty|no beliefs"):
        BeliefIndex.build(np.zeros((0, 3), dtype=np.float32))
