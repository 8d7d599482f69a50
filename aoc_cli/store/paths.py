"""Output files of commands (audit logs, plots, CSV exports, bench results) go outside the
corpus store and into a folder that exists: an audit log at ``corpora/maze/corpus.h5`` must not
replace a corpus, and a typo in a folder name must not create folders anywhere."""

from __future__ import annotations

import os
from pathlib import Path

from aoc_cli.errors import AocError, param


def check_output(path: str | os.PathLike, flag: str, store_root: str | os.PathLike,
                 folder: bool = False) -> Path:
    """``path`` if a command may write it: not inside the store, its parent folder exists
    (``folder``: ``path`` is a folder to write into, itself created if missing), not an
    existing folder when it is a file. Else an AocError naming ``flag``: the parameter that
    gave the path (``audit``; ``--audit`` is taken as ``audit``)."""
    flag = param(flag.removeprefix("--").replace("-", "_"))
    path = Path(path)
    target = path.resolve()
    root = Path(store_root).resolve()
    if target == root or root in target.parents:
        raise AocError(f"{flag} {path} is inside the corpus store {store_root}: write it "
                       "elsewhere (the store holds only what ingest, collect, train and build_index "
                       "write)")
    parent = target.parent
    if not parent.is_dir():
        raise AocError(f"{flag} {path}: the folder {path.parent} does not exist; create it "
                       "first or give another path")
    if not folder and target.is_dir():
        raise AocError(f"{flag} {path} is a folder: give a file name")
    if folder and target.exists() and not target.is_dir():
        raise AocError(f"{flag} {path} is a file: give a folder")
    return path
