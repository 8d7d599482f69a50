"""Streaming training and chunked beliefs (aoc_cli.belief.stream): a block's history windows
are the in-memory path's, the chunked beliefs are the in-memory beliefs, and a model trained
by streaming small blocks learns a value that needs the history."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from aoc_cli.belief import BeliefConfig, load_model, train_model
from aoc_cli.belief.stream import Columns, block_inputs, blocks, train_streaming, \
    write_row_beliefs
from aoc_cli.belief.inputs import encode_corpus
from aoc_cli.store import Store
from tests.belief.corpora import history_dependent

# varying episode lengths, so blocks and history windows cross episode starts unevenly
LENGTHS = np.random.default_rng(3).integers(1, 60, 90)


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    data = history_dependent(episodes=120, length=40, seed=0)
    store = Store.open(tmp_path_factory.mktemp("stream") / "store")
    return store.write("hist", data)


def test_blocks_cut_at_episode_starts_and_cover_every_row_once():
    starts = np.concatenate([[0], np.cumsum(LENGTHS)])
    ranges = blocks(starts, block_rows=100)
    assert ranges[0][0] == 0 and ranges[-1][1] == starts[-1]
    assert all(b == c for (_a, b), (c, _d) in zip(ranges, ranges[1:]))
    assert all(a in starts and b in starts and b > a for a, b in ranges)
    # a block is cut at the first episode start at or after block_rows (or holds one episode)
    assert all(b - a <= 100 + LENGTHS.max() for a, b in ranges)


def test_block_inputs_are_the_in_memory_encoding_of_the_same_rows(corpus):
    model_cfg = BeliefConfig(max_epochs=1, history_length=4, seed=0, threads=1)
    train_model(corpus, model_cfg, "m", overwrite=True)
    model = load_model(corpus, "m")
    device = model.device  # the encoder's (a GPU when torch sees one)
    full = encode_corpus(corpus, model.encoder, 4, True, device)
    cols = Columns(corpus)
    for a, b in [(0, 37), (37, 1000), (1001, 1002), (4790, corpus.n_rows)]:
        inputs, lo = block_inputs(cols, model.encoder, a, b, 4, True, device)
        got = inputs.batch(torch.arange(a - lo, b - lo, device=device))
        want = full.batch(torch.arange(a, b, device=device))
        for g, w in zip(got, want):
            assert torch.equal(g, w)


def test_chunked_beliefs_equal_the_in_memory_beliefs(corpus, tmp_path, monkeypatch):
    import aoc_cli.belief.stream as stream

    train_model(corpus, BeliefConfig(max_epochs=1, seed=1, threads=1), "b", overwrite=True)
    model = load_model(corpus, "b")
    monkeypatch.setattr(stream, "BELIEF_BATCH", 1000)  # several chunks on a small corpus
    path = write_row_beliefs(model, corpus, tmp_path / "beliefs.npy")
    got = np.load(path, mmap_mode="r")
    want = model.row_beliefs(corpus, batch=1000)
    assert got.shape == want.shape and got.dtype == np.float32
    np.testing.assert_array_equal(got, want)
    assert [p.name for p in tmp_path.iterdir()] == ["beliefs.npy"]  # no temporary left


def test_streaming_training_learns_a_value_that_needs_the_history(corpus):
    fast = dict(value="reward", max_epochs=15, patience=15, seed=0, threads=1, batch_size=250,
                hidden=64)
    cfg = BeliefConfig(history_length=2, **fast)
    metrics = train_streaming(corpus, cfg, "s", overwrite=True, block_rows=600)
    assert metrics["streamed"] and metrics["epochs"] == 15
    model = load_model(corpus, "s")
    assert model.history_length == 2 and len(model.values) == corpus.n_rows
    # the same data without the history cannot explain the value: streaming must use it
    flat = train_streaming(corpus, BeliefConfig(history_length=0, **fast), "flat",
                           overwrite=True, block_rows=600)
    assert metrics["val_r2"] > 0.95          # as the in-memory path (tests/belief/test_train.py)
    assert flat["val_r2"] < 0.1


def test_train_model_streams_a_large_corpus_and_honours_save(corpus, monkeypatch):
    import aoc_cli.belief.stream as stream

    monkeypatch.setattr(stream, "STREAM_ROWS", 1000)  # this corpus counts as large
    cfg = BeliefConfig(value="reward", history_length=2, max_epochs=1, seed=0, threads=1)
    metrics = train_model(corpus, cfg, "probe", overwrite=True, save=False, extra={"x": 1})
    assert metrics["streamed"] and metrics["x"] == 1
    assert not (corpus.models_dir / "probe").exists()
    # the dynamics head and the other belief kinds train in memory
    assert not stream.streams(corpus, BeliefConfig(dynamics_weight=1.0))
    assert not stream.streams(corpus, BeliefConfig(belief="reward"))


@pytest.mark.parametrize("value", ["return", "mean-return", "reward"])
def test_block_value_targets_are_the_whole_column_targets(corpus, value):
    from aoc_cli.belief.stream import block_value_targets
    from aoc_cli.belief.targets import value_targets

    cols = Columns(corpus)
    got = block_value_targets(corpus, cols, blocks(cols.starts, 333), value, 0.9)
    np.testing.assert_array_equal(got, value_targets(corpus, value, 0.9))


def test_streaming_training_applies_the_weight_decay(corpus):
    """--weight-decay reaches the streamed optimiser as the in-memory one (it was ignored)."""
    fast = dict(value="reward", max_epochs=3, patience=3, seed=0, threads=1, batch_size=250,
                hidden=32, history_length=0)

    def norm(model_id, decay):
        train_streaming(corpus, BeliefConfig(weight_decay=decay, **fast), model_id,
                        overwrite=True, block_rows=600)
        net = load_model(corpus, model_id).net
        return float(torch.sqrt(sum((p.detach() ** 2).sum() for p in net.parameters())))

    assert norm("wd", 0.5) < 0.9 * norm("plain", 0.0)
