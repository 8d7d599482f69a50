"""``aoc export`` then ``aoc ingest`` gives the same corpus, for every format, every built-in
task and every ingest fixture: the same content hash, spaces, tag labels and episode ids."""

import json

import h5py
import numpy as np
import pytest

from aoc_cli.envs import TASKS
from aoc_cli.formats import export, ingest, read_dataset
from aoc_cli.store import Store
from tests.formats import export_corpora

NAMES = list(TASKS) + ["fixture-d4rl", "fixture-npz", "fixture-d3rlpy",
                       "fixture-d3rlpy-discrete", "fixture-minari-dict", "fixture-minari-box",
                       "fixture-csv", "fixture-csv-reward-free", "fixture-csv-mapped",
                       "labelled", "appended"]
SUFFIX = {"minari": "", "d4rl": ".hdf5", "csv": ".csv"}


@pytest.fixture(scope="module")
def corpora(tmp_path_factory):
    root = tmp_path_factory.mktemp("export")
    minari_root = root / "minari"
    mp = pytest.MonkeyPatch()
    mp.setenv("MINARI_DATASETS_PATH", str(minari_root))
    (root / "scratch").mkdir()
    names = export_corpora.build(root / "store", root / "scratch", minari_root)
    assert names == NAMES
    yield Store(root / "store"), root
    mp.undo()


def same_corpus(a, b):
    """Everything a corpus is, compared: the content hash covers the arrays."""
    assert b.hash == a.hash
    for key in ("rows", "episodes", "observation_space", "action_space", "has_rewards",
                "tags", "columns"):
        assert b.manifest[key] == a.manifest[key], key
    assert b.episode_ids == a.episode_ids
    # the hash, recomputed from the arrays read back, is the recorded one
    assert b.content_hash() == a.hash


def round_trip(store, root, name, fmt, **kw):
    out = root / "out" / fmt / f"{name}{SUFFIX[fmt]}"
    result = export(name, fmt, out, store=store, overwrite=True, **kw)
    assert result.content_hash == store.corpus(name).hash or kw
    back = f"{name}-from-{fmt}"
    ingest(out, back, store=store, overwrite=True)
    return store.corpus(back), out


@pytest.mark.parametrize("name", NAMES)
def test_d4rl_export_reads_back_as_the_same_corpus(corpora, name):
    store, root = corpora
    back, _ = round_trip(store, root, name, "d4rl")
    same_corpus(store.corpus(name), back)


@pytest.mark.parametrize("name", NAMES)
def test_minari_export_reads_back_as_the_same_corpus(corpora, name):
    store, root = corpora
    back, _ = round_trip(store, root, name, "minari")
    same_corpus(store.corpus(name), back)


@pytest.mark.parametrize("name", NAMES)
def test_csv_export_reads_back_as_the_same_corpus(corpora, name):
    store, root = corpora
    back, _ = round_trip(store, root, name, "csv")
    same_corpus(store.corpus(name), back)


def test_the_test_corpora_hold_what_round_trips_lose_first(corpora):
    store, _ = corpora
    lab = store.corpus("labelled")
    assert lab.action_space["names"] == ["none", "low", "mid", "high"] and not lab.has_rewards
    assert lab.episode_ids == ["z9", "a1", "m5", "b2"]
    assert store.corpus("appended").manifest["tags"]["site"] == ["north", "east"]
    assert np.isnan(store.corpus("appended").column("score")).sum() == 120
    assert np.isnan(store.corpus("labelled").column("score")).any()
    assert store.corpus("fixture-csv").observation_space["static"] == ["age", "sex=F", "sex=M"]
    assert store.corpus("ward").discrete and store.corpus("ward").episode_ids[0] == "p0000"


def test_d4rl_file_has_the_d4rl_keys_and_flags_every_episode_end(corpora):
    store, root = corpora
    _, out = round_trip(store, root, "labelled", "d4rl")
    c = store.corpus("labelled")
    with h5py.File(out) as f:
        assert {"observations", "actions", "terminals", "timeouts", "infos"} <= set(f)
        assert "rewards" not in f  # reward-free: no made-up zeros
        assert f["observations"].shape == (c.n_rows, 3) and f["actions"].dtype == np.int64
        ends = np.flatnonzero(f["terminals"][()] | f["timeouts"][()]) + 1
        np.testing.assert_array_equal(ends, c.episode_starts[1:])
        assert json.loads(f["infos/arm"].attrs["labels"]) == ["treated", "control", "unused"]
        spec = json.loads(f["metadata/aoc"][()])
        assert spec["unflagged_ends"] == [2] and spec["episode_ids"] == c.episode_ids


