"""Two writers of one corpus, as two real processes: the second fails at once with one line
naming the first's pid, and no row is lost (issue 13, "Data lost" 1)."""

from __future__ import annotations

import pytest

from tests.reliability.common import (
    d4rl_file,
    one_line_error,
    python,
    rows_of,
    spawn,
)

HOLD = """
import sys
from aoc_cli.store.lock import {fn}
with {fn}({args}):
    print("held", flush=True)
    sys.stdin.readline()
"""


def hold(store, fn: str, args: str):
    """A real process holding a writer lock until its stdin is closed."""
    proc = python(HOLD.format(fn=fn, args=args), store)
    assert proc.stdout.readline().strip() == "held", proc.stderr.read()
    return proc


@pytest.fixture
def corpus(tmp_path):
    store = tmp_path / "store"
    source = d4rl_file(tmp_path / "part.hdf5", n=400)
    proc = spawn("ingest", str(source), "--name", "c", store=store)
    assert proc.wait() == 0, proc.stderr.read()
    return store, source


def test_a_second_writer_fails_with_the_pid_of_the_first(corpus):
    store, source = corpus
    holder = hold(store, "writing_corpus", f"{str(store)!r}, 'c'")
    try:
        for args in (("ingest", str(source), "--name", "c", "--append"),
                     ("ingest", str(source), "--name", "c", "--overwrite"),
                     ("train", "c", "--epochs", "1")):
            second = spawn(*args, store=store)
            out, err = second.communicate(timeout=120)
            one_line_error(second.returncode, out, err,
                           rf"corpus 'c' is being written by pid {holder.pid}\b")
    finally:
        holder.communicate("\n", timeout=30)
    assert rows_of(store, "c") == 400
    # the lock is gone with its holder: the append now works
    after = spawn("ingest", str(source), "--name", "c", "--append", store=store)
    assert after.wait(timeout=120) == 0, after.stderr.read()
    assert rows_of(store, "c") == 800


def test_two_trains_of_one_model_id_exclude_each_other(corpus):
    store, _ = corpus
    holder = hold(store, "writing_model", f"{str(store / 'c')!r}, 'default'")
    try:
        second = spawn("train", "c", "--epochs", "1", store=store)
        out, err = second.communicate(timeout=120)
        one_line_error(second.returncode, out, err,
                       rf"model 'default' of corpus 'c' is being written by pid {holder.pid}")
        # an ingest waits for no train either: it fails while the model is being written
        second = spawn("ingest", str(corpus[1]), "--name", "c", "--append", store=store)
        out, err = second.communicate(timeout=120)
        one_line_error(second.returncode, out, err,
                       rf"corpus 'c' is being written by pid {holder.pid}")
    finally:
        holder.communicate("\n", timeout=30)
    assert not (store / "c" / "models" / "default").exists()
    assert rows_of(store, "c") == 400


def test_a_lock_dies_with_a_killed_holder(corpus):
    store, source = corpus
    holder = hold(store, "writing_corpus", f"{str(store)!r}, 'c'")
    holder.kill()  # kill -9: the kernel releases the flock
    holder.wait()
    after = spawn("ingest", str(source), "--name", "c", "--append", store=store)
    assert after.wait(timeout=120) == 0, after.stderr.read()
    assert rows_of(store, "c") == 800


def test_racing_appends_lose_no_rows(tmp_path):
    """Two `aoc ingest --append` started together: each either adds its rows or fails with
    one line; the corpus ends with exactly the rows of the appends that succeeded."""
    store = tmp_path / "store"
    source = d4rl_file(tmp_path / "part.hdf5", n=5_000)
    assert spawn("ingest", str(source), "--name", "c", store=store).wait() == 0
    expected = 5_000
    for _trial in range(2):
        procs = [spawn("ingest", str(source), "--name", "c", "--append", store=store)
                 for _ in range(2)]
        results = [(p, *p.communicate(timeout=300)) for p in procs]
        for p, out, err in results:
            if p.returncode == 0:
                expected += 5_000
            else:
                one_line_error(p.returncode, out, err, r"corpus 'c' is being written by pid")
        assert rows_of(store, "c") == expected
    assert expected >= 15_000  # at least one append of each trial went through
