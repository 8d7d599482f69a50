import numpy as np
import pytest

from aoc_cli.errors import AocError
from aoc_cli.formats import ReadOptions, detect_format, ingest, read_dataset
from aoc_cli.store import Store
from tests.formats.sources import flat_arrays, write_d4rl


def assert_corpus_equals(corpus, exp):
    assert corpus.n_rows == len(exp.observations)
    assert corpus.n_episodes == len(exp.episode_starts) - 1
    np.testing.assert_array_equal(corpus.episode_starts, exp.episode_starts)
    np.testing.assert_array_equal(corpus.observations, exp.observations)
    np.testing.assert_array_equal(corpus.actions, exp.actions)
    np.testing.assert_array_equal(corpus.rewards, exp.rewards)
    np.testing.assert_array_equal(corpus.read("terminals"), exp.terminals)
    np.testing.assert_array_equal(corpus.read("truncations"), exp.truncations)
    np.testing.assert_allclose(corpus.episode_returns(), exp.returns)


def test_d4rl_round_trip_splits_at_terminals_and_timeouts_keeping_trailing_episode(tmp_path):
    arrays, exp = flat_arrays()
    path = write_d4rl(tmp_path / "hopper.hdf5", arrays)
    assert detect_format(path) == "d4rl"
    result = ingest(path, "hopper", store=Store(tmp_path / "store"))
    corpus = Store(tmp_path / "store").corpus("hopper")
    assert (result.rows, result.episodes) == (400, 4)
    assert list(exp.episode_starts) == [0, 50, 150, 300, 400]
    assert_corpus_equals(corpus, exp)
    # the trailing episode (rows 300..399) has neither flag: kept, truncated on its last row
    trunc = corpus.read("truncations")
    assert trunc[399] and not corpus.read("terminals")[399]
    # a timeout is a truncation, not a terminal
    assert trunc[149] and not corpus.read("terminals")[149]


def test_d4rl_row_that_is_terminal_and_timeout_is_a_terminal(tmp_path):
    arrays, _ = flat_arrays(n=20, ends=((9, "t"), (19, "o")))
    arrays["timeouts"][9] = True
    data = read_dataset(write_d4rl(tmp_path / "x.hdf5", arrays))
    assert data.terminals[9] and not data.truncations[9]
    assert list(data.episode_starts) == [0, 10, 20]


def test_d4rl_infos_give_tag_columns_and_numeric_columns(tmp_path):
    arrays, _ = flat_arrays(n=30, ends=((9, "t"), (29, "o")))
    policy = np.array([b"expert"] * 10 + [b"random"] * 20)
    path = write_d4rl(tmp_path / "x.hdf5", arrays,
                      infos={"policy": policy, "cost": np.arange(30.0)})
    data = read_dataset(path, options=ReadOptions(tag_columns=["policy"], tags={"site": "a"}))
    codes, labels = data.tags["policy"]
    assert labels == ["expert", "random"]
    np.testing.assert_array_equal(codes, [0] * 10 + [1] * 20)
    assert data.tags["site"][1] == ["a"]
    np.testing.assert_array_equal(data.columns["cost"], np.arange(30.0))


def test_npz_round_trip_equals_source(tmp_path):
    arrays, exp = flat_arrays(seed=3)
    path = tmp_path / "data.npz"
    np.savez(path, **arrays)
    assert detect_format(path) == "npz"
    ingest(path, "n", store=Store(tmp_path / "s"))
    assert_corpus_equals(Store(tmp_path / "s").corpus("n"), exp)


def test_npz_with_object_arrays_is_refused_not_unpickled(tmp_path):
    arrays, _ = flat_arrays(n=10, ends=((9, "t"),))
    arrays["observations"] = np.array([object()] * 10, dtype=object)
    path = tmp_path / "evil.npz"
    np.savez(path, **arrays)
    with pytest.raises(AocError, match="object arrays are refused"):
        read_dataset(path)


def test_integer_actions_are_discrete_and_reward_free_drops_rewards(tmp_path):
    arrays, _ = flat_arrays(n=20, ends=((19, "t"),))
    arrays["actions"] = np.arange(20) % 4
    data = read_dataset(write_d4rl(tmp_path / "x.hdf5", arrays),
                        options=ReadOptions(reward_free=True))
    assert data.action_space == {"type": "discrete", "n": 4}
    assert data.rewards is None
    np.testing.assert_array_equal(data.actions, np.arange(20) % 4)


def test_continuous_action_bounds_are_the_observed_range(tmp_path):
    arrays, _ = flat_arrays(n=20, ends=((19, "t"),))
    data = read_dataset(write_d4rl(tmp_path / "x.hdf5", arrays))
    np.testing.assert_allclose(data.action_space["low"], arrays["actions"].min(0))
    np.testing.assert_allclose(data.action_space["high"], arrays["actions"].max(0))
    assert data.action_space["bounds"] == "observed"
