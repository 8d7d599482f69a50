"""What failed and killed writers leave in a store: lock files of corpora that were never
written go with the command, temporaries of dead writers are cleared store-wide by the next
write (and by `aoc verify`, which lists them), and every array of corpus.h5 has a checksum so
that damage is named by array."""

from __future__ import annotations

import json
import subprocess
import sys

import h5py
import numpy as np
import pytest

from aoc_cli.errors import AocError
from aoc_cli.store import Store
from aoc_cli.store.lock import writing_corpus, writing_model
from aoc_cli.store.sweep import clear_dead

from tests.store.test_store import make_data


def dead_pid() -> int:
    """The pid of a process that has exited."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def hidden(root):
    return sorted(p.name for p in root.iterdir() if p.name.startswith("."))


def test_a_refused_write_leaves_no_lock_file(tmp_path):
    store = Store(tmp_path)
    store.write("kept", make_data())
    for name in ("x3", "x4"):
        with pytest.raises(AocError):
            with writing_corpus(tmp_path, name):
                raise AocError("bad input")  # what a refused ingest raises under its lock
    bad = make_data()
    bad.actions = bad.actions[:-1]  # one row short: refused by validation
    with pytest.raises(AocError):
        store.write("x5", bad)
    assert hidden(tmp_path) == [".kept.lock"]  # the corpus that exists keeps its lock file


def test_a_failed_first_train_leaves_no_model_lock(tmp_path):
    store = Store(tmp_path)
    corpus = store.write("c", make_data())
    with pytest.raises(RuntimeError):
        with writing_model(corpus.path, "new"):
            raise RuntimeError("training failed")
    assert hidden(tmp_path) == [".c.lock"]
    with writing_model(corpus.path, "made"):
        (corpus.path / "models" / "made").mkdir(parents=True)
    assert hidden(tmp_path) == [".c.lock", ".c.model-made.lock"]


def test_a_lock_file_removed_while_taking_it_is_taken_afresh(tmp_path, monkeypatch):
    # a holder letting go removes the file of a corpus that does not exist: whoever opened
    # that file just before must not hold a lock on the removed file, but on the new one
    import os

    from aoc_cli.store import lock as lock_module

    real_open, calls = os.open, []

    def open_then_removed(path, flags, *args):
        fd = real_open(path, flags, *args)
        if flags & os.O_CREAT:  # taking the lock (not the store's sweep looking at it)
            calls.append(path)
        if len(calls) == 1:
            os.unlink(path)  # removed between this open and the flock
        return fd

    monkeypatch.setattr(lock_module.os, "open", open_then_removed)
    with writing_corpus(tmp_path, "n"):
        assert calls == [tmp_path / ".n.lock"] * 2  # opened again
        held = lock_module._HELD[str((tmp_path / ".n.lock").absolute())][0]
        assert lock_module.same_file(held, tmp_path / ".n.lock")
    assert not (tmp_path / ".n.lock").exists()


def test_any_write_clears_dead_writers_temporaries_anywhere(tmp_path):
    store = Store(tmp_path)
    store.write("a", make_data())
    pid = dead_pid()
    (tmp_path / "a" / "models" / "m").mkdir(parents=True)
    leftovers = [tmp_path / f".b.p{pid}.abc123.tmp", tmp_path / "a" / "models" / "m" /
                 f".beliefs.npy.p{pid}.q_9.tmp.npy"]
    leftovers[0].mkdir()
    (leftovers[0] / "corpus.h5").write_bytes(b"half")
    leftovers[1].write_bytes(b"half")
    live = tmp_path / f".c.p{1}.xyz.tmp"  # pid 1 is alive: never touched
    live.write_bytes(b"")
    store.write("other", make_data())  # a write of another corpus
    assert not any(p.exists() for p in leftovers)
    assert live.exists()


def test_clear_dead_reports_what_it_removed(tmp_path):
    pid = dead_pid()
    (tmp_path / "a" / "models").mkdir(parents=True)  # holds a model folder: something
    (tmp_path / f".a.p{pid}.r1.old").mkdir()
    (tmp_path / ".gone.lock").write_text("123\n")  # no corpus 'gone', nobody holds it
    (tmp_path / ".a.lock").write_text("")  # corpus 'a' exists: kept
    cleared = clear_dead(tmp_path)
    assert cleared == [
        {"path": f".a.p{pid}.r1.old", "corpus": "a", "what": "temporary", "pid": pid},
        {"path": ".gone.lock", "corpus": "gone", "what": "lock", "pid": None},
    ]
    assert hidden(tmp_path) == [".a.lock"]
    with writing_corpus(tmp_path, "held"):  # a held lock of a missing corpus stays
        assert clear_dead(tmp_path) == [] and (tmp_path / ".held.lock").exists()


#: A writer of a new corpus (and of a new model of corpus "c") that is killed mid-write: it holds
#: the locks and has half-written temporaries when it says "ready".
KILLED_WRITER = """
import sys, time
from pathlib import Path
from aoc_cli.store import atomic_dir
from aoc_cli.store.lock import writing_corpus, writing_model
root = Path(sys.argv[1])
with writing_corpus(root, "new"), atomic_dir(root / "new") as tmp, \\
        writing_model(root / "c", "m"), atomic_dir(root / "c" / "models" / "m") as tmp_m:
    (tmp / "corpus.h5").write_bytes(b"half")
    (tmp_m / "model.pt").write_bytes(b"half")
    (root / "empty").mkdir()  # a name that holds nothing but a folder
    (root / ".empty.lock").write_text("")
    print("ready", flush=True)
    time.sleep(120)
