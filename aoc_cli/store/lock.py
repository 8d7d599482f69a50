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

A lock file whose corpus (or model) does not exist when its last holder lets go (a refused
ingest, a failed first train) is removed by that holder, under an exclusive lock; whoever
takes a lock checks afterwards that the file it locked is still the one at the path, and
starts again if it was removed meanwhile. Taking a corpus lock also clears the temporaries of
dead writers anywhere in the store (:mod:`aoc_cli.store.sweep`).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from pathlib import Path
from typing import Callable, Iterator

from aoc_cli.errors import AocError, Locked
from aoc_cli.store.layout import holds_anything, models_dir
from aoc_cli.store.lockfiles import pid_alive, remove_locked, same_file
from aoc_cli.store.sweep import clear_dead

#: path -> [fd, exclusive, depth] of the locks this process holds.
_HELD: dict[str, list] = {}


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
    return Locked(what, pids)


@contextlib.contextmanager
def file_lock(path: str | os.PathLike, what: str, shared: bool = False,
              keep: Callable[[], bool] | None = None) -> Iterator[bool]:
    """Hold an flock on ``path`` (created if missing); AocError at once when it is held.

    Yields True when this call took the lock, False when the process already held it.
    ``keep``: asked when the lock is let go; False removes the lock file (what it guards does
    not exist), unless another process holds it too."""
    path = Path(path)
    key = str(path.absolute())
    held = _HELD.get(key)
    if held is not None:
        if not shared and not held[1]:  # flock does not upgrade atomically: never needed
            raise RuntimeError(f"{path} is held shared by this process; take it exclusively "
                               "first")
        held[2] += 1
        try:
            yield False
        finally:
            held[2] -= 1
        return
    fd = _take(path, what, shared)
    try:
        if not shared:
            os.ftruncate(fd, 0)
        os.lseek(fd, 0, os.SEEK_END)
        os.write(fd, f"{os.getpid()}\n".encode())
        _HELD[key] = [fd, not shared, 1]
        yield True
    finally:
        _HELD.pop(key, None)
        if keep is not None:
            with contextlib.suppress(Exception):
                if not keep():
                    remove_locked(fd, path, exclusive=not shared)
        with contextlib.suppress(OSError):
            fcntl.flock(fd, fcntl.LOCK_UN)
        os.close(fd)


def _take(path: Path, what: str, shared: bool) -> int:
    """Open and flock ``path``; the fd of a lock on the file that is at the path now."""
    for _ in range(100):
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
        if same_file(fd, path):
            return fd
        os.close(fd)  # removed (and perhaps re-created) by a holder letting go: again
    raise AocError(f"cannot take the lock {path}: it keeps being removed; run this again")


def corpus_lock_path(root: Path, name: str) -> Path:
    return Path(root) / f".{name}.lock"


@contextlib.contextmanager
def writing_corpus(root: str | os.PathLike, name: str, shared: bool = False) -> Iterator[None]:
    """The corpus lock: exclusive for ingest/collect, shared for train/index. Its file goes
    when the name holds nothing as the lock is let go; taking it clears the temporaries of
    dead writers anywhere in the store."""
    root = Path(root)
    with file_lock(corpus_lock_path(root, name), f"corpus {name!r}", shared=shared,
                   keep=lambda: holds_anything(root / name)) as taken:
        if taken:
            with contextlib.suppress(OSError):
                clear_dead(root)
        yield


@contextlib.contextmanager
def writing_model(corpus_path: str | os.PathLike, model_id: str) -> Iterator[None]:
    """What train and index of one model hold: the corpus lock shared, the model's exclusive
    (its file goes when the model does not exist as it is let go)."""
    corpus_path = Path(corpus_path)
    root, name = corpus_path.parent, corpus_path.name
    with writing_corpus(root, name, shared=True), \
            file_lock(model_lock_path(root, name, model_id),
                      f"model {model_id!r} of corpus {name!r}",
                      keep=lambda: (models_dir(corpus_path) / model_id).exists()):
        yield


def model_lock_path(root: Path, name: str, model_id: str) -> Path:
    return Path(root) / f".{name}.model-{model_id}.lock"
