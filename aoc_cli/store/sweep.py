"""What dead writers leave in a store, cleared: their temporaries anywhere in it, and lock
files of corpora or models that do not exist.

A writer's temporaries are named ``.<name>.p<pid>.<random>.tmp`` (``.old`` for a replaced
folder on its way out, :mod:`aoc_cli.store.atomic`); one whose pid is no longer alive belongs
to a writer killed before it could remove it (kill -9, a lost machine). Every write clears
them store-wide when it takes its corpus lock (:func:`aoc_cli.store.lock.writing_corpus`), and
``aoc verify`` lists what it cleared. A temporary of a live process is never touched. (Pids
are this machine's: a store written from two machines at once is not supported.)

A lock file ``.<name>.lock`` (``.<name>.model-<id>.lock``) of a name that holds nothing (no
corpus folder, or one without a manifest, corpus file or models; no model folder) and that no
process holds is removed too: a command lets go of such a lock file itself; these are left by
an older aoc or a killed process (``tests/store/test_sweep.py`` kills one).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import re
import shutil
from pathlib import Path

from aoc_cli.store.layout import holds_anything, models_dir
from aoc_cli.store.lockfiles import pid_alive, remove_locked

#: A temporary that records its writer's pid: ``.<name>.p<pid>.<random>.tmp[suffix]`` / ``.old``.
TEMPORARY = re.compile(r"^\.(.+)\.p(\d+)\.[A-Za-z0-9_]+\.(tmp.*|old)$")
#: A writer lock at the store's top level: ``.<name>.lock`` or ``.<name>.model-<id>.lock``.
LOCK = re.compile(r"^\.(.+?)(?:\.model-(.+))?\.lock$")


def clear_dead(root: str | os.PathLike) -> list[dict]:
    """Remove the temporaries of dead writers anywhere under the store ``root`` and the lock
    files of corpora / models that do not exist and that nobody holds. Returns one record per
    removed entry: ``{"path": relative path, "corpus": the corpus it belonged to, "what":
    "temporary" | "lock", "pid": the dead writer's (None for a lock)}``, in path order."""
    root = Path(root)
    if not root.is_dir():
        return []
    cleared = []
    for folder, dirs, files in os.walk(root):
        here = Path(folder)
        for entry in sorted(dirs + files):
            m = TEMPORARY.match(entry)
            if m is None or pid_alive(int(m.group(2))):
                continue
            path = here / entry
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path, ignore_errors=True)
                dirs.remove(entry)
            else:
                with contextlib.suppress(OSError):
                    path.unlink()
            if not path.exists():
                rel = path.relative_to(root)
                corpus = rel.parts[0] if len(rel.parts) > 1 else m.group(1)
                cleared.append({"path": str(rel), "corpus": corpus, "what": "temporary",
                                "pid": int(m.group(2))})
    for entry in sorted(os.listdir(root)):
        m = LOCK.match(entry)
        if m is None or not _orphan(root, m.group(1), m.group(2)):
            continue
        if _remove_unheld(root / entry):
            cleared.append({"path": entry, "corpus": m.group(1), "what": "lock", "pid": None})
    return sorted(cleared, key=lambda r: r["path"])


def _orphan(root: Path, name: str, model: str | None) -> bool:
    """The corpus (or its model) a lock file guards does not exist: its name holds nothing."""
    corpus = root / name
    return not (models_dir(corpus) / model).exists() if model else not holds_anything(corpus)


def _remove_unheld(path: Path) -> bool:
    """Remove a lock file no process holds (taken exclusively without waiting first)."""
    try:
        fd = os.open(path, os.O_RDWR)
    except OSError:
        return False
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
        return remove_locked(fd, path, exclusive=True)
    finally:
        os.close(fd)
