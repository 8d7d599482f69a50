"""Lock files and the processes behind them: whether a writer's pid is alive, and removing a
lock file safely (only while holding it exclusively, and only if it is still the file at its
path). Shared by the writer locks (:mod:`aoc_cli.store.lock`), the clearing of dead writers'
leftovers (:mod:`aoc_cli.store.sweep`) and the atomic writes (:mod:`aoc_cli.store.atomic`).
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from pathlib import Path


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


def same_file(fd: int, path: Path) -> bool:
    """Whether the open file ``fd`` is the file at ``path`` now (not removed or replaced)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        return False
    own = os.fstat(fd)
    return (own.st_dev, own.st_ino) == (st.st_dev, st.st_ino)


def remove_locked(fd: int, path: Path, exclusive: bool) -> bool:
    """Remove the lock file ``path`` locked through ``fd`` when no other process holds it
    (a shared lock is first made exclusive, without waiting). True when removed."""
    if not exclusive:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return False
    if not same_file(fd, path):
        return False
    with contextlib.suppress(FileNotFoundError):
        os.unlink(path)
    return True
