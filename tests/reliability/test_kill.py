"""kill -9 and SIGTERM during a write, with real processes (issue 13, "Data lost" 5): the
store keeps its previous state; a killed writer's temporary folder is removed by the next
write; SIGTERM is handled like Ctrl-C (its temporaries removed at once; exit 143)."""

from __future__ import annotations

import signal
import time

import pytest

from tests.reliability.common import d4rl_file, one_line_error, python, rows_of, spawn, snapshot

#: An `aoc ingest` whose corpus.h5 write pauses (in a real process) once the temporary corpus
#: folder exists, so the test can kill it there.
SLOW_INGEST = """
import sys, time
import aoc_cli.store.writer as writer
real = writer._write_h5
def slow(path, data, *options):
    digest = real(path, data, *options)
    print("writing", flush=True)
    time.sleep(60)
    return digest
writer._write_h5 = slow
from aoc_cli.cli.app import main
main(["ingest", {source!r}, "--name", "c", "--append"])
"""


@pytest.fixture
def corpus(tmp_path):
    store = tmp_path / "store"
    source = d4rl_file(tmp_path / "part.hdf5", n=400)
    assert spawn("ingest", str(source), "--name", "c", store=store).wait(timeout=120) == 0
    return store, source


def temporaries(store):
    return sorted(p.name for p in store.iterdir() if p.name.endswith((".tmp", ".old")))


def start_slow_ingest(store, source):
    proc = python(SLOW_INGEST.format(source=str(source)), store)
    assert proc.stdout.readline().strip() == "writing", proc.stderr.read()
    return proc


def test_kill_9_leaves_the_old_corpus_and_the_next_write_removes_the_leftovers(corpus):
    store, source = corpus
    before = snapshot(store / "c")
    proc = start_slow_ingest(store, source)
    left = temporaries(store)
    assert left and all(name.startswith(f".c.p{proc.pid}.") for name in left)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert temporaries(store) == left  # nothing can clean up after kill -9 ...
    assert snapshot(store / "c") == before and rows_of(store, "c") == 400
    second = spawn("ingest", str(source), "--name", "c", "--append", store=store)
    assert second.wait(timeout=120) == 0, second.stderr.read()
    assert temporaries(store) == []  # ... but the next write of the corpus does
    assert rows_of(store, "c") == 800


def test_sigterm_is_handled_like_ctrl_c(corpus):
    store, source = corpus
    before = snapshot(store / "c")
    proc = start_slow_ingest(store, source)
    assert temporaries(store)
    proc.send_signal(signal.SIGTERM)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, (out, err)  # 128 + SIGTERM
    assert err.strip().splitlines() == ["aoc: terminated (the store keeps its previous state)"]
    assert temporaries(store) == []
    assert snapshot(store / "c") == before


def test_a_live_writers_temporary_is_left_alone(corpus, tmp_path):
    store, source = corpus
    proc = start_slow_ingest(store, source)
    try:
        from aoc_cli.store.atomic import remove_stale

        assert remove_stale(store / "c") == []
        assert temporaries(store)
        # and the corpus is locked meanwhile
        other = spawn("ingest", str(source), "--name", "c", "--overwrite", store=store)
        out, err = other.communicate(timeout=120)
        one_line_error(other.returncode, out, err, rf"being written by pid {proc.pid}\b")
    finally:
        proc.kill()
        proc.wait()
    time.sleep(0.05)
    assert remove_stale(store / "c") and temporaries(store) == []


def killed_ingest(store, source) -> tuple[int, list[str]]:
    """kill -9 an append to corpus c mid-write: (its pid, the temporaries it left)."""
    proc = start_slow_ingest(store, source)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    left = temporaries(store)
    assert left and all(name.startswith(f".c.p{proc.pid}.") for name in left)
    return proc.pid, left


def test_a_write_of_another_corpus_clears_a_killed_writers_temporaries(corpus):
    store, source = corpus
    killed_ingest(store, source)
    other = spawn("ingest", str(source), "--name", "d", store=store)
    assert other.wait(timeout=120) == 0, other.stderr.read()
    assert temporaries(store) == []
    assert rows_of(store, "c") == 400 and rows_of(store, "d") == 400


def test_verify_clears_and_lists_a_killed_writers_temporaries(corpus):
    import json

    store, source = corpus
    pid, left = killed_ingest(store, source)
    check = spawn("verify", "-f", "json", store=store)
    out, err = check.communicate(timeout=120)
    assert check.returncode == 0, err
    cleared = [r for r in json.loads(out) if r["status"] == "cleared"]
    assert sorted(r["file"] for r in cleared) == left
    assert all(r["corpus"] == "c" and f"pid {pid}" in r["detail"] for r in cleared)
    assert temporaries(store) == []
    assert f"cleared {len(left)} leftovers of dead writers" in err
