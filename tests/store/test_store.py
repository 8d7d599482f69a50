import json
import os

import numpy as np
import pytest

from aoc_cli.errors import AocError, CorpusExists
from aoc_cli.store import CorpusData, Store, box_space, discrete_space, episode_starts_from_lengths


def make_data(lengths=(3, 5, 2), d_o=2, d_a=1, discrete=False, rewards=True, seed=0):
    rng = np.random.default_rng(seed)
    n = sum(lengths)
    obs = rng.standard_normal((n, d_o)).astype(np.float32)
    act = rng.integers(0, 3, n) if discrete else rng.standard_normal((n, d_a)).astype(np.float32)
    starts = episode_starts_from_lengths(lengths)
    term = np.zeros(n, bool)
    term[starts[1:] - 1] = True
    return CorpusData(
        observations=obs, actions=act,
        rewards=rng.standard_normal(n) if rewards else None,
        terminals=term, truncations=np.zeros(n, bool), episode_starts=starts,
        observation_space=box_space(d_o),
        action_space=discrete_space(3) if discrete else box_space(d_a),
        tags={"policy": (np.arange(n) % 2, ["a", "b"])},
    )


def test_write_then_read_round_trips_arrays_and_episodes(tmp_path):
    data = make_data()
    corpus = Store(tmp_path).write("c1", data)
    assert corpus.n_rows == 10 and corpus.n_episodes == 3
    np.testing.assert_array_equal(corpus.observations, data.observations)
    np.testing.assert_array_equal(corpus.actions, data.actions)
    np.testing.assert_array_equal(corpus.rewards, data.rewards)
    np.testing.assert_array_equal(corpus.episode_starts, [0, 3, 8, 10])
    np.testing.assert_array_equal(corpus.timesteps, [0, 1, 2, 0, 1, 2, 3, 4, 0, 1])
    codes, labels = corpus.tag("policy")
    assert labels == ["a", "b"] and list(codes[:3]) == [0, 1, 0]
    returns = corpus.episode_returns()
    np.testing.assert_allclose(returns[1], data.rewards[3:8].sum())


def test_history_is_previous_rows_of_same_episode_left_padded(tmp_path):
    data = make_data()
    corpus = Store(tmp_path).write("c1", data)
    h = corpus.history([0, 4, 7, 9], length=3)
    assert h.observations.shape == (4, 3, 2)
    # row 0: first of its episode -> nothing
    assert not h.mask[0].any()
    # row 4: episode starts at 3 -> only row 3 present, in the newest slot
    assert list(h.mask[1]) == [False, False, True]
    np.testing.assert_array_equal(h.observations[1, 2], data.observations[3])
    np.testing.assert_array_equal(h.observations[1, 0], 0)
    # row 7: rows 4, 5, 6 oldest first
    np.testing.assert_array_equal(h.observations[2], data.observations[4:7])
    np.testing.assert_allclose(h.rewards[2], data.rewards[4:7].astype(np.float32))
    # row 9: episode starts at 8
    assert list(h.mask[3]) == [False, False, True]


def test_history_of_length_zero_is_empty(tmp_path):
    corpus = Store(tmp_path).write("c1", make_data())
    h = corpus.history([1, 2], length=0)
    assert h.observations.shape == (2, 0, 2) and h.mask.shape == (2, 0)


def test_reward_free_and_discrete_corpora_are_first_class(tmp_path):
    corpus = Store(tmp_path).write("d", make_data(discrete=True, rewards=False))
    assert corpus.discrete and not corpus.has_rewards and corpus.rewards is None
    assert corpus.actions.dtype == np.int64
    h = corpus.history([5], 2)
    assert h.actions.shape == (1, 2) and (h.rewards == 0).all()


def test_existing_name_needs_overwrite_and_overwrite_replaces(tmp_path):
    store = Store(tmp_path)
    store.write("c", make_data(seed=0))
    with pytest.raises(CorpusExists, match="overwrite=True") as err:
        store.write("c", make_data(seed=1))
    assert err.value.name == "c"
    new = store.write("c", make_data(seed=1), overwrite=True)
    np.testing.assert_array_equal(new.observations, make_data(seed=1).observations)
    # no temporary folders left (the writer lock file .c.lock stays: it is never removed)
    assert sorted(p.name for p in tmp_path.iterdir()) == [".c.lock", "c"]


