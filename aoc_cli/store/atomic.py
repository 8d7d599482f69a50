"""Nothing half-written: every file goes to a temporary file in the same folder and is renamed
into place, so an interrupted command leaves the previous state intact.

Temporaries are named ``.<name>.p<pid>.<random>.tmp`` (``.old`` for a replaced folder on its
way out): a writer killed with kill -9 cannot remove its own, so the next write of the same
name removes those whose pid is no longer alive (:func:`remove_stale`).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import re
import tempfile
import time
import zlib
from pathlib import Path
from typing import Iterator

import numpy as np

from aoc_cli.store.columns import ColumnStack
from aoc_cli.store.lockfiles import pid_alive

#: Temporaries of an older aoc carry no pid: removed when older than this many seconds.
LEGACY_STALE_SECONDS = 3600


def _prefix(path: Path) -> str:
    return f".{path.name}.p{os.getpid()}."


def remove_stale(path: str | os.PathLike) -> list[Path]:
    """Remove the temporaries of ``path`` (``.<name>.*.tmp*``, ``.<name>.*.old``) left by
    writers that died: those recording a pid that is not alive, and pid-less ones (an older
    aoc) untouched for an hour. Returns what was removed."""
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        return []
    pattern = re.compile(r"^\." + re.escape(path.name) + r"\.(p(\d+)\.)?[^.]+\.(tmp.*|old)$")
    removed = []
    for entry in folder.iterdir():
        m = pattern.match(entry.name)
        if m is None:
            continue
        if m.group(2) is not None:
            stale = not pid_alive(int(m.group(2)))
        else:
            try:
                stale = time.time() - entry.lstat().st_mtime > LEGACY_STALE_SECONDS
            except OSError:
                continue
        if not stale:
            continue
        if entry.is_dir() and not entry.is_symlink():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                entry.unlink()
        removed.append(entry)
    return removed


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    On an exception the temporary file is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(path)
    fd, tmp = tempfile.mkstemp(prefix=_prefix(path), suffix=".tmp" + suffix, dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        if tmp_path.exists():  # mkstemp makes 0600: give the file the mode a plain open would
            os.chmod(tmp_path, 0o666 & ~_umask())
        os.replace(tmp_path, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp_path.unlink()
        raise


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary folder beside ``path``; on success it replaces ``path`` (if any).

    The old folder is renamed aside, the new one renamed in, then the old one deleted.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale(path)
    tmp = Path(tempfile.mkdtemp(prefix=_prefix(path), suffix=".tmp", dir=path.parent))
    try:
        yield tmp
        os.chmod(tmp, 0o777 & ~_umask())  # mkdtemp makes 0700: the mode a plain mkdir gives
        old = None
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=_prefix(path), suffix=".old", dir=path.parent))
            os.rmdir(old)
            os.replace(path, old)
        os.replace(tmp, path)
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def write_json(path: str | os.PathLike, obj: dict) -> None:
    """Write JSON atomically (indented, stable key order)."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2, sort_keys=False) + "\n")


def write_npy(path: str | os.PathLike, array: np.ndarray) -> None:
    """Write a .npy atomically (memory-mappable with ``np.load(..., mmap_mode="r")``)."""
    with atomic_path(path, suffix=".npy") as tmp:
        np.save(tmp, array, allow_pickle=False)


def hash_arrays(*arrays, hasher=None) -> str:
    """A content hash (SHA-256 truncated to 16 bytes, hex) of arrays: dtype, shape and bytes
    (a :class:`~aoc_cli.store.columns.ColumnStack` as the rows it stands for, block by block).
    ``hasher``: a SHA-256 already fed with what comes before ``arrays``.

    SHA-256 rather than blake2b: with the CPU's SHA extensions it hashes ~1.4 GB/s here,
    blake2b ~0.65 GB/s, and hashing is a fixed part of every ingest (benchmarks/perf/ingest.py).
    """
    h = hashlib.sha256() if hasher is None else hasher
    for a in arrays:
        if a is None:
            h.update(b"<none>")
            continue
        for part in array_bytes(a):
            h.update(part)
    return h.hexdigest()[:32]


