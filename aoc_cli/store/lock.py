"""Writer locks: one writer per corpus (and per model of a corpus) at a time.

A lock is ``fcntl.flock`` on a file in the store folder, beside the corpus folder (not in it:
ingest replaces that folder by renaming, a lock inside it would go with it):

* ``<store>/.<name>.lock``: ingest and collect take it exclusively (they replace the corpus),
  train and index take it shared (they add to ``models/`` but leave the data alone);
* ``<store>/.<name>.model-<id>.lock``: train and index of model ``<id>`` take it exclusively.

So two ingests of one corpus, an ingest during a train, or two trains of one model id cannot
run at once; two trains of different model ids can. The second writer does not wait: it fails
at once with one line naming the pid that holds the lock, and nothing is written. The holder
records its pid in the lock file. The kernel releases a lock when its process dies (also on
kill -9), so a dead writer never leaves a corpus locked. Locks are re-entrant within a process
(``aoc ingest`` holds the lock it takes again in :meth:`Store.write`).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from pathlib import Path
from typing import Iterator

from aoc_cli.errors import AocError

#: path -> [fd, exclusive, depth] of the locks this process holds.
_HELD: dict[str, list] = {}


def pid_alive(pid: int) -> bool:
    """True when a process with this pid exists (one we may not signal counts too)."""
    if pid <= 0:
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _holders(path: Path) -> list[int]:
    """Live pids recorded in a lock file, other than this process."""
    try:
        text = path.read_text()
    except OSError:
        return []
    pids = []
    for line in text.split():
        if line.isdigit() and int(line) != os.getpid() and pid_alive(int(line)) \
                and int(line) not in pids:
            pids.append(int(line))
    return pids


def _busy(path: Path, what: str) -> AocError:
    pids = _holders(path)
    for _ in range(20):  # the holder writes its pid just after it took the lock
        if pids:
            break
        time.sleep(0.025)
        pids = _holders(path)
    who = ("pid " + ", ".join(str(p) for p in pids)) if pids else "another process"
    return AocError(f"{what} is being written by {who}: wait until it has finished, then "
                    "run this again")


@contextlib.contextmanager
def file_lock(path: str | os.PathLike, what: str, shared: bool = False) -> Iterator[None]:
    """Hold an flock on ``path`` (created if missing); AocError at once when it is held."""
    path = Path(path)
    key = str(path.absolute())
    held = _HELD.get(key)
    if held is not None:
        if not shared and not held[1]:  # flock does not upgrade atomically: never needed
            raise RuntimeError(f"{path} is held shared by this process; take it exclusively "
                               "first")
        held[2] += 1
        try:
            yield
        finally:
            held[2] -= 1
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
    except OSError as err:
        raise AocError(f"cannot write to the store: creating the lock file {path} failed "
                       f"({err.strerror}); is the store folder writable?") from None
    try:
        fcntl.flock(fd, (fcntl.LOCK_SH if shared else fcntl.LOCK_EX) | fcntl.LOCK_NB)
    except BlockingIOError:
        os.close(fd)
        raise _busy(path, what) from None
    try:
        if not shared:
            os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_END)
        os.write(fd, f"{os.getpid()}\n".encode())
        _HELD[key] = [fd, not shared, 1]
        yield
    finally:
        _HELD.pop(key, None)
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def corpus_lock_path(root: Path, name: str) -> Path:
    return Path(root) / f".{name}.lock"


@contextlib.contextmanager
def writing_corpus(root: str | os.PathLike, name: str, shared: bool = False) -> Iterator[None]:
    """The corpus lock: exclusive for ingest/collect, shared for train/index."""
    with file_lock(corpus_lock_path(Path(root), name), f"corpus {name!r}", shared=shared):
        yield


@contextlib.contextmanager
def writing_model(corpus_path: str | os.PathLike, model_id: str) -> Iterator[None]:
    """What train and index of one model hold: the corpus lock shared, the model's exclusive."""
    corpus_path = Path(corpus_path)
    root, name = corpus_path.parent, corpus_path.name
    with writing_corpus(root, name, shared=True), \
            file_lock(root / f".{name}.model-{model_id}.lock",
                      f"model {model_id!r} of corpus {name!r}"):
        yield
