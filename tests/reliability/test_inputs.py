"""Hostile input to the readers (issue 13, internal errors and silently accepted input): each
case is one line and exit 2 with the store unchanged, or a valid corpus (with a warning where
the input was taken in a way the user may not have meant)."""

from __future__ import annotations

import gzip

import h5py
import numpy as np
import pytest

from tests.conftest import run_in_process
from tests.formats.sources import flat_arrays, write_csv
from tests.reliability.common import one_line_error, snapshot


@pytest.fixture
def aoc(capsys):
    return lambda *args: run_in_process(capsys, *args)


def warnings_of(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.startswith("aoc: warning: ")]


def test_strings_in_hdf5_observations(store, aoc, tmp_path):
    arrays, _ = flat_arrays(n=50, ends=((9, "t"),))
    path = tmp_path / "s.hdf5"
    with h5py.File(path, "w") as f:
        for k, v in arrays.items():
            f[k] = v
        del f["observations"]
        f["observations"] = np.array([b"abc"] * 50)
    one_line_error(*aoc("ingest", str(path), "--name", "x"),
                   rf"{path}: observations holds \|S3 values, not numbers")
    assert snapshot(store) == {}


def test_minari_metadata_without_content(store, aoc, tmp_path):
    folder = tmp_path / "ds" / "data"
    folder.mkdir(parents=True)
    (folder / "metadata.json").write_text("{}")
    with h5py.File(folder / "main_data.hdf5", "w") as f:
        f.create_group("episode_0")
    line = one_line_error(*aoc("ingest", str(tmp_path / "ds"), "--name", "x"),
                          r"cannot read Minari dataset .*re-download")
    assert "metadata.json" in line or "KeyError" in line or ":" in line


def test_corrupt_gzip_body(store, aoc, tmp_path):
    path = tmp_path / "log.csv.gz"
    body = gzip.compress(b"episode,t,obs_0,act_0\n" + b"1,0,0.5,1\n" * 2000)
    path.write_bytes(body[:40] + bytes(200) + body[240:])
    one_line_error(*aoc("ingest", str(path), "--name", "x"),
                   r"cannot read .*log.csv.gz as UTF-8 text .*gzip")


def test_random_bytes_named_npz_are_not_called_pickled(store, aoc, tmp_path):
    path = tmp_path / "x.npz"
    path.write_bytes(np.random.default_rng(0).bytes(3000))
    line = one_line_error(*aoc("ingest", str(path), "--name", "x"), r"not an NPZ archive")
    assert "pickle" not in line and "object" not in line


def test_a_pickled_npz_is_refused_not_unpickled(store, aoc, tmp_path):
    path = tmp_path / "p.npz"
    np.savez(path, observations=np.array([{"a": 1}] * 4, dtype=object),
             actions=np.zeros((4, 1)))
    one_line_error(*aoc("ingest", str(path), "--name", "x"), r"object arrays are refused")


def csv_log(tmp_path, rows, header=("episode", "t", "obs_0", "act_0", "reward")):
    return write_csv(tmp_path / "log.csv", list(header), rows)


def test_repeated_id_and_time_is_refused_and_empty_ids_warn(store, aoc, tmp_path):
    path = csv_log(tmp_path, [(1, 0, 0.1, 1, 0), (1, 1, 0.3, 1, 0), (2, 0, 0.2, 0, 1),
                              (1, 0, 0.2, 0, 1)])
    one_line_error(*aoc("ingest", str(path), "--name", "x"),
                   r"data rows 1 and 4 are both at \(episode 1, t 0\)")
    path = csv_log(tmp_path, [(1, 0, 0.1, 1, 0), ("", 0, 0.4, 1, 0), (2, 0, 0.5, 0, 1)])
    code, _out, err = aoc("ingest", str(path), "--name", "x")
    assert code == 0, err
    assert any("empty 'episode' cell" in w for w in warnings_of(err)), err


def test_static_ids_not_in_the_series_warn(store, aoc, tmp_path):
    path = csv_log(tmp_path, [(1, 0, 0.1, 1, 0), (2, 0, 0.2, 0, 1)])
    static = write_csv(tmp_path / "static.csv", ["episode", "age"], [(1, 40), (2, 50), (3, 60)])
    code, _out, err = aoc("ingest", str(path), "--name", "x", "--static", str(static))
    assert code == 0, err
    assert any("1 ids have no rows in the series (first: '3')" in w
               for w in warnings_of(err)), err


