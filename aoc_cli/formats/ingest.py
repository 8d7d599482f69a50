"""Read a dataset into a corpus of the store: ``aoc ingest`` as a library function.

Checks that need no reading (the name, an existing corpus) come first, so bad usage fails
before a long read; the store is written only once everything is valid, atomically.
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats.common import ReadOptions, observed_bounds
from aoc_cli.formats.csv import read_csv, read_frame
from aoc_cli.formats.d3rlpy import read_d3rlpy
from aoc_cli.formats.d4rl import read_d4rl
from aoc_cli.formats.detect import FORMATS, detect_format
from aoc_cli.formats.impute import counts
from aoc_cli.formats.minari import read_minari
from aoc_cli.formats.npz import read_npz
from aoc_cli.store import CorpusData, Store, check_name, writing_corpus
from aoc_cli.store.columns import ColumnStack
from aoc_cli.store.corpus import all_finite, finite_rows


def read_dataset(path: str | os.PathLike, fmt: str | None = None,
                 options: ReadOptions | None = None) -> CorpusData:
    """Read ``path`` (format ``fmt`` or detected) into a validated :class:`CorpusData`.

    Applies the options every format shares: constant ``tags``, ``reward_free``, and the
    non-finite check (an AocError naming the first bad row) or, with ``drop_nonfinite``, the
    removal of every episode holding a NaN/inf observation, action or reward.
    """
    data = _read_dataset(path, fmt, options)
    if isinstance(data.observations, ColumnStack):
        data.observations = np.asarray(data.observations)
    if isinstance(data.imputed, ColumnStack):
        data.imputed = np.asarray(data.imputed)
    return data


def _read_dataset(path, fmt, options) -> CorpusData:
    """:func:`read_dataset`, a table's observations and imputed mask left as
    :class:`ColumnStack` (what :func:`ingest` hands the store, which makes their rows block by
    block)."""
    options = options or ReadOptions()
    if is_frame(path):
        fmt = "frame"
    elif fmt is None:
        fmt = detect_format(path)
    elif fmt not in FORMATS:
        raise AocError(f"unknown format {fmt!r}: use {param('fmt')} {'|'.join(FORMATS)}")
    elif fmt != "minari" and not Path(path).exists():
        raise AocError(f"no such file or folder: {path}; check the path")
    tabular = ("impute", "impute_like", "outcome", "outcome_reward", "bin_actions", "bin_like",
               "censored_column")
    asked = [name for name in tabular if getattr(options, name) is not None] + [
        name for name in ("impute_mask", "allow_role_overlap") if getattr(options, name)]
    if asked and fmt not in ("csv", "parquet", "frame"):
        raise AocError(f"{param(asked[0])} applies to tables (CSV, Parquet, a DataFrame), not "
                       f"to {fmt} data")
    reader = {"minari": read_minari, "d4rl": read_d4rl, "d3rlpy": read_d3rlpy, "npz": read_npz,
              "csv": read_csv, "parquet": read_csv, "frame": read_frame}[fmt]
    data = reader(Path(path) if fmt not in ("minari", "frame") else path, options)
    where = "the frame" if fmt == "frame" else path
    if data.n_rows == 0:
        raise AocError(f"{where} has zero rows: nothing to store")
    if options.reward_free:
        data.rewards = None
    for key, value in options.tags.items():
        if key in data.tags:
            raise AocError(f"tag {key!r} is given twice ({param('tags')} and "
                           f"{param('tag_columns')})")
        data.tags[key] = (np.zeros(data.n_rows, np.int32), [value])
    data.source = {**data.source, "format": fmt}
    if options.drop_nonfinite:
        bad = data.nonfinite_episodes()
        if bad.all():
            raise AocError(f"every episode of {where} holds NaN or inf values: nothing left "
                           "to store")
        if bad.any():
            data = data.select_episodes(~bad)
            data.source = {**data.source, "dropped_nonfinite_episodes": int(bad.sum())}
            if data.action_space.get("bounds") == "observed":
                data.action_space = {**data.action_space,
                                     **observed_bounds(np.asarray(data.actions))}
    else:
        _check_finite(data)
    return data.validate()


def _check_finite(data: CorpusData) -> None:
    """AocError naming the first row (and its episode and step) holding NaN or inf."""
    first = None
    for name, arr in (("observations", data.observations), ("actions", data.actions),
                      ("rewards", data.rewards)):
        if arr is None:
            continue
        arr = arr if isinstance(arr, ColumnStack) else np.asarray(arr)
        if all_finite(arr):
            continue
        finite = finite_rows(arr)
        if not finite.all():
            row = int(np.argmin(finite))
            if first is None or row < first[1]:
                first = (name, row)
    if first is None:
        return
    name, row = first
    starts = np.asarray(data.episode_starts)
    ep = int(np.searchsorted(starts, row, side="right") - 1)
    label = f"episode {ep}" + (f" (id {data.episode_ids[ep]})" if data.episode_ids else "")
    raise AocError(f"{name} of row {row} ({label}, step {row - int(starts[ep])}) is not finite "
                   f"(NaN or inf): fix the data or pass {param('drop_nonfinite')} to drop the "
                   "episodes that hold such rows")


def is_frame(source) -> bool:
    """Whether ``source`` is an in-memory table (Arrow, pandas, polars), not a path."""
    return not isinstance(source, (str, bytes, os.PathLike))


def with_fitted(store: Store, name: str, options: ReadOptions, append: bool) -> ReadOptions:
    """``options`` with the preprocessing to reuse (``fitted``): the imputation and dose bins
    of the corpus appended to, or of those named by ``impute_like`` and ``bin_like``."""
    fitted: dict = {"from": {}}
    wanted = []
    if append and store.exists(name):
        wanted += [("impute", name, False), ("bins", name, False)]
    if options.impute_like:
        wanted.append(("impute", options.impute_like, True))
    if options.bin_like:
        wanted.append(("bins", options.bin_like, True))
    for key, corpus, required in wanted:
        pre = store.corpus(corpus).preprocessing
        if key not in pre:
            if required:
                flag = param("impute_like" if key == "impute" else "bin_like", corpus)
                raise AocError(f"{flag}: corpus {corpus!r} has no "
                               f"{'imputation' if key == 'impute' else 'dose bins'} to reuse")
            continue
        fitted[key] = pre[key]
        fitted["from"][key] = corpus
    return dataclasses.replace(options, fitted=fitted) if len(fitted) > 1 else options


@dataclass
class IngestResult:
    """What ``aoc ingest`` prints."""

    name: str
    format: str
    rows: int
    episodes: int
    seconds: float
    total_rows: int
    total_episodes: int
    dropped_episodes: int
    imputed_cells: dict = field(default_factory=dict)
    censored_episodes: int = 0

    def summary(self) -> dict:
        out = {"name": self.name, "format": self.format, "rows": self.rows,
               "episodes": self.episodes, "seconds": round(self.seconds, 3)}
        if self.total_rows != self.rows:
            out.update(total_rows=self.total_rows, total_episodes=self.total_episodes)
        if self.dropped_episodes:
            out["dropped_episodes"] = self.dropped_episodes
        if self.censored_episodes:
            out["censored_episodes"] = self.censored_episodes
        if self.imputed_cells:
            out["imputed_cells"] = self.imputed_cells
        return out


def ingest(path: str | os.PathLike, name: str, *, store: Store | None = None,
           fmt: str | None = None, options: ReadOptions | None = None,
           overwrite: bool = False, append: bool = False) -> IngestResult:
    """Read ``path`` (or an in-memory table: Arrow, pandas, polars) and store it as corpus
    ``name`` (replace with ``overwrite``, add episodes with ``append``: same spaces required).
    Nothing is written unless everything is valid."""
    t0 = time.perf_counter()
    store = store or Store.open()
    options = options or ReadOptions()
    check_name(name)
    store.check_writable(name, overwrite=overwrite, append=append, notify=False)
    if is_frame(path):
        fmt = "frame"
    elif fmt is None:
        fmt = detect_format(path)  # a missing or unknown input fails before the store is touched
    with writing_corpus(store.root, name):  # one writer per corpus: a second fails at once
        store.check_writable(name, overwrite=overwrite, append=append)
        data = _read_dataset(path, fmt, with_fitted(store, name, options, append))
        corpus = store.write(name, data, overwrite=overwrite, append=append)
    return IngestResult(
        name=name, format=data.source.get("format", fmt or "?"), rows=data.n_rows,
        episodes=data.n_episodes, seconds=time.perf_counter() - t0,
        total_rows=corpus.n_rows, total_episodes=corpus.n_episodes,
        dropped_episodes=int(data.source.get("dropped_nonfinite_episodes", 0)),
        imputed_cells={} if data.imputed is None else counts(
            data.imputed, data.observation_space.get("names") or
            [f"obs_{j}" for j in range(data.observations.shape[1])]),
        censored_episodes=int(data.truncations[np.asarray(data.episode_starts[1:]) - 1].sum())
        if data.preprocessing else 0,
    )
