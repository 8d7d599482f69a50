import h5py
import numpy as np

from aoc_cli.formats import detect_format, ingest, read_dataset
from aoc_cli.store import Store
from tests.formats.sources import d3rlpy_episodes, write_d3rlpy


def test_d3rlpy_dump_round_trips_episodes_and_terminated_flags(tmp_path):
    eps = d3rlpy_episodes(lengths=(7, 12, 5))
    path = write_d3rlpy(tmp_path / "buffer.h5", eps)
    assert detect_format(path) == "d3rlpy"
    result = ingest(path, "b", store=Store(tmp_path / "s"))
    c = Store(tmp_path / "s").corpus("b")
    assert (result.rows, result.episodes) == (24, 3)
    np.testing.assert_array_equal(c.episode_starts, [0, 7, 19, 24])
    np.testing.assert_array_equal(c.observations, np.concatenate([e[0] for e in eps]))
    np.testing.assert_array_equal(c.actions, np.concatenate([e[1] for e in eps]))
    np.testing.assert_allclose(c.rewards, np.concatenate([e[2] for e in eps]))
    np.testing.assert_allclose(c.episode_returns(),
                               [e[2].astype(np.float64).sum() for e in eps])
    # episodes 0 and 2 terminated, episode 1 was cut off
    term, trunc = c.read("terminals"), c.read("truncations")
    assert np.flatnonzero(term).tolist() == [6, 23]
    assert np.flatnonzero(trunc).tolist() == [18]


def test_d3rlpy_discrete_actions_and_tuple_observations(tmp_path):
    eps = d3rlpy_episodes(lengths=(4, 6), d_o=5, discrete=True)
    data = read_dataset(write_d3rlpy(tmp_path / "b.h5", eps, tuple_obs=True))
    assert data.discrete and data.action_space["n"] == int(max(e[1].max() for e in eps)) + 1
    np.testing.assert_array_equal(data.actions, np.concatenate([e[1][:, 0] for e in eps]))
    # tuple parts observations_i_0 (first 2 dims) and observations_i_1 joined in order
    np.testing.assert_array_equal(data.observations, np.concatenate([e[0] for e in eps]))


def test_d3rlpy_v1_flat_dump_ends_episodes_at_episode_terminals(tmp_path):
    rng = np.random.default_rng(0)
    n = 10
    ep_end = np.zeros(n, np.float32)
    ep_end[[3, 9]] = 1
    term = np.zeros(n, np.float32)
    term[3] = 1  # episode 0 terminal, episode 1 timed out
    with h5py.File(tmp_path / "v1.h5", "w") as f:
        f["observations"] = rng.standard_normal((n, 2)).astype(np.float32)
        f["actions"] = rng.standard_normal((n, 1)).astype(np.float32)
        f["rewards"] = rng.standard_normal(n).astype(np.float32)
        f["terminals"] = term
        f["episode_terminals"] = ep_end
        f["discrete_action"] = False
    data = read_dataset(tmp_path / "v1.h5")
    assert data.source["format"] == "d3rlpy"
    assert list(data.episode_starts) == [0, 4, 10]
    assert data.terminals[3] and data.truncations[9] and not data.terminals[9]


def test_truncated_d3rlpy_dump_is_a_clear_error(tmp_path):
    import pytest

    from aoc_cli.errors import AocError

    path = write_d3rlpy(tmp_path / "b.h5", d3rlpy_episodes(lengths=(30,) * 10))
    path.write_bytes(path.read_bytes()[: path.stat().st_size * 3 // 4])
    with pytest.raises(AocError, match="truncated or corrupt"):
        read_dataset(path)
