import numpy as np
import pytest

from aoc_cli.formats import ReadOptions, detect_format, ingest, read_dataset
from aoc_cli.store import Store
from tests.formats.sources import write_minari


@pytest.fixture
def minari_root(tmp_path, monkeypatch):
    root = tmp_path / "minari"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(root))
    return root


def test_minari_dict_observations_and_discrete_actions_round_trip(minari_root, tmp_path):
    _, buffers = write_minari("test/dict-v0", lengths=(6, 9, 4))
    folder = minari_root / "test" / "dict-v0" / "data"
    assert detect_format(folder) == "minari"
    ingest(folder, "m", store=Store(tmp_path / "s"))
    c = Store(tmp_path / "s").corpus("m")
    assert (c.n_rows, c.n_episodes) == (19, 3)
    np.testing.assert_array_equal(c.episode_starts, [0, 6, 15, 19])
    # sorted key order: pos (2 dims) then vel (1 dim); the final (T+1-th) observation dropped
    expected_obs = np.concatenate(
        [np.concatenate([b.observations["pos"][:-1], b.observations["vel"][:-1]], axis=1)
         for b in buffers])
    np.testing.assert_array_equal(c.observations, expected_obs)
    assert c.observation_space["keys"] == ["pos", "vel"]
    assert c.observation_space["names"] == ["pos[0]", "pos[1]", "vel"]
    assert c.discrete and c.n_actions == 3
    np.testing.assert_array_equal(c.actions, np.concatenate([b.actions for b in buffers]))
    np.testing.assert_allclose(c.rewards, np.concatenate([b.rewards for b in buffers]))
    np.testing.assert_allclose(c.episode_returns(), [np.sum(b.rewards) for b in buffers])
    np.testing.assert_array_equal(c.read("terminals"),
                                  np.concatenate([b.terminations for b in buffers]))
    np.testing.assert_array_equal(c.read("truncations"),
                                  np.concatenate([b.truncations for b in buffers]))
    assert c.load().episode_ids == ["0", "1", "2"]


def test_minari_dataset_id_box_spaces_and_info_tag(minari_root, tmp_path):
    _, buffers = write_minari("test/box-v0", lengths=(5, 3), dict_obs=False, discrete=False,
                              infos=True)
    assert detect_format("test/box-v0") == "minari"
    data = read_dataset("test/box-v0", options=ReadOptions(tag_columns=["policy"]))
    np.testing.assert_array_equal(data.observations,
                                  np.concatenate([b.observations[:-1] for b in buffers]))
    np.testing.assert_array_equal(data.actions, np.concatenate([b.actions for b in buffers]))
    assert data.action_space["low"] == [-1.0, -1.0] and data.observation_space["high"] == [5.0] * 3
    codes, labels = data.tags["policy"]
    assert labels == ["0", "1"] and codes.tolist() == [0] * 5 + [1] * 3
    assert data.source["dataset_id"] == "test/box-v0"


def test_truncated_minari_file_is_a_clear_error(minari_root):
    from aoc_cli.errors import AocError

    write_minari("test/cut-v0", lengths=(20,) * 5)
    path = minari_root / "test" / "cut-v0" / "data" / "main_data.hdf5"
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    with pytest.raises(AocError, match="truncated or corrupt"):
        read_dataset("test/cut-v0")


def test_unknown_minari_id_is_a_missing_path(minari_root):
    from aoc_cli.errors import AocError

    with pytest.raises(AocError, match="no such file or folder"):
        read_dataset("test/absent-v0")
