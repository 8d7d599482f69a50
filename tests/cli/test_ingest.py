"""``aoc ingest`` through the real CLI: the summary, and every bad input of issue 2 (one line
on stderr, exit 2, the store untouched)."""

import hashlib
import json
import os

import h5py
import numpy as np
import pytest

from tests.conftest import run_in_process

from tests.formats.sources import flat_arrays, write_csv, write_d4rl


def snapshot(root):
    """Every file under the store with its content hash (and every folder, incl. temporaries);
    not the writer lock files ``.NAME.lock`` (a pid, no data; those of existing corpora stay)."""
    out = {}
    if not os.path.exists(root):
        return out
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            out[os.path.relpath(os.path.join(dirpath, d), root)] = "dir"
        for f in filenames:
            if f.startswith(".") and f.endswith(".lock"):
                continue
            p = os.path.join(dirpath, f)
            out[os.path.relpath(p, root)] = hashlib.md5(open(p, "rb").read()).hexdigest()
    return out


@pytest.fixture
def aoc(capsys):
    """Overrides the subprocess runner of tests/conftest.py for speed (see run_in_process)."""
    return lambda *args: run_in_process(capsys, *args)


def test_real_process_exit_codes_and_one_line_errors(store, d4rl_file):
    from tests.conftest import run_aoc

    code, out, err = run_aoc("ingest", str(d4rl_file), "--name", "hopper", "-f", "json")
    assert code == 0 and json.loads(out)["rows"] == 400, err
    code, out, err = run_aoc("ingest", str(d4rl_file), "--name", "hopper")
    assert code == 2 and out == ""
    assert err.strip().splitlines() == [
        "aoc: error: corpus 'hopper' already exists: pass --overwrite to replace it or "
        "--append to add to it"]


@pytest.fixture
def d4rl_file(tmp_path):
    arrays, _ = flat_arrays()
    return write_d4rl(tmp_path / "hopper.hdf5", arrays)


@pytest.fixture
def filled_store(store, aoc, d4rl_file):
    code, _, err = aoc("ingest", str(d4rl_file), "--name", "hopper")
    assert code == 0, err
    return store


def assert_refused(aoc, store, args, match):
    before = snapshot(store)
    code, out, err = aoc(*args)
    assert code == 2, (out, err)
    assert out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("aoc: error:"), err
    assert match in lines[0], lines[0]
    assert snapshot(store) == before
    return lines[0]


def test_ingest_prints_summary_in_the_requested_format(store, aoc, d4rl_file):
    code, out, err = aoc("ingest", str(d4rl_file), "--name", "hopper", "--format", "json")
    assert code == 0, err
    summary = json.loads(out)
    assert {k: summary[k] for k in ("name", "rows", "episodes", "format")} == \
        {"name": "hopper", "rows": 400, "episodes": 4, "format": "d4rl"}
    assert summary["seconds"] >= 0
    code, out, _ = aoc("ingest", str(d4rl_file), "--name", "h2", "--format", "csv")
    assert out.splitlines()[0].startswith("name,format,rows,episodes,seconds")
    assert out.splitlines()[1].startswith("h2,d4rl,400,4,")


