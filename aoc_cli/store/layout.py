"""The store's root and on-disk layout, in one place::

    <root>/                          --store, else $AOC_STORE, else ./corpora (store_root)
      <name>/corpus.h5, manifest.json
      <name>/models/<model>/         a belief model and its row beliefs (model_dir)
      <name>/models/<model>/index/<index>/   a corpus index built on it (index_dir)
      <name>/targets/                value targets computed on the corpus as a held-out log
                                     (targets_dir; aoc_cli.belief.targets.held_out_targets)
      .<name>.lock, .<name>.model-<model>.lock   writer locks (aoc_cli.store.lock)

Every other module builds these paths through the functions here, and names the default
model and index by :data:`DEFAULT_MODEL` and :data:`DEFAULT_INDEX`
(tests/store/test_layout.py checks that no module spells them out).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from aoc_cli.errors import AocError

#: The environment variable naming the store root (read here only, by :func:`store_root`).
STORE_ENV = "AOC_STORE"
#: The store root when neither ``--store`` nor ``$AOC_STORE`` is given (relative to the
#: working directory).
DEFAULT_ROOT = "corpora"
#: The model id ``aoc train`` writes and every command reads unless told otherwise.
DEFAULT_MODEL = "default"
#: The index id ``aoc index`` writes and every command reads unless told otherwise.
DEFAULT_INDEX = "default"

CORPUS_FILE = "corpus.h5"
MANIFEST_FILE = "manifest.json"
MODELS = "models"
INDEXES = "index"
TARGETS = "targets"

_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")


def check_name(name: str, what: str = "corpus") -> str:
    """A store name: letters, digits, '.', '_', '-'; no path separators, no '..'."""
    if not _NAME.match(name or "") or ".." in name:
        raise AocError(
            f"invalid {what} name {name!r}: use letters, digits, '.', '_' and '-' "
            "(no path separators, no '..')"
        )
    return name


def is_name(name: str) -> bool:
    """Whether ``name`` is a valid store name (:func:`check_name` without the error)."""
    return bool(_NAME.match(name or "")) and ".." not in name


def store_root(root: str | os.PathLike | None = None) -> Path:
    """The store root: ``root`` (``--store``) when given, else ``$AOC_STORE``, else
    ``./corpora``."""
    if root is None:
        root = os.environ.get(STORE_ENV) or DEFAULT_ROOT
    return Path(root)


def holds_anything(corpus_path: str | os.PathLike) -> bool:
    """Whether a corpus's folder holds anything of a corpus (its manifest, its corpus file or
    models); the lock file of a name that holds nothing may go (:mod:`aoc_cli.store.sweep`)."""
    path = Path(corpus_path)
    return (path / MANIFEST_FILE).is_file() or (path / CORPUS_FILE).exists() \
        or models_dir(path).exists()


def models_dir(corpus_path: str | os.PathLike) -> Path:
    """``<corpus>/models/``: every model of a corpus."""
    return Path(corpus_path) / MODELS


def model_dir(corpus_path: str | os.PathLike, model_id: str) -> Path:
    """``<corpus>/models/<model_id>/`` (the id checked as a store name)."""
    return models_dir(corpus_path) / check_name(model_id, "model")


def indexes_dir(corpus_path: str | os.PathLike, model_id: str) -> Path:
    """``<corpus>/models/<model_id>/index/``: every corpus index built on one model."""
    return model_dir(corpus_path, model_id) / INDEXES


def index_dir(corpus_path: str | os.PathLike, model_id: str, index_id: str) -> Path:
    """``<corpus>/models/<model_id>/index/<index_id>/`` (both ids checked as store names)."""
    return indexes_dir(corpus_path, model_id) / check_name(index_id, "index")


def targets_dir(corpus_path: str | os.PathLike) -> Path:
    """``<corpus>/targets/``: value targets computed on the corpus as a held-out log."""
    return Path(corpus_path) / TARGETS
