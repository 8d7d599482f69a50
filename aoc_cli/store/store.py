"""The corpus store: ``<root>/<name>/corpus.h5`` + ``manifest.json`` (+ ``models/<id>/``).

The root and the layout are :mod:`aoc_cli.store.layout`. Writing is
:mod:`aoc_cli.store.writer` (a temporary folder renamed into place, under the corpus's writer
lock, :mod:`aoc_cli.store.lock`); reading is :mod:`aoc_cli.store.reader`. The manifest's
``content_hash`` identifies the data; everything derived from a corpus records it and is
refused when it no longer matches.

A folder of the store that holds a corpus file or models but no ``manifest.json`` is a
*damaged* corpus (a manifest deleted or lost): it is listed as damaged, and only
``--overwrite`` replaces it.
"""

from __future__ import annotations

import os
from pathlib import Path

from aoc_cli.errors import AocError, CorpusExists, CorpusNotFound, Damaged, param, warn
from aoc_cli.store.corpus import CorpusData
from aoc_cli.store.layout import (CORPUS_FILE, MANIFEST_FILE, check_name, is_name, models_dir,
                                  store_root)
from aoc_cli.store.reader import Corpus
from aoc_cli.store.writer import write_corpus

__all__ = ["Store", "check_name"]


class Store:
    """A folder of corpora."""

    def __init__(self, root: Path):
        self.root = Path(root)

    @classmethod
    def open(cls, root: str | os.PathLike | None = None) -> "Store":
        root = store_root(root)
        if root.exists() and not root.is_dir():
            raise AocError(f"store {root} is not a folder: pass {param('store')} with a folder "
                           "path")
        return cls(root)

    def path(self, name: str) -> Path:
        return self.root / check_name(name)

    def exists(self, name: str) -> bool:
        return (self.path(name) / MANIFEST_FILE).is_file()

    def is_damaged(self, name: str) -> bool:
        """A folder with a corpus file or models but no manifest."""
        path = self.path(name)
        return not (path / MANIFEST_FILE).is_file() and (
            (path / CORPUS_FILE).exists() or models_dir(path).exists())

    def names(self) -> list[str]:
        if not self.root.is_dir():
            return []
        return sorted(p.name for p in self.root.iterdir()
                      if not p.name.startswith(".") and (p / MANIFEST_FILE).is_file())

    def damaged_names(self) -> list[str]:
        """Folders that hold a corpus file or models but no manifest."""
        if not self.root.is_dir():
            return []
        return sorted(p.name for p in self.root.iterdir()
                      if p.is_dir() and not p.name.startswith(".") and is_name(p.name)
                      and self.is_damaged(p.name))

    def corpus(self, name: str) -> Corpus:
        """Open a stored corpus (read-only, lazy)."""
        path = self.path(name)
        if not (path / MANIFEST_FILE).is_file():
            if self.is_damaged(name):
                raise Damaged(name, f"{path} has no manifest.json")
            raise CorpusNotFound(name, self.root, self.names())
        return Corpus(path)

    def check_writable(self, name: str, *, overwrite: bool = False, append: bool = False,
                       notify: bool = True) -> None:
        """Refuse to write ``name`` when that would replace data not asked to be replaced:
        an existing corpus without --overwrite/--append, a damaged folder without
        --overwrite. ``append`` to a missing corpus creates it (with a warning when
        ``notify``)."""
        check_name(name)
        if overwrite and append:
            raise AocError(f"pass either {param('overwrite', True)} or {param('append', True)}, "
                           "not both")
        if self.is_damaged(name) and not overwrite:
            raise AocError(f"corpus folder {self.path(name)} is damaged (a corpus file or "
                           f"models but no manifest.json): pass {param('overwrite', True)} to replace it and "
                           "everything in it, or move it away")
        if self.exists(name):
            if not (overwrite or append):
                raise CorpusExists(name)
        elif append and notify and not self.is_damaged(name):
            warn(f"{param('append', True)}: corpus {name!r} does not exist in {self.root}; creating it")

    def write(self, name: str, data: CorpusData, *, overwrite: bool = False,
              append: bool = False, float_opts: dict | None = None) -> Corpus:
        """Validate and store ``data`` as corpus ``name`` (see
        :func:`aoc_cli.store.writer.write_corpus`)."""
        check_name(name)
        return write_corpus(self, name, data, overwrite=overwrite, append=append,
                            float_opts=float_opts)