def test_append_concatenates_and_requires_same_spaces(tmp_path):
    store = Store(tmp_path)
    first = store.write("c", make_data(seed=0))
    h0 = first.hash
    both = store.write("c", make_data(seed=1), append=True)
    assert both.n_rows == 20 and both.n_episodes == 6 and both.hash != h0
    with pytest.raises(AocError, match="spaces"):
        store.write("c", make_data(d_o=3), append=True)


@pytest.mark.parametrize("name", ["../x", "a/b", "", ".hidden", "a..b"])
def test_invalid_names_are_refused(tmp_path, name):
    with pytest.raises(AocError, match="invalid corpus name"):
        Store(tmp_path).write(name, make_data())


def test_nonfinite_rows_are_named(tmp_path):
    data = make_data()
    data.observations[6, 1] = np.nan
    with pytest.raises(AocError, match="row 6"):
        Store(tmp_path).write("c", data)
    assert list(data.nonfinite_episodes()) == [False, True, False]
    kept = data.select_episodes(~data.nonfinite_episodes())
    assert Store(tmp_path).write("c", kept).n_rows == 5


def test_different_lengths_are_refused(tmp_path):
    data = make_data()
    data.rewards = data.rewards[:-1]
    with pytest.raises(AocError, match="different lengths"):
        Store(tmp_path).write("c", data)


def test_failed_write_leaves_previous_state(tmp_path, monkeypatch):
    store = Store(tmp_path)
    store.write("c", make_data(seed=0))
    before = json.loads((tmp_path / "c" / "manifest.json").read_text())
    import aoc_cli.store.writer as mod

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(mod, "_manifest", boom)
    with pytest.raises(KeyboardInterrupt):
        store.write("c", make_data(seed=1), overwrite=True)
    after = json.loads((tmp_path / "c" / "manifest.json").read_text())
    assert before == after
    assert sorted(os.listdir(tmp_path)) == [".c.lock", "c"]


def test_atomic_files_get_the_mode_of_a_plain_open(tmp_path):
    # mkstemp creates 0600 files; what the store writes is readable like any file it makes
    import os

    from aoc_cli.store.atomic import write_json

    old = os.umask(0o022)
    try:
        write_json(tmp_path / "a.json", {"x": 1})
        (tmp_path / "plain").write_text("x")
    finally:
        os.umask(old)
    assert (tmp_path / "a.json").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "plain").stat().st_mode & 0o777 == 0o644


def test_float_columns_are_contiguous_unless_other_dataset_options_are_passed(tmp_path):
    import h5py

    store = Store(tmp_path)
    plain = store.write("plain", make_data())
    packed = store.write("packed", make_data(), float_opts=dict(compression="gzip"))
    with h5py.File(plain.path / "corpus.h5") as f:
        assert f["observations"].chunks is None and f["observations"].compression is None
        assert f["terminals"].compression == "gzip"  # flags: always compressed
    with h5py.File(packed.path / "corpus.h5") as f:
        assert f["observations"].compression == "gzip"
    assert packed.hash == plain.hash  # the same content, stored differently
    np.testing.assert_array_equal(packed.load().observations, plain.load().observations)


def test_imputed_mask_and_preprocessing_are_stored_and_survive_append(tmp_path):
    store = Store(tmp_path)
    data = make_data()
    assert store.write("plain", data).imputed_mask is None
    mask = np.zeros(data.observations.shape, bool)
    mask[[1, 4], 0] = True
    data = make_data()
    data.imputed = mask
    data.preprocessing = {"impute": {"rule": "median", "medians": [0.5, 1.5]}}
    c = store.write("imp", data)
    np.testing.assert_array_equal(c.imputed_mask, mask)
    assert c.preprocessing["impute"]["medians"] == [0.5, 1.5]
    assert "imputed" in c.manifest["arrays"] and c.changed_arrays() == []
    c = store.write("imp", make_data(lengths=(2,)), append=True)  # nothing imputed in it
    assert c.imputed_mask.shape == (12, 2) and c.imputed_mask.sum() == 2
    np.testing.assert_array_equal(c.load().imputed, c.imputed_mask)
    assert c.preprocessing["impute"]["rule"] == "median"
