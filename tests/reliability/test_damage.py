"""Damage written by the test into a real store (issue 13, "Damage that goes unseen" and the
internal errors): every command that meets it says so in one line naming the file and what to
do (exit 2); `aoc verify` finds a changed byte in any file; `aoc info` never shows a damaged
model as ok."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from tests.conftest import run_in_process
from tests.reliability.common import column_offset, flip_byte, one_line_error, snapshot


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """A maze corpus with a trained model and its index, built once."""
    import os

    root = tmp_path_factory.mktemp("pristine") / "store"
    from aoc_cli.belief.config import BeliefConfig
    from aoc_cli.belief.train import train_model
    from aoc_cli.envs import collect
    from aoc_cli.index import build_index
    from aoc_cli.store import Store

    store = Store(root)
    data, _ = collect("maze", steps=1200, seed=0)
    corpus = store.write("m", data)
    train_model(corpus, BeliefConfig(max_epochs=1, history_length=2, hidden=16,
                                     belief_dim=8, threads=1), "default")
    build_index(corpus)
    assert os.path.isfile(root / "m" / "models" / "default" / "index" / "default" /
                          "index.faiss")
    return root


@pytest.fixture
def store(pristine, tmp_path, monkeypatch):
    root = tmp_path / "store"
    shutil.copytree(pristine, root)
    monkeypatch.setenv("AOC_STORE", str(root))
    return root


@pytest.fixture
def aoc(capsys):
    return lambda *args: run_in_process(capsys, *args)


MODEL = "m/models/default"
QUERY = json.dumps({"observation": [1.0, 1.0], "history": []})


def verify_rows(aoc, *names):
    code, out, err = aoc("verify", *names, "-f", "json")
    return code, {r["file"]: r["status"] for r in json.loads(out)}, err


def test_an_intact_store_verifies(store, aoc):
    code, rows, err = verify_rows(aoc)
    assert code == 0, err
    assert set(rows.values()) == {"ok"}
    assert {"manifest.json", "corpus.h5", "corpus.h5 (content)",
            "models/default/config.json", "models/default/weights.pt",
            "models/default/beliefs.npy",
            "models/default/index/default/index.faiss"} <= set(rows)


def test_every_file_of_the_store_is_checked_byte_for_byte(store, aoc):
    """One changed byte in any file the store wrote: `aoc verify` says which, exit 2."""
    files = sorted(p for p in store.rglob("*") if p.is_file() and not p.name.startswith("."))
    assert len(files) >= 10
    for path in files:
        saved = path.read_bytes()
        flip_byte(path, len(saved) // 2)
        code, rows, err = verify_rows(aoc, "m")
        rel = str(path.relative_to(store / "m"))
        assert code == 2 and "damaged" in err, (rel, err)
        assert rows.get(rel, rows.get(rel + " (content)")) == "damaged", (rel, rows)
        path.write_bytes(saved)
    assert verify_rows(aoc)[0] == 0


def test_changed_rewards_are_found_by_verify_train_and_index(store, aoc):
    h5 = store / "m" / "corpus.h5"
    flip_byte(h5, column_offset(h5, "rewards") + 8)
    code, rows, _ = verify_rows(aoc, "m")
    assert code == 2 and rows["corpus.h5"] == "damaged" and rows["corpus.h5 (content)"] == \
        "damaged"
    # the damaged array is named (a CRC-32 per array in the manifest), and only it
    out = aoc("verify", "m", "-f", "json")[1]
    content = next(r for r in json.loads(out) if r["file"] == "corpus.h5 (content)")
    assert content["detail"].endswith("changed: rewards"), content
    before = snapshot(store)
    one_line_error(*aoc("train", "m", "--model", "other", "--epochs", "1"),
                   r"corpus 'm' is damaged: its arrays no longer match.*\(changed: rewards\).*"
                   r"aoc verify m")
    one_line_error(*aoc("index", "m", "--index-id", "again"),
                   r"corpus 'm' is damaged: its arrays no longer match.*aoc verify m")
    assert snapshot(store) == before


@pytest.mark.parametrize("command", [
    ("info", "m"), ("rollout", "m", "--env", "maze", "-n", "1"), ("train", "m", "--epochs", "1",
                                                                  "--overwrite"),
    ("explain", "m", "--input", "-"),
])
@pytest.mark.parametrize("damage", ["not json", "changed", "missing key", "truncated h5",
                                    "h5 metadata"])
def test_a_damaged_corpus_is_one_line_for_every_command(store, aoc, command, damage,
                                                        monkeypatch):
    manifest = store / "m" / "manifest.json"
    h5 = store / "m" / "corpus.h5"
    if damage == "not json":
        manifest.write_text("{ not json")
    elif damage == "changed":
        manifest.write_text(manifest.read_text().replace('"rows": 1200', '"rows": 1201'))
    elif damage == "missing key":
        meta = json.loads(manifest.read_text())
        del meta["action_space"], meta["sha256"]
        manifest.write_text(json.dumps(meta))
    elif damage == "truncated h5":
        h5.write_bytes(h5.read_bytes()[:5000])
    else:  # the superblock and root group metadata, with the size kept
        data = bytearray(h5.read_bytes())
        data[8:600] = bytes(592)
        h5.write_bytes(bytes(data))
    import io
    import sys

    monkeypatch.setattr(sys, "stdin", io.StringIO(QUERY + "\n"))
    before = snapshot(store)
    line = one_line_error(*aoc(*command), r"corpus 'm' is damaged")
    assert "aoc verify m" in line or "--overwrite" in line
    assert snapshot(store) == before


@pytest.mark.parametrize("damage", ["flipped weights", "truncated weights", "config not json",
                                    "config changed", "values header"])
def test_a_damaged_model_is_named_and_never_shown_as_ok(store, aoc, damage):
    folder = store / MODEL
    if damage == "flipped weights":
        flip_byte(folder / "weights.pt", (folder / "weights.pt").stat().st_size // 2)
    elif damage == "truncated weights":
        data = (folder / "weights.pt").read_bytes()
        (folder / "weights.pt").write_bytes(data[: len(data) // 3])
    elif damage == "config not json":
        (folder / "config.json").write_text("{")
    elif damage == "config changed":
        (folder / "config.json").write_text(
            (folder / "config.json").read_text().replace('"mode": "value"', '"mode": "imitation"'))
    else:
        data = bytearray((folder / "values.npy").read_bytes())
        data[10:40] = b"x" * 30
        (folder / "values.npy").write_bytes(bytes(data))
    code, out, err = aoc("info", "m", "-f", "json")
    assert code == 0, err
    assert [m["status"] for m in json.loads(out)["built"]] == ["damaged"]
    for command in (("rollout", "m", "--env", "maze", "-n", "1"), ("index", "m")):
        line = one_line_error(*aoc(*command), r"model 'default' of corpus 'm' is damaged")
        assert "aoc train m --model default --overwrite" in line
    assert verify_rows(aoc, "m")[0] == 2
    if damage == "config not json":  # the command the message names works
        code, _out, err = aoc("train", "m", "--model", "default", "--overwrite", "--epochs",
                              "1", "--hidden", "8", "--belief-dim", "4")
        assert code == 0, err
        assert verify_rows(aoc, "m")[0] == 0


@pytest.mark.parametrize("damage", ["faiss random", "faiss truncated", "beliefs deleted",
                                    "beliefs header", "index.json not json"])
def test_a_damaged_index_is_one_line_naming_the_rebuild(store, aoc, damage):
    model = store / MODEL
    faiss_file = model / "index" / "default" / "index.faiss"
    if damage == "faiss random":
        faiss_file.write_bytes(np.random.default_rng(0).bytes(faiss_file.stat().st_size))
    elif damage == "faiss truncated":
        faiss_file.write_bytes(faiss_file.read_bytes()[:100])
    elif damage == "beliefs deleted":
        (model / "beliefs.npy").unlink()
    elif damage == "beliefs header":
        data = bytearray((model / "beliefs.npy").read_bytes())
        data[10:50] = b"y" * 40
        (model / "beliefs.npy").write_bytes(bytes(data))
    else:
        (faiss_file.parent / "index.json").write_text("[")
    line = one_line_error(*aoc("rollout", "m", "--env", "maze", "-n", "1"), r"damaged|missing")
    assert "aoc index m" in line
    assert verify_rows(aoc, "m")[0] == 2
    # and `aoc index` rebuilds it
    code, _out, err = aoc("index", "m")
    assert code == 0, err
    assert verify_rows(aoc, "m")[0] == 0


def test_a_corpus_folder_without_its_manifest_is_damaged_not_absent(store, aoc, tmp_path):
    from tests.reliability.common import d4rl_file

    (store / "m" / "manifest.json").unlink()
    code, out, err = aoc("ls", "-f", "json")
    assert code == 0 and [(r["name"], r["status"]) for r in json.loads(out)] == [("m", "damaged")]
    before = snapshot(store)
    source = d4rl_file(tmp_path / "x.hdf5")
    one_line_error(*aoc("ingest", str(source), "--name", "m"), r"damaged.*--overwrite")
    one_line_error(*aoc("ingest", str(source), "--name", "m", "--append"),
                   r"damaged.*--overwrite")
    one_line_error(*aoc("info", "m"), r"corpus 'm' is damaged.*no manifest.json")
    assert snapshot(store) == before
    code, _out, err = aoc("ingest", str(source), "--name", "m", "--overwrite")
    assert code == 0, err
    assert not (store / "m" / "models").exists()


@pytest.mark.parametrize("fail_in", ["beliefs", "index", "typical residual"])
def test_a_failed_index_leaves_the_previous_beliefs_and_index(store, aoc, fail_in):
    """Issue 13, "Data lost" 4: the beliefs of a retrained model are staged with the index
    and swapped in only when everything succeeded."""
    import aoc_cli.index.build as session
    from aoc_cli.belief.config import BeliefConfig
    from aoc_cli.belief.train import train_model
    from aoc_cli.store import Store

    corpus = Store(store).corpus("m")
    model = store / MODEL
    old = store.parent / "old-model"
    shutil.copytree(model, old)
    train_model(corpus, BeliefConfig(max_epochs=1, history_length=2, hidden=16, belief_dim=8,
                                     threads=1, seed=7), "default", overwrite=True)
    # the previous beliefs and index (of the model before retraining: to be recomputed)
    shutil.copy(old / "beliefs.npy", model / "beliefs.npy")
    shutil.copy(old / "beliefs.json", model / "beliefs.json")
    shutil.copytree(old / "index", model / "index")
    before = {p: p.read_bytes() for p in [model / "beliefs.npy", model / "beliefs.json"] +
              sorted((model / "index" / "default").iterdir())}

    def boom(*args, **kwargs):
        raise RuntimeError(f"failed in {fail_in}")

    monkeypatch = pytest.MonkeyPatch()
    if fail_in == "beliefs":  # NaN beliefs, as of a damaged model
        import aoc_cli.belief.stream as stream

        real = stream.write_row_beliefs

        def nan_beliefs(*a, **k):  # the beliefs are written chunk by chunk into a .npy
            path = real(*a, **k)
            written = np.load(path, mmap_mode="r+")
            written[:] = np.nan
            written.flush()
            return path

        monkeypatch.setattr(stream, "write_row_beliefs", nan_beliefs)
        pattern = r"the belief of row 0 is not finite.*aoc train m --model default --overwrite"
    elif fail_in == "index":
        monkeypatch.setattr(session.BeliefIndex, "build", boom)
        pattern = None
    else:
        monkeypatch.setattr(session, "typical_residual", boom)
        pattern = None
    try:
        code, out, err = aoc("index", "m")
    finally:
        monkeypatch.undo()
    if pattern:
        one_line_error(code, out, err, pattern)
    else:
        assert code == 1 and f"failed in {fail_in}" in err
    assert {p: p.read_bytes() for p in before} == before
    assert not [p for p in (model / "index").iterdir() if p.name.startswith(".")]
    code, _out, err = aoc("index", "m")
    assert code == 0, err
    assert (model / "beliefs.npy").read_bytes() != before[model / "beliefs.npy"]
    assert verify_rows(aoc, "m")[0] == 0


@pytest.mark.parametrize("query,pattern", [
    ('{"observation": "abc"}', r'line 1: "observation" must be a list of numbers'),
    ('{"observation": [1, 2], "history": [[1, 2, "x", 4, 5]]}',
     r"line 1: history step 0 must be a list of numbers"),
    ('{"observation": [1, NaN]}', r"NaN or inf"),
])
def test_jsonl_queries_that_are_not_numbers_are_one_line(store, aoc, monkeypatch, query,
                                                         pattern):
    import io
    import sys

    monkeypatch.setattr(sys, "stdin", io.StringIO(query + "\n"))
    one_line_error(*aoc("explain", "m", "--input", "-"), pattern)