def array_bytes(a) -> Iterator:
    """What the hashes read of an array: ``{dtype}{shape}`` then its C-ordered bytes (of a
    ColumnStack: its rows, a block at a time)."""
    if not isinstance(a, ColumnStack):
        a = np.ascontiguousarray(a)
    yield f"{a.dtype.str}{a.shape}".encode()
    if isinstance(a, ColumnStack):
        for _start, block in a.blocks():
            yield memoryview(block).cast("B")
    else:
        yield memoryview(a).cast("B")


def array_checksum(a) -> str:
    """CRC-32 (hex) of an array's dtype, shape and bytes: recorded per array of a corpus so that
    ``aoc verify`` names the changed ones. A checksum that finds damage, not a content identity
    (that is :func:`hash_arrays`); CRC-32 as HDF5's and zlib's own, faster than SHA-256
    (docs/notes/benchmarks-rounds.md, "Figures once in docstrings")."""
    crc = 0
    for part in array_bytes(a):
        crc = zlib.crc32(part, crc)
    return f"{crc:08x}"


def sha256_file(path: str | os.PathLike, chunk: int = 1 << 22) -> str:
    """SHA-256 (hex) of a file's bytes."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def crc32_file(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    """CRC-32 (hex) of a file's bytes (one buffer reused)."""
    crc, buf = 0, bytearray(chunk)
    view = memoryview(buf)
    with open(path, "rb", buffering=0) as f:
        while k := f.readinto(buf):
            crc = zlib.crc32(view[:k], crc)
    return f"{crc:08x}"


def file_record(path: str | os.PathLike, checksum: str = "sha256") -> dict:
    """``{"bytes", "sha256"}`` of a file, as recorded beside what is written; ``checksum``
    ``"crc32"``: ``{"bytes", "crc32"}``, for ``corpus.h5``, whose arrays the content hash
    (SHA-256) already identifies: the file's own record only has to find damage (any changed
    byte, as the CRC-32 per array does), at ~2.5x SHA-256's speed (docs/notes/benchmarks-rounds.md)."""
    if checksum == "crc32":
        return {"bytes": os.path.getsize(path), "crc32": crc32_file(path)}
    return {"bytes": os.path.getsize(path), "sha256": sha256_file(path)}


def seal(meta: dict) -> dict:
    """``meta`` with ``"sha256"``: the SHA-256 of its other keys (canonical JSON), so a JSON
    file can be checked on its own (:func:`seal_status`)."""
    body = {k: v for k, v in meta.items() if k != "sha256"}
    text = json.dumps(body, sort_keys=True, separators=(",", ":"))
    return {**body, "sha256": hashlib.sha256(text.encode()).hexdigest()}


def seal_status(meta: dict) -> bool | None:
    """True when a sealed JSON object is intact, False when changed, None when unsealed."""
    if not isinstance(meta, dict) or "sha256" not in meta:
        return None
    return seal(meta)["sha256"] == meta["sha256"]


def hash_file(path: str | os.PathLike, chunk: int = 1 << 22) -> str:
    """blake2b (16 bytes, hex) of a file's bytes."""
    h = hashlib.blake2b(digest_size=16)
    with open(path, "rb") as f:
        while block := f.read(chunk):
            h.update(block)
    return h.hexdigest()


def content_hash(observations, actions, rewards, terminals, truncations, episode_starts,
                 tags: dict, columns: dict, hasher=None) -> str:
    """The corpus content hash: SHA-256 (128 bits) of the arrays in a fixed order (tag codes
    and numeric columns by name). The store records it; :mod:`aoc_cli.store.verify` and the
    commands that read every column recompute it. ``hasher``: a SHA-256 already fed with the
    observations (:func:`array_bytes`; the writer hashes their blocks as it writes them), which
    are then not read again."""
    parts = [actions, rewards, terminals, truncations, episode_starts]
    parts = parts if hasher is not None else [observations] + parts
    parts += [tags[k] for k in sorted(tags)] + [columns[k] for k in sorted(columns)]
    return hash_arrays(*parts, hasher=hasher)