def test_csv_has_one_row_a_step_with_named_columns_and_labels(corpora):
    store, root = corpora
    _, out = round_trip(store, root, "pendulum-het", "csv")
    header, *rows = out.read_text().splitlines()
    c = store.corpus("pendulum-het")
    assert header.split(",") == ["id", "t", "cos_theta", "sin_theta", "theta_dot", "torque",
                                 "reward", "terminal", "truncated", "system", "policy"]
    assert len(rows) == c.n_rows
    first = rows[0].split(",")
    assert first[:2] == ["0", "0"] and np.float32(first[2]) == c.observations[0, 0]
    codes, labels = c.tag("policy")
    assert first[-1] == labels[codes[0]]


def test_csv_static_covariates_go_to_their_own_file_and_come_back(corpora):
    store, root = corpora
    static = root / "out" / "static" / "ward-static.csv"
    back, out = round_trip(store, root, "ward", "csv", static=static)
    same_corpus(store.corpus("ward"), back)
    names = store.corpus("ward").observation_space["names"]
    header = out.read_text().splitlines()[0].split(",")
    assert not set(store.corpus("ward").observation_space["static"]) & set(header)
    assert names[0] in header
    s_header, *s_rows = static.read_text().splitlines()
    assert s_header.split(",")[:2] == ["id", "age"] and "sex" in s_header.split(",")
    assert len(s_rows) == store.corpus("ward").n_episodes
    assert {r.split(",")[s_header.split(",").index("sex")] for r in s_rows} == {"F", "M"}


def test_csv_static_of_a_corpus_without_covariates_is_refused(corpora):
    from aoc_cli.errors import AocError

    store, root = corpora
    with pytest.raises(AocError, match="no per-patient covariates"):
        export("maze", "csv", root / "out" / "m.csv", store=store, static=root / "s.csv")


def test_selection_exports_the_selected_rows_whole_episodes_kept(corpora):
    store, root = corpora
    c = store.corpus("maze")
    codes, labels = c.tag("policy")
    back, _ = round_trip(store, root, "maze", "d4rl", select={"policy": [labels[codes[0]]]})
    keep = codes == codes[0]
    assert back.n_rows == int(keep.sum())
    np.testing.assert_array_equal(back.observations, c.observations[keep])
    np.testing.assert_array_equal(back.read("truncations"), c.read("truncations")[keep])
    assert back.manifest["tags"] == c.manifest["tags"]


def test_a_selection_that_cuts_an_episode_truncates_it_there(corpora):
    from aoc_cli.formats.export import select_rows

    data = store_data = corpora[0].corpus("labelled").load()
    mask = np.ones(data.n_rows, bool)
    mask[2] = False  # episode z9 (rows 0..4) splits into rows 0..1 and 3..4
    out = select_rows(store_data, mask)
    assert out.episode_starts.tolist() == [0, 2, 4, 7, 13, 15]
    assert out.episode_ids == ["z9#1", "z9#2", "a1", "m5", "b2"]
    assert out.truncations[1] and not out.terminals[1]


def test_minari_export_loads_in_minari_by_id_without_an_environment(corpora, monkeypatch):
    import minari

    store, root = corpora
    home = root / "minari-home"
    monkeypatch.setenv("MINARI_DATASETS_PATH", str(home))
    export("ward", "minari", home / "aoc" / "ward-v0", store=store)
    ds = minari.load_dataset("aoc/ward-v0")
    c = store.corpus("ward")
    assert ds.total_episodes == c.n_episodes and ds.total_steps == c.n_rows
    assert ds.spec.env_spec is None
    meta = json.loads((home / "aoc" / "ward-v0" / "data" / "metadata.json").read_text())
    assert meta["aoc"]["episode_ids"] == c.episode_ids
    assert meta["aoc"]["tags"] == c.manifest["tags"]
    ep = next(iter(ds.iterate_episodes([1])))
    a, b = c.episode_starts[1], c.episode_starts[2]
    np.testing.assert_array_equal(ep.observations[:-1], c.observations[a:b])
    np.testing.assert_array_equal(ep.observations[-1], c.observations[b - 1])
    np.testing.assert_array_equal(ep.actions, c.actions[a:b])
    np.testing.assert_array_equal(ep.infos["clinician"][:-1], c.tag("clinician")[0][a:b])