def test_append_to_a_missing_corpus_warns_and_creates_it(store, aoc, tmp_path):
    path = csv_log(tmp_path, [(1, 0, 0.1, 1, 0), (2, 0, 0.2, 0, 1)])
    code, _out, err = aoc("ingest", str(path), "--name", "x", "--append")
    assert code == 0, err
    assert warnings_of(err) == [f"aoc: warning: --append: corpus 'x' does not exist in "
                                f"{store}; creating it"]


def test_observations_of_more_than_one_dimension_are_flattened_with_a_warning(store, aoc,
                                                                               tmp_path):
    path = tmp_path / "img.npz"
    np.savez(path, observations=np.zeros((20, 2, 3), np.float32),
             actions=np.zeros((20, 1), np.float32), rewards=np.zeros(20))
    code, _out, err = aoc("ingest", str(path), "--name", "x")
    assert code == 0, err
    assert warnings_of(err) == ["aoc: warning: observations of shape (20, 2, 3) are flattened "
                                "to (20, 6), row-major"]


@pytest.mark.parametrize("args,pattern", [
    (("--audit", "{store}/m/corpus.h5"), r"--audit .* is inside the corpus store"),
    (("--plot", "{store}/plot.png"), r"--plot .* is inside the corpus store"),
    (("--audit", "{tmp}/no/such/folder/a.h5"), r"--audit .*: the folder .* does not exist"),
    (("--plot", "{tmp}/missing/p.png"), r"--plot .*: the folder .* does not exist"),
    (("--audit", "{tmp}"), r"--audit .* is a folder"),
    (("--noise-std", "nan"), r"--noise-std must be a finite number >= 0, got nan"),
])
def test_output_paths_into_the_store_or_nowhere_are_refused(store, aoc, tmp_path, args,
                                                            pattern):
    path = csv_log(tmp_path, [(1, 0, 0.1, 1, 0), (2, 0, 0.2, 0, 1)])
    assert aoc("ingest", str(path), "--name", "m")[0] == 0
    before = snapshot(store)
    args = [a.format(store=store, tmp=tmp_path) for a in args]
    one_line_error(*aoc("rollout", "m", "--env", "maze", "--policy", "zero", *args), pattern)
    assert snapshot(store) == before
    assert not (tmp_path / "no").exists() and not (tmp_path / "missing").exists()


def test_collect_csv_into_the_store_is_refused(store, aoc):
    one_line_error(*aoc("collect", "ward", "--name", "w", "--csv", str(store / "w")),
                   r"--csv .* is inside the corpus store")
    assert not (store / "w").exists()


def test_jsonl_queries_that_are_not_numbers(tmp_path):
    from types import SimpleNamespace

    from aoc_cli.explanation.decisions import parse_query
    from aoc_cli.errors import AocError

    corpus = SimpleNamespace(name="m", observation_dim=2, action_dim=2, discrete=False)
    for line, pattern in [('{"observation": "abc"}', r'"observation" must be a list of numbers'),
                          ('{"observation": [1, "x"]}', r"must be a list of numbers"),
                          ('{"observation": [1, NaN]}', r"NaN or inf"),
                          ('{"observation": [1, 2], "history": 5}', r'"history" must be a list'),
                          ('{"observation": [1, 2], "history": [[1, "a", 2, 3, 4]]}',
                           r"history step 0 must be a list of numbers")]:
        with pytest.raises(AocError, match=pattern):
            parse_query(line, 1, corpus, 2)
    obs, hist, _a, _c = parse_query('{"observation": [1, 2], "history": [[1, 2, 3, 4, 5]]}',
                                    1, corpus, 2)
    assert obs.shape == (2,) and hist.mask.sum() == 1


def test_refused_ingests_leave_no_lock_files(store, aoc, tmp_path):
    """Nine bad inputs into a store holding a corpus: `ls -a` shows only that corpus's lock."""
    good = write_csv(tmp_path / "good.csv", ["episode", "t", "obs_0", "act_0"],
                     [[e, t, 0.1 * t, 1.0] for e in range(3) for t in range(5)])
    code, _, err = aoc("ingest", str(good), "--name", "kept")
    assert code == 0, err
    bad = tmp_path / "bad.csv"
    bad.write_text("episode,t,obs_0,act_0\n1,0,0.5,zz\n1,1,0.5,\n")
    for i in range(9):
        one_line_error(*aoc("ingest", str(bad), "--name", f"x{i}", "--format", "csv"))
    assert sorted(p.name for p in store.iterdir()) == [".kept.lock", "kept"]
