"""Write a corpus out again: ``aoc export`` as a library function.

>>> from aoc_cli.formats import export
>>> export("ward", "csv", "ward.csv")                       # doctest: +SKIP

Three formats: ``minari`` (a dataset folder written by minari's own writer,
:mod:`aoc_cli.formats.export_minari`), ``d4rl`` (one flat HDF5 file,
:mod:`aoc_cli.formats.export_d4rl`) and ``csv`` (one row per step, plus its column mapping,
:mod:`aoc_cli.formats.export_csv`). Each carries the export spec
(:mod:`aoc_cli.formats.spec`), so ``aoc ingest`` of the result gives the same corpus: the same
content hash, spaces, tag labels and episode ids.

Every file goes to a temporary beside its target and is renamed into place; nothing is written
into the store, and nothing existing is replaced without ``overwrite``.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats import export_csv, export_d4rl, export_minari
from aoc_cli.formats.minari import data_folder
from aoc_cli.formats.spec import describe
from aoc_cli.progress import Progress
from aoc_cli.rows import row_selection
from aoc_cli.store import CorpusData, Store, episode_starts_from_lengths

EXPORT_FORMATS = ("minari", "d4rl", "csv")


@dataclass
class ExportResult:
    """What ``aoc export`` prints."""

    name: str
    format: str
    out: str
    rows: int
    episodes: int
    seconds: float
    content_hash: str
    files: list[str] = field(default_factory=list)

    def summary(self) -> dict:
        return {"name": self.name, "format": self.format, "out": self.out, "rows": self.rows,
                "episodes": self.episodes, "seconds": round(self.seconds, 3),
                "content_hash": self.content_hash, "files": self.files}


def select_rows(data: CorpusData, mask: np.ndarray) -> CorpusData:
    """The rows where ``mask`` (N,) is true. Each run of consecutive selected rows of one
    episode becomes an episode; a run cut off before its episode's end is truncated there.
    An episode split into several runs gives ids ``<id>#1``, ``<id>#2``, ... (its index when
    the corpus has no ids)."""
    mask = np.asarray(mask, bool)
    n = data.n_rows
    starts = np.asarray(data.episode_starts)
    episode = np.searchsorted(starts, np.arange(n), side="right") - 1
    rows = np.flatnonzero(mask)
    new_run = np.ones(len(rows), bool)
    new_run[1:] = (np.diff(rows) != 1) | (np.diff(episode[rows]) != 0)
    run_starts = np.flatnonzero(new_run)
    lengths = np.diff(np.append(run_starts, len(rows)))
    last = rows[run_starts + lengths - 1]
    truncations = np.asarray(data.truncations)[rows].copy()
    cut = (last != starts[episode[last] + 1] - 1) & ~np.asarray(data.terminals)[last]
    truncations[(run_starts + lengths - 1)[cut]] = True
    run_episode = episode[rows[run_starts]]
    ids = None
    counts = np.bincount(run_episode, minlength=data.n_episodes)
    if data.episode_ids is not None or (counts > 1).any():
        base = data.episode_ids or [str(e) for e in range(data.n_episodes)]
        seen: dict[int, int] = {}
        ids = []
        for e in run_episode.tolist():
            seen[e] = seen.get(e, 0) + 1
            ids.append(base[e] if counts[e] == 1 else f"{base[e]}#{seen[e]}")
    return CorpusData(
        observations=np.asarray(data.observations)[rows],
        actions=np.asarray(data.actions)[rows],
        rewards=None if data.rewards is None else np.asarray(data.rewards)[rows],
        terminals=np.asarray(data.terminals)[rows], truncations=truncations,
        episode_starts=episode_starts_from_lengths(lengths),
        observation_space=data.observation_space, action_space=data.action_space,
        tags={k: (np.asarray(c)[rows], lab) for k, (c, lab) in data.tags.items()},
        columns={k: np.asarray(v)[rows] for k, v in data.columns.items()},
        episode_ids=ids, source=data.source,
        imputed=_rows_imputed(data.imputed, rows), preprocessing=data.preprocessing,
    )


def _rows_imputed(imputed: np.ndarray | None, rows: np.ndarray) -> np.ndarray | None:
    """The imputed-cell mask of the selected ``rows`` (None when none of them was imputed)."""
    if imputed is None:
        return None
    part = np.asarray(imputed)[rows]
    return part if part.any() else None


def check_target(path: Path, store: Store, overwrite: bool, *, folder: bool = False) -> None:
    """Refuse a target inside the store, an existing path without ``overwrite``, a file where
    a folder goes (and the reverse), and a folder to replace that is not a Minari dataset."""
    target = Path(os.path.abspath(path))
    root = Path(os.path.abspath(store.root))
    for p in (target, target.resolve()):
        if p == root or root in p.parents or root.resolve() in p.parents or \
                p == root.resolve():
            raise AocError(f"refusing to write {path} inside the corpus store {store.root}: "
                           "export to a path outside it")
    if not os.path.lexists(target):
        return
    if not overwrite:
        raise AocError(f"{path} already exists: pass {param('overwrite')} to replace it, or choose "
                       f"another {param('out')}")
    if folder:
        if not target.is_dir():
            raise AocError(f"{path} is a file, a Minari dataset is a folder: choose another "
                           f"{param('out')}")
        if any(target.iterdir()) and data_folder(target) is None:
            raise AocError(f"{path} is a folder that holds no Minari dataset: {param('overwrite')} "
                           f"replaces only a dataset folder; choose another {param('out')}")
    elif target.is_dir():
        raise AocError(f"{path} is a folder: pass a file name as {param('out')}")


def export(name: str, fmt: str, out: str | os.PathLike, *, store: Store | None = None,
           select: dict[str, list[str]] | None = None,
           exclude: dict[str, list[str]] | None = None,
           rows: tuple[int, int] | None = None, overwrite: bool = False,
           static: str | os.PathLike | None = None,
           progress: Progress | None = None) -> ExportResult:
    """Write corpus ``name`` (the rows of ``select`` / ``exclude``, tag selections as
    :func:`aoc_cli.rows.row_selection` takes them, within the row range ``rows`` = (start,
    end), end excluded) as ``fmt`` to ``out``. ``static`` (CSV
    only): also write the per-patient covariates of a corpus read with ``--static`` to this
    file, one row per episode id, and leave them out of the step rows."""
    t0 = time.perf_counter()
    if fmt not in EXPORT_FORMATS:
        raise AocError(f"unknown export format {fmt!r}: use {param('to')} "
                       f"{'|'.join(EXPORT_FORMATS)}")
    if static is not None and fmt != "csv":
        raise AocError(f"{param('static')} writes CSV covariates: use it with {param('to', 'csv')}")
    store = store or Store.open()
    out = Path(out)
    corpus = store.corpus(name)
    targets = [out] if fmt != "csv" else export_csv.targets(out, static)
    for target in targets:
        check_target(target, store, overwrite, folder=fmt == "minari")
    if rows is not None and not (0 <= rows[0] < rows[1]):
        raise AocError(f"rows must be START:END with 0 <= START < END, got {rows[0]}:{rows[1]}",
                       param="rows")
    mask = row_selection(corpus, select, exclude, row_range=rows)
    data = corpus.load()
    if mask is not None:
        data = select_rows(data, mask)
    # a whole corpus is what its manifest's content hash was computed from
    spec = describe(data, name, fmt, content_hash=corpus.hash if mask is None else None)
    writer = {"minari": export_minari.write_minari, "d4rl": export_d4rl.write_d4rl,
              "csv": export_csv.write_csv}[fmt]
    kwargs = {"static": Path(static)} if static is not None else {}
    files = writer(data, spec, out, progress=progress, **kwargs)
    return ExportResult(name=name, format=fmt, out=str(out), rows=data.n_rows,
                        episodes=data.n_episodes, seconds=time.perf_counter() - t0,
                        content_hash=spec["content_hash"], files=[str(f) for f in files])