def test_reading_an_export_without_its_metadata_still_reads_the_rows(corpora):
    store, root = corpora
    _, out = round_trip(store, root, "lunar", "csv")
    (out.parent / "lunar.columns.json").rename(out.parent / "lunar.mapping.json")
    data = read_dataset(out, options=read_options(act="main_engine,side_engine"))
    c = store.corpus("lunar")
    # the rows read as a plain CSV (float64); the shortest float32 text rounds back exactly
    assert data.observations.dtype == np.float64 and "exported_from" not in data.source
    np.testing.assert_array_equal(data.observations.astype(np.float32), c.observations[:, :2])
    assert data.n_episodes == c.n_episodes


def read_options(act):
    from aoc_cli.formats import ReadOptions

    return ReadOptions(obs_columns=["x", "y"], act_columns=act.split(","))


def test_csv_labelled_discrete_actions_are_written_as_codes_with_their_labels(corpora):
    store, root = corpora
    back, out = round_trip(store, root, "labelled", "csv")
    header, *rows = out.read_text().splitlines()
    header = header.split(",")
    c = store.corpus("labelled")
    assert header[:2] == ["id", "t"] and "reward" not in header
    codes = [int(r.split(",")[header.index("action")]) for r in rows]
    text = [r.split(",")[header.index("action_label")] for r in rows]
    assert codes == c.actions.tolist()
    assert text == [c.action_space["names"][a] for a in c.actions]
    assert "action_label" not in back.manifest["columns"]


def test_minari_export_never_touches_the_users_minari_folder(corpora, monkeypatch, tmp_path):
    import os

    store, _ = corpora
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.delenv("MINARI_DATASETS_PATH", raising=False)
    (tmp_path / "home").mkdir()
    export("maze", "minari", tmp_path / "out" / "maze-v0", store=store)
    assert not (tmp_path / "home" / ".minari").exists()
    assert "MINARI_DATASETS_PATH" not in os.environ
    assert sorted(os.listdir(tmp_path / "out")) == ["maze-v0"]
    assert sorted(os.listdir(tmp_path / "out" / "maze-v0")) == ["data"]


@pytest.mark.parametrize("fmt", ["d4rl", "minari"])
def test_an_export_that_fails_midway_leaves_nothing_and_the_old_file_intact(
        corpora, monkeypatch, tmp_path, fmt):
    import os

    import minari.dataset.minari_storage as storage

    store, _ = corpora
    out = tmp_path / ("m.hdf5" if fmt == "d4rl" else "m-v0")
    export("maze", fmt, out, store=store)
    before = sorted(p.name for p in out.rglob("*")) if out.is_dir() else out.read_bytes()

    def fail(*args, **kwargs):
        raise OSError("disk full")

    if fmt == "d4rl":
        monkeypatch.setattr(h5py.Group, "create_dataset", fail)
    else:
        monkeypatch.setattr(storage.MinariStorage, "update_metadata", fail)
    with pytest.raises(OSError, match="disk full"):
        export("lunar", fmt, out, store=store, overwrite=True)
    assert os.listdir(tmp_path) == [out.name]
    after = sorted(p.name for p in out.rglob("*")) if out.is_dir() else out.read_bytes()
    assert after == before


def test_an_export_edited_afterwards_reads_as_it_is_with_a_warning_or_a_clear_error(
        corpora):
    from aoc_cli.errors import AocError, AocWarning

    store, root = corpora
    _, out = round_trip(store, root, "two-gates", "csv")
    lines = out.read_text().splitlines()
    cells = lines[1].split(",")
    cells[2] = "0.5"  # one observation changed by hand
    out.write_text("\n".join([lines[0], ",".join(cells)] + lines[2:]) + "\n")
    with pytest.warns(AocWarning, match="differ from the corpus 'two-gates'"):
        data = read_dataset(out)
    assert data.observations[0, 0] == np.float32(0.5)
    out.write_text("\n".join(lines[:-1]) + "\n")  # the last row removed
    with pytest.raises(AocError, match="edited after export"):
        read_dataset(out)