def test_append_adds_episodes_and_overwrite_replaces(filled_store, aoc, d4rl_file):
    code, out, err = aoc("ingest", str(d4rl_file), "--name", "hopper", "--append", "-f", "json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["rows"] == 400 and summary["total_rows"] == 800
    assert summary["total_episodes"] == 8
    code, out, err = aoc("ingest", str(d4rl_file), "--name", "hopper", "--overwrite",
                         "-f", "json")
    assert code == 0 and json.loads(out)["rows"] == 400


def test_forced_format_and_csv_options_reach_the_reader(store, aoc, tmp_path):
    path = write_csv(tmp_path / "log.txt", ["pid", "hour", "hr", "treat", "group"],
                     [[1, 0, 80.0, 1, "a"], [1, 1, 82.0, 0, "a"], [2, 0, 90.0, 1, "b"]])
    code, out, err = aoc("ingest", str(path), "--name", "icu", "--from", "csv",
                         "--id-column", "pid", "--time-column", "hour", "--obs-columns", "hr",
                         "--act-columns", "treat", "--discrete-actions", "--reward-free",
                         "--tag-column", "group", "--tag", "site=x", "-f", "json")
    assert code == 0, err
    code, out, _ = aoc("info", "icu", "-f", "json")
    info = json.loads(out)
    assert info["discrete"] and not info["has_rewards"] and info["episodes"] == 2
    assert info["tags"] == {"group": {"a": 2, "b": 1}, "site": {"x": 3}}


def test_missing_path(store, aoc, tmp_path):
    assert_refused(aoc, store, ["ingest", str(tmp_path / "nope.hdf5"), "--name", "x"],
                   "no such file or folder")


def test_unknown_format(store, aoc, tmp_path):
    (tmp_path / "notes.txt").write_text("hello\n")
    assert_refused(aoc, store, ["ingest", str(tmp_path / "notes.txt"), "--name", "x"],
                   "cannot tell the format")
    assert_refused(aoc, store, ["ingest", str(tmp_path / "notes.txt"), "--name", "x",
                                "--from", "xlsx"], "unknown format 'xlsx'")


def test_undetectable_hdf5(store, aoc, tmp_path):
    with h5py.File(tmp_path / "other.h5", "w") as f:
        f["weights"] = np.zeros(3)
    assert_refused(aoc, store, ["ingest", str(tmp_path / "other.h5"), "--name", "x"],
                   "cannot tell the format of HDF5 file")


def test_truncated_hdf5(store, aoc, d4rl_file):
    data = d4rl_file.read_bytes()
    d4rl_file.write_bytes(data[: len(data) // 2])
    assert_refused(aoc, store, ["ingest", str(d4rl_file), "--name", "x"], "truncated or corrupt")


def test_corrupt_hdf5(store, aoc, d4rl_file):
    data = bytearray(d4rl_file.read_bytes())
    data[8:4096] = os.urandom(4088)  # keep the signature, destroy the superblock and tree
    d4rl_file.write_bytes(bytes(data))
    assert_refused(aoc, store, ["ingest", str(d4rl_file), "--name", "x", "--from", "d4rl"],
                   "truncated or corrupt")


def test_arrays_of_different_lengths(store, aoc, tmp_path):
    arrays, _ = flat_arrays()
    arrays["actions"] = arrays["actions"][:-3]
    path = write_d4rl(tmp_path / "bad.hdf5", arrays)
    line = assert_refused(aoc, store, ["ingest", str(path), "--name", "x"],
                          "arrays of different lengths")
    assert "actions has 397 rows" in line


def test_nonfinite_values_name_the_first_bad_row(store, aoc, tmp_path):
    arrays, _ = flat_arrays()
    arrays["rewards"][170] = np.inf
    arrays["observations"][160, 2] = np.nan
    path = write_d4rl(tmp_path / "nan.hdf5", arrays)
    line = assert_refused(aoc, store, ["ingest", str(path), "--name", "x"], "row 160")
    assert "observations" in line and "episode 2" in line and "step 10" in line
    assert "--drop-nonfinite" in line


def test_drop_nonfinite_drops_those_episodes(store, aoc, tmp_path):
    arrays, _ = flat_arrays()
    arrays["observations"][160, 2] = np.nan  # episode 2 (rows 150..299)
    path = write_d4rl(tmp_path / "nan.hdf5", arrays)
    code, out, err = aoc("ingest", str(path), "--name", "x", "--drop-nonfinite", "-f", "json")
    assert code == 0, err
    summary = json.loads(out)
    assert summary["rows"] == 250 and summary["episodes"] == 3
    assert summary["dropped_episodes"] == 1


def test_zero_rows(store, aoc, tmp_path):
    arrays, _ = flat_arrays()
    empty = {k: v[:0] for k, v in arrays.items()}
    path = write_d4rl(tmp_path / "empty.hdf5", empty)
    assert_refused(aoc, store, ["ingest", str(path), "--name", "x"], "zero rows")
    csv_path = write_csv(tmp_path / "empty.csv", ["episode", "t", "obs_a", "act_u"], [])
    assert_refused(aoc, store, ["ingest", str(csv_path), "--name", "x"], "zero rows")


def test_existing_name_without_overwrite(filled_store, aoc, d4rl_file):
    assert_refused(aoc, filled_store, ["ingest", str(d4rl_file), "--name", "hopper"],
                   "already exists: pass --overwrite")


def test_append_with_different_spaces(filled_store, aoc, tmp_path):
    arrays, _ = flat_arrays(d_o=7)
    path = write_d4rl(tmp_path / "other.hdf5", arrays)
    assert_refused(aoc, filled_store, ["ingest", str(path), "--name", "hopper", "--append"],
                   "cannot --append to 'hopper'")


@pytest.mark.parametrize("name", ["../escape", "a/b", "..", ".hidden"])
def test_invalid_corpus_name(filled_store, aoc, d4rl_file, name):
    assert_refused(aoc, filled_store, ["ingest", str(d4rl_file), "--name", name],
                   "invalid corpus name")
    assert not (filled_store.parent / "escape").exists()
