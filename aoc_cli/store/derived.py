"""Beliefs and indexes on disk: built in a temporary folder and swapped in only when
everything succeeded, recorded with checksums, checked when opened.

``aoc index`` builds ``models/<id>/index/<index_id>/`` in a temporary folder beside it (with
the new ``beliefs.npy`` staged in it when the beliefs are recomputed); only when the index,
its typical residual and ``index.json`` are written are the beliefs moved into the model
folder and the index folder renamed into place. A failure (NaN beliefs of a damaged model, a
FAISS error, Ctrl-C, kill -9) leaves the previous beliefs and index as they were.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.store.atomic import file_record, seal, write_json
from aoc_cli.store.verify import check_files, read_json

BELIEFS = "beliefs.npy"
BELIEFS_META = "beliefs.json"


def beliefs_fresh(model_dir: Path, model_hash: str) -> bool:
    """True when ``beliefs.npy`` was computed by this model and is intact (fast check); a
    damaged or missing one is recomputed by the next ``aoc index``."""
    try:
        meta = read_json(Path(model_dir) / BELIEFS_META, "beliefs", "")
        check_files(model_dir, meta, (BELIEFS,), "beliefs", "")
    except AocError:
        return False
    return meta.get("model_hash") == model_hash and (Path(model_dir) / BELIEFS).is_file()


def check_finite(beliefs: np.ndarray, what: str, todo: str) -> None:
    """Refuse beliefs holding NaN or inf (a damaged or diverged model)."""
    with np.errstate(invalid="ignore", over="ignore"):  # by chunks: beliefs may be a memmap
        ok = all(np.isfinite(np.asarray(beliefs[a:a + (1 << 18)], np.float64).sum())
                 for a in range(0, len(beliefs), 1 << 18))
    if not ok and not np.isfinite(beliefs).all():
        bad = int(np.flatnonzero(~np.isfinite(beliefs).all(axis=1))[0])
        raise AocError(f"{what}: the belief of row {bad} is not finite (NaN or inf); {todo}")


def stage_beliefs(tmp: Path, beliefs: np.ndarray) -> Path:
    """Write beliefs (N, d_b) into the staging folder; moved in by :func:`commit_beliefs`."""
    path = Path(tmp) / BELIEFS
    np.save(path, np.ascontiguousarray(beliefs, dtype=np.float32), allow_pickle=False)
    return path


def commit_beliefs(staged: Path, model_dir: Path, meta: dict) -> None:
    """Move staged beliefs into the model folder and write their sealed record (the npy first:
    a crash between the two leaves beliefs that the next index recomputes)."""
    record = file_record(staged)
    os.replace(staged, Path(model_dir) / BELIEFS)
    write_json(Path(model_dir) / BELIEFS_META, seal({**meta, "files": {BELIEFS: record}}))


def write_index_meta(folder: Path, meta: dict) -> None:
    """``index.json``: ``meta`` with the size and SHA-256 of every other file of the index
    folder (staged beliefs excluded), sealed."""
    files = {p.name: file_record(p) for p in sorted(Path(folder).iterdir())
             if p.is_file() and p.name not in ("index.json", BELIEFS)
             and not p.name.startswith(".")}
    write_json(Path(folder) / "index.json", seal({**meta, "files": files}))


def open_beliefs(model_dir: Path, what: str, todo: str) -> np.ndarray:
    """The (N, d_b) beliefs, memory-mapped, after the fast check of their record."""
    model_dir = Path(model_dir)
    if not (model_dir / BELIEFS).is_file():
        raise AocError(f"{what}: {model_dir / BELIEFS} is missing; {todo}")
    if (model_dir / BELIEFS_META).is_file():
        meta = read_json(model_dir / BELIEFS_META, what, todo)
        check_files(model_dir, meta, (BELIEFS,), what, todo)
    try:
        beliefs = np.load(model_dir / BELIEFS, mmap_mode="r", allow_pickle=False)
    except (OSError, ValueError, EOFError) as err:
        first = str(err).splitlines()[0][:120] if str(err) else type(err).__name__
        raise AocError(f"{what}: {model_dir / BELIEFS} is not a readable .npy ({first}); "
                       f"{todo}") from None
    if beliefs.ndim != 2:
        raise AocError(f"{what}: {model_dir / BELIEFS} holds shape {beliefs.shape}, not "
                       f"(rows, belief dims); {todo}")
    return beliefs


def open_index_meta(folder: Path, what: str, todo: str) -> dict:
    """``index.json`` of an index folder (sealed) after the fast check of the files it
    records."""
    meta = read_json(Path(folder) / "index.json", what, todo)
    check_files(folder, meta, sorted(meta.get("files") or {}), what, todo)
    return meta