"""


def test_a_killed_writers_lock_files_and_temporaries_go_with_the_next_write(tmp_path):
    store = Store(tmp_path)
    store.write("c", make_data())
    writer = subprocess.Popen([sys.executable, "-c", KILLED_WRITER, str(tmp_path)],
                              stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline().strip() == "ready"
        held = hidden(tmp_path)
        assert {".new.lock", ".c.model-m.lock", ".empty.lock"} <= set(held)
        assert any(n.startswith(".new.p") for n in held)
        assert clear_dead(tmp_path) == [  # alive: nothing of it goes but the unheld lock
            {"path": ".empty.lock", "corpus": "empty", "what": "lock", "pid": None}]
        (tmp_path / ".empty.lock").write_text("")
    finally:
        writer.kill()  # SIGKILL: no cleanup of its own
        writer.wait()
        writer.stdout.close()
    assert ".new.lock" in hidden(tmp_path)  # left behind by the killed writer
    store.write("other", make_data())  # any later write sweeps the store
    assert hidden(tmp_path) == [".c.lock", ".other.lock"]
    assert not any(p.name.startswith(".") for p in (tmp_path / "c" / "models").iterdir())


def test_the_manifest_records_a_checksum_per_array(tmp_path):
    corpus = Store(tmp_path).write("c", make_data())
    arrays = json.loads((corpus.path / "manifest.json").read_text())["arrays"]
    assert sorted(arrays) == ["actions", "episode_starts", "observations", "rewards",
                              "tags/policy", "terminals", "truncations"]
    assert corpus.changed_arrays() == []


def test_changed_arrays_are_named(tmp_path):
    corpus = Store(tmp_path).write("c", make_data())
    with h5py.File(corpus.path / "corpus.h5", "r+") as f:
        f["rewards"][2] = f["rewards"][2] + 1.0
    fresh = Store(tmp_path).corpus("c")
    assert fresh.changed_arrays() == ["rewards"]
    with pytest.raises(AocError, match=r"no longer match.*\(changed: rewards\)"):
        fresh.verify_content()


def test_a_corpus_without_array_checksums_verifies_as_before(tmp_path):
    from aoc_cli.store.atomic import seal
    from aoc_cli.store.verify import verify_corpus

    store = Store(tmp_path)
    corpus = store.write("c", make_data())
    manifest = json.loads((corpus.path / "manifest.json").read_text())
    del manifest["arrays"]  # as an older aoc wrote it
    (corpus.path / "manifest.json").write_text(json.dumps(seal(manifest)))
    rows = {r["file"]: r for r in verify_corpus(store, "c")}
    assert rows["corpus.h5 (content)"]["status"] == "ok"
    assert store.corpus("c").changed_arrays() is None
    with h5py.File(corpus.path / "corpus.h5", "r+") as f:
        f["observations"][0] = np.float32(9.0)
    rows = {r["file"]: r for r in verify_corpus(store, "c")}
    assert rows["corpus.h5 (content)"]["status"] == "damaged"
    assert "older aoc" in rows["corpus.h5 (content)"]["detail"]
