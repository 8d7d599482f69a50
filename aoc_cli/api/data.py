"""The API's entries that bring data in and out of the store: ingest, info, the corpus list,
verify, export (collect: :mod:`aoc_cli.api.collection`)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

from aoc_cli.api.common import StoreLike, open_store
from aoc_cli.formats import ExportResult, IngestResult, ReadOptions
from aoc_cli.formats import export as _export
from aoc_cli.formats import ingest as _ingest
from aoc_cli.formats.split import SplitResult
from aoc_cli.formats.split import split as _split
from aoc_cli.progress import Progress
from aoc_cli.store import list_corpora, summarize
from aoc_cli.store.verify import cleared_rows, corpora_to_verify, verify_corpus


def ingest(path: str | os.PathLike, name: str, *, store: StoreLike = None,
           fmt: str | None = None, options: ReadOptions | dict | None = None,
           overwrite: bool = False, append: bool = False,
           progress: Progress | None = None) -> IngestResult:
    """Read the dataset at ``path`` (a file, a folder or a Minari id; ``fmt`` one of
    minari|d4rl|d3rlpy|npz|csv, None: detected) into corpus ``name``. ``options``: how to read
    it (tags, CSV columns, ...: a :class:`~aoc_cli.formats.ReadOptions` or a dict of its
    fields); ``overwrite`` replaces a corpus, ``append`` adds episodes of the
    same spaces. Nothing is written unless everything is valid; ``.summary()`` is what
    ``aoc ingest`` prints."""
    options = ReadOptions(**options) if isinstance(options, dict) else options or ReadOptions()
    if progress is not None:
        options.progress = progress
    return _ingest(path, name, store=open_store(store), fmt=fmt, options=options,
                   overwrite=overwrite, append=append)


def split(name: str, *, test: float = 0.2, seed: int = 0, by: str | None = None,
          names: tuple[str, str] | None = None, store: StoreLike = None,
          overwrite: bool = False) -> SplitResult:
    """Split corpus ``name`` into ``NAME-train`` and ``NAME-test`` (or ``names``): a share
    ``test`` of its stays drawn with ``seed``, or (``by``) of a tag's values; imputation
    medians and dose bins fitted again on the training part alone; the split recorded in both
    manifests (``aoc split``)."""
    return _split(name, store=open_store(store), test=test, seed=seed, by=by, names=names,
                  overwrite=overwrite)


def info(name: str, *, store: StoreLike = None) -> dict:
    """Corpus ``name`` in detail: rows, episodes, spaces, returns, tags, sources and what has
    been built from it (``aoc info``)."""
    return summarize(open_store(store).corpus(name))


def corpora(*, store: StoreLike = None) -> tuple[Path, list[dict]]:
    """(the store's folder, one row per corpus of it) as ``aoc ls`` prints them."""
    s = open_store(store)
    return s.root, list_corpora(s)


@dataclass
class Verified:
    """``aoc verify``'s rows ``{"corpus", "file", "status", "detail"}`` (status ok, damaged,
    missing, unrecorded, or cleared: a dead writer's leftover removed first)."""

    root: Path
    corpora: list[str]
    rows: list[dict]
    cleared: int

    @property
    def bad(self) -> list[dict]:
        """The damaged or missing files' rows."""
        return [r for r in self.rows if r["status"] in ("damaged", "missing")]

    @property
    def files(self) -> int:
        """Files checked (the cleared leftovers not counted)."""
        return len(self.rows) - self.cleared

    def failure(self) -> str | None:
        """One line naming the first damaged file and what rebuilds it; None when intact."""
        bad = self.bad
        if not bad:
            return None
        return (f"{len(bad)} of {self.files} files damaged or missing, first "
                f"{bad[0]['corpus']}/{bad[0]['file']} ({bad[0]['detail']}): "
                "re-ingest or re-collect a damaged corpus with --overwrite, "
                "re-train a damaged model with --overwrite, re-run `aoc index` "
                "for damaged beliefs or an index")


def verify(names: Sequence[str] | None = None, *, store: StoreLike = None,
           progress: Progress | None = None) -> Verified:
    """Recompute every checksum the store recorded for corpora ``names`` (default every
    corpus, damaged folders too), after clearing what dead writers left; nothing raises for a
    damaged file: see :attr:`Verified.bad` and :meth:`Verified.failure`."""
    s = open_store(store)
    chosen = corpora_to_verify(s, list(names or []))
    cleared = cleared_rows(s)
    rows = list(cleared)
    for i, name in enumerate(chosen):
        if progress is not None:
            progress(i, len(chosen), f"verify {name}")
        rows += verify_corpus(s, name)
        if progress is not None:
            progress(i + 1, len(chosen))
    return Verified(s.root, chosen, rows, len(cleared))


def export(name: str, to: str, out: str | os.PathLike, *, store: StoreLike = None,
           select: dict[str, list[str]] | None = None,
           exclude: dict[str, list[str]] | None = None, rows: tuple[int, int] | None = None,
           static: str | os.PathLike | None = None, overwrite: bool = False,
           progress: Progress | None = None) -> ExportResult:
    """Write corpus ``name`` as ``to`` (minari, d4rl or csv) to ``out`` (outside the store):
    the rows of the tag selections ``select`` / ``exclude`` ({tag: [values]}) within the row
    range ``rows`` = (start, end); ``static`` (csv): the per-episode covariates to this file.
    ``aoc ingest`` reads it back as the same corpus."""
    return _export(name, to, out, store=open_store(store), select=select, exclude=exclude,
                   rows=rows, overwrite=overwrite, static=static, progress=progress)
