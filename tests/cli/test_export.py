"""``aoc export``: writes, refuses what it must (one line, exit 2), leaves nothing half-written."""

import json
import os

import numpy as np
import pytest

from aoc_cli.envs import collect
from aoc_cli.store import Store


@pytest.fixture
def maze(store):
    data, _ = collect("maze", steps=200, seed=0)
    Store(store).write("m", data)
    return Store(store).corpus("m")


def one_error_line(err):
    lines = [x for x in err.splitlines() if x.strip()]
    assert len(lines) == 1 and lines[0].startswith("aoc: error: "), err
    return lines[0]


@pytest.mark.parametrize("fmt,name", [("d4rl", "m.hdf5"), ("csv", "m.csv"), ("minari", "m-v0")])
def test_export_then_ingest_prints_and_keeps_the_content_hash(aoc_inproc, maze, tmp_path, fmt,
                                                              name):
    out = tmp_path / "out" / name
    code, stdout, _ = aoc_inproc("export", "m", "--to", fmt, "--out", str(out), "-f", "json")
    assert code == 0
    shown = json.loads(stdout)
    assert shown["content_hash"] == maze.hash and shown["rows"] == maze.n_rows
    assert shown["files"][0] == str(out)
    code, _, _ = aoc_inproc("ingest", str(out), "--name", "back", "-f", "json")
    assert code == 0 and Store(maze.path.parent).corpus("back").hash == maze.hash
    # nothing but the target (and the CSV's mapping) was left beside it
    left = sorted(os.listdir(out.parent))
    assert left == sorted([name] + (["m.columns.json"] if fmt == "csv" else []))


def test_export_refuses_an_existing_path_without_overwrite(aoc_inproc, maze, tmp_path):
    out = tmp_path / "m.hdf5"
    out.write_text("keep me")
    code, _, err = aoc_inproc("export", "m", "--to", "d4rl", "--out", str(out))
    assert code == 2 and "already exists: pass --overwrite" in one_error_line(err)
    assert out.read_text() == "keep me"
    code, _, _ = aoc_inproc("export", "m", "--to", "d4rl", "--out", str(out), "--overwrite",
                            "-f", "json")
    assert code == 0 and out.read_bytes()[:4] == b"\x89HDF"


def test_export_refuses_to_write_into_the_store(aoc_inproc, maze, store):
    code, _, err = aoc_inproc("export", "m", "--to", "csv", "--out", str(store / "x.csv"))
    assert code == 2 and "inside the corpus store" in one_error_line(err)
    assert not (store / "x.csv").exists()


def test_overwrite_never_replaces_a_folder_that_is_not_a_minari_dataset(aoc_inproc, maze,
                                                                         tmp_path):
    folder = tmp_path / "papers"
    folder.mkdir()
    (folder / "thesis.tex").write_text("precious")
    code, _, err = aoc_inproc("export", "m", "--to", "minari", "--out", str(folder),
                              "--overwrite")
    assert code == 2 and "holds no Minari dataset" in one_error_line(err)
    assert (folder / "thesis.tex").read_text() == "precious"


def test_overwrite_replaces_an_earlier_minari_export(aoc_inproc, maze, tmp_path):
    out = tmp_path / "m-v0"
    assert aoc_inproc("export", "m", "--to", "minari", "--out", str(out), "-f", "json")[0] == 0
    code, _, _ = aoc_inproc("export", "m", "--to", "minari", "--out", str(out), "--overwrite",
                            "--select", "policy=pi1", "-f", "json")
    assert code == 0
    meta = json.loads((out / "data" / "metadata.json").read_text())
    codes, labels = maze.tag("policy")
    assert meta["total_steps"] == int((codes == labels.index("pi1")).sum())


@pytest.mark.parametrize("args,text", [
    (["--to", "parquet"], "'parquet' is not one of"),
    (["--to", "d4rl", "--static", "s.csv"], "--static writes CSV covariates"),
    (["--to", "csv", "--select", "policy=nope"], "has no value 'nope'"),
    (["--to", "csv", "--select", "policy"], "--select expects TAG=VALUE"),
    (["--to", "csv", "--rows", "5"], "--rows expects START:END"),
    (["--to", "csv", "--rows", "9:3"], "--rows must be START:END with 0 <= START < END"),
])
def test_bad_input_is_one_line_and_exit_2(aoc_inproc, maze, tmp_path, args, text):
    code, out, err = aoc_inproc("export", "m", "--out", str(tmp_path / "x.csv"), *args)
    assert code == 2 and text in one_error_line(err) and out == ""
    assert not (tmp_path / "x.csv").exists()


def test_unknown_corpus_is_one_line_and_exit_2(aoc_inproc, store, tmp_path):
    code, _, err = aoc_inproc("export", "nope", "--to", "csv", "--out", str(tmp_path / "x.csv"))
    assert code == 2 and "no corpus 'nope'" in one_error_line(err)


def test_csv_export_of_a_selection_reads_back_with_its_rows(aoc_inproc, maze, tmp_path):
    out = tmp_path / "pi2.csv"
    code, _, _ = aoc_inproc("export", "m", "--to", "csv", "--out", str(out), "--exclude",
                            "policy=pi1,pi3,pi4", "-f", "json")
    assert code == 0
    assert aoc_inproc("ingest", str(out), "--name", "pi2", "-f", "json")[0] == 0
    back = Store(maze.path.parent).corpus("pi2")
    codes, labels = maze.tag("policy")
    keep = codes == labels.index("pi2")
    np.testing.assert_array_equal(back.observations, maze.observations[keep])
    assert back.manifest["tags"] == maze.manifest["tags"]


def test_rows_exports_a_row_range_cutting_episodes_where_it_ends(aoc_inproc, maze, tmp_path):
    out = tmp_path / "part.hdf5"
    code, stdout, _ = aoc_inproc("export", "m", "--to", "d4rl", "--out", str(out), "--rows",
                                 "5:40", "-f", "json")
    assert code == 0 and json.loads(stdout)["rows"] == 35
    assert aoc_inproc("ingest", str(out), "--name", "part", "-f", "json")[0] == 0
    back = Store(maze.path.parent).corpus("part")
    np.testing.assert_array_equal(back.observations, maze.observations[5:40])
    # the last exported row ends its episode: terminal as it was, else truncated there
    last = back.read("terminals")[-1] or back.read("truncations")[-1]
    assert last and back.episode_starts[0] == 0
