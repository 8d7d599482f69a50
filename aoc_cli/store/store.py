"""The corpus store: ``<root>/<name>/corpus.h5`` + ``manifest.json`` (+ ``models/<id>/``).

The root is ``--store``, else ``$AOC_STORE``, else ``./corpora``. A corpus folder is built in a
temporary folder beside it and renamed into place, so an interrupted write leaves the previous
state intact. The manifest's ``content_hash`` identifies the data; everything derived from a
corpus records it and is refused when it no longer matches.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from functools import cached_property
from pathlib import Path

import h5py
import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.store.atomic import atomic_dir, hash_arrays, write_json
from aoc_cli.store.corpus import CorpusData, History, episode_starts_from_lengths, gather_history

SCHEMA_VERSION = 1
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,127}$")
#: Columns up to this many bytes are read into memory once; larger ones are sliced from disk.
IN_MEMORY_BYTES = 2 << 30


def check_name(name: str, what: str = "corpus") -> str:
    """A store name: letters, digits, '.', '_', '-'; no path separators, no '..'."""
    if not _NAME.match(name or "") or ".." in name:
        raise AocError(
            f"invalid {what} name {name!r}: use letters, digits, '.', '_' and '-' "
            "(no path separators, no '..')"
        )
    return name


class Store:
    """A folder of corpora."""

    def __init__(self, root: Path):
        self.root = Path(root)

    @classmethod
    def open(cls, root: str | os.PathLike | None = None) -> "Store":
        if root is None:
            root = os.environ.get("AOC_STORE") or "corpora"
        root = Path(root)
        if root.exists() and not root.is_dir():
            raise AocError(f"store {root} is not a folder: pass --store with a folder path")
        return cls(root)

    def path(self, name: str) -> Path:
        return self.root / check_name(name)

    def exists(self, name: str) -> bool:
        return (self.path(name) / "manifest.json").is_file()

    def names(self) -> list[str]:
        if not self.root.is_dir():
            return []
        return sorted(p.name for p in self.root.iterdir()
                      if not p.name.startswith(".") and (p / "manifest.json").is_file())

    def corpus(self, name: str) -> "Corpus":
        """Open a stored corpus (read-only, lazy)."""
        path = self.path(name)
        if not (path / "manifest.json").is_file():
            known = ", ".join(self.names()) or "none"
            raise AocError(
                f"no corpus {name!r} in store {self.root} (known: {known}); "
                "create it with `aoc ingest` or `aoc collect`"
            )
        return Corpus(path)

    def write(self, name: str, data: CorpusData, *, overwrite: bool = False,
              append: bool = False, on_progress=None) -> "Corpus":
        """Validate and store ``data`` as corpus ``name`` (atomically).

        ``append`` adds the episodes to an existing corpus with the same spaces; derived
        models are kept but become stale (their corpus hash no longer matches).
        """
        check_name(name)
        data.validate()
        exists = self.exists(name)
        if exists and not (overwrite or append):
            raise AocError(f"corpus {name!r} already exists: pass --overwrite to replace it "
                           "or --append to add to it")
        keep_models = None
        sources = [data.source]
        if append and exists:
            old = self.corpus(name)
            old.check_same_spaces(data)
            sources = old.manifest.get("sources", []) + [data.source]
            data = concat(old.load(), data)
            keep_models = old.path / "models"
        self.root.mkdir(parents=True, exist_ok=True)
        with atomic_dir(self.path(name)) as tmp:
            digest = _write_h5(tmp / "corpus.h5", data)
            if keep_models is not None and keep_models.is_dir():
                shutil.copytree(keep_models, tmp / "models")
            write_json(tmp / "manifest.json", _manifest(name, data, digest, sources))
        return self.corpus(name)

    def delete(self, name: str) -> None:
        shutil.rmtree(self.path(name))


def concat(a: CorpusData, b: CorpusData) -> CorpusData:
    """Episodes of ``a`` then ``b`` (same spaces); tags merged by label."""
    tags = {}
    for key in sorted(set(a.tags) | set(b.tags)):
        labels: list[str] = []
        codes = []
        for part in (a, b):
            if key in part.tags:
                c, lab = part.tags[key]
            else:
                c, lab = np.zeros(part.n_rows, np.int32), ["unknown"]
            for x in lab:
                if x not in labels:
                    labels.append(x)
            remap = np.array([labels.index(x) for x in lab], dtype=np.int32)
            codes.append(remap[np.asarray(c)])
        tags[key] = (np.concatenate(codes), labels)
    columns = {k: np.concatenate([a.columns.get(k, np.full(a.n_rows, np.nan)),
                                  b.columns.get(k, np.full(b.n_rows, np.nan))])
               for k in sorted(set(a.columns) | set(b.columns))}
    ids = None
    if a.episode_ids is not None or b.episode_ids is not None:
        ids = (a.episode_ids or [f"{i}" for i in range(a.n_episodes)]) + \
              (b.episode_ids or [f"{a.n_episodes + i}" for i in range(b.n_episodes)])
    obs_dtype = np.result_type(a.observations.dtype, b.observations.dtype)
    return CorpusData(
        observations=np.concatenate([a.observations, b.observations]).astype(obs_dtype),
        actions=np.concatenate([a.actions, b.actions]),
        rewards=None if a.rewards is None else np.concatenate([a.rewards, b.rewards]),
        terminals=np.concatenate([a.terminals, b.terminals]),
        truncations=np.concatenate([a.truncations, b.truncations]),
        episode_starts=episode_starts_from_lengths(
            np.concatenate([np.diff(a.episode_starts), np.diff(b.episode_starts)])),
        observation_space=a.observation_space,
        action_space=a.action_space,
        tags=tags,
        columns=columns,
        episode_ids=ids,
        source=b.source,
    )


#: Float columns (observations, actions, rewards, numeric columns) are stored contiguous and
#: uncompressed: measured on 1M random-walk rows (benchmarks/ingest.py, docs/benchmarks.md),
#: gzip-1 + shuffle saved 25% of the bytes for 20x the write time and lzf 2%, and a contiguous
#: uncompressed dataset can be memory-mapped (:meth:`Corpus.read` of large columns).
#: Flags, step counters and tag codes compress 50-100x cheaply: gzip-1 + shuffle, chunked.
FLOAT_OPTS: dict = {}
SMALL_OPTS: dict = dict(compression="gzip", compression_opts=1, shuffle=True)
CHUNK_ROWS = 1 << 16


def _write_h5(path: Path, data: CorpusData) -> str:
    """Write the arrays (float columns contiguous, the rest chunked gzip-1 + shuffle) and
    return their content hash."""

    def put(f, key, arr):
        arr = np.ascontiguousarray(arr)
        if np.issubdtype(arr.dtype, np.floating) and not FLOAT_OPTS:
            f.create_dataset(key, data=arr)
            return
        opts = FLOAT_OPTS if np.issubdtype(arr.dtype, np.floating) else SMALL_OPTS
        chunks = (max(1, min(len(arr), CHUNK_ROWS)),) + arr.shape[1:]
        f.create_dataset(key, data=arr, chunks=chunks, **opts)

    timesteps = data.timesteps()
    with h5py.File(path, "w") as f:
        put(f, "observations", data.observations)
        put(f, "actions", data.actions)
        if data.rewards is not None:
            put(f, "rewards", data.rewards)
        put(f, "terminals", data.terminals)
        put(f, "truncations", data.truncations)
        f.create_dataset("episode_starts", data=data.episode_starts)
        put(f, "timesteps", timesteps)
        for key, (codes, labels) in data.tags.items():
            put(f, f"tags/{key}", codes)
            f[f"tags/{key}"].attrs["labels"] = json.dumps(labels)
        for key, col in data.columns.items():
            put(f, f"columns/{key}", col)
        if data.episode_ids is not None:
            f.create_dataset("episode_ids", data=np.array(data.episode_ids, dtype=object),
                             dtype=h5py.string_dtype())
        f.attrs["schema_version"] = SCHEMA_VERSION
        f.attrs["observation_space"] = json.dumps(data.observation_space)
        f.attrs["action_space"] = json.dumps(data.action_space)
        f.attrs["source"] = json.dumps(data.source)
    parts = [data.observations, data.actions, data.rewards, data.terminals, data.truncations,
             data.episode_starts]
    for key in sorted(data.tags):
        parts.append(data.tags[key][0])
    for key in sorted(data.columns):
        parts.append(data.columns[key])
    return hash_arrays(*parts)


def _memmap(ds: h5py.Dataset, path: Path) -> np.ndarray | None:
    """A read-only memory map of a contiguous, uncompressed dataset (None if it is not)."""
    offset = ds.id.get_offset()
    if ds.chunks is not None or ds.compression is not None or offset is None:
        return None
    return np.memmap(path, mode="r", dtype=ds.dtype, shape=ds.shape, offset=offset)


def _manifest(name: str, data: CorpusData, digest: str, sources: list[dict]) -> dict:
    return {
        "schema_version": SCHEMA_VERSION,
        "name": name,
        "written": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "rows": data.n_rows,
        "episodes": data.n_episodes,
        "observation_space": data.observation_space,
        "action_space": data.action_space,
        "has_rewards": data.rewards is not None,
        "tags": {k: labels for k, (_c, labels) in data.tags.items()},
        "columns": sorted(data.columns),
        "content_hash": digest,
        "sources": sources,
    }


class Corpus:
    """A stored corpus, read lazily. Small columns are cached in memory on first use."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.name = self.path.name
        self.manifest = json.loads((self.path / "manifest.json").read_text())
        self._cache: dict[str, np.ndarray] = {}

    # -- description -------------------------------------------------------------------
    @property
    def hash(self) -> str:
        return self.manifest["content_hash"]

    @property
    def n_rows(self) -> int:
        return int(self.manifest["rows"])

    @property
    def n_episodes(self) -> int:
        return int(self.manifest["episodes"])

    @property
    def observation_space(self) -> dict:
        return self.manifest["observation_space"]

    @property
    def action_space(self) -> dict:
        return self.manifest["action_space"]

    @property
    def observation_dim(self) -> int:
        return int(self.observation_space["shape"][0])

    @property
    def discrete(self) -> bool:
        return self.action_space["type"] == "discrete"

    @property
    def action_dim(self) -> int:
        """Continuous: the number of action dimensions; discrete: 1 (one integer a row)."""
        return 1 if self.discrete else int(self.action_space["shape"][0])

    @property
    def n_actions(self) -> int | None:
        return int(self.action_space["n"]) if self.discrete else None

    @property
    def has_rewards(self) -> bool:
        return bool(self.manifest["has_rewards"])

    @property
    def models_dir(self) -> Path:
        return self.path / "models"

    def check_same_spaces(self, data: CorpusData) -> None:
        def shape(space):
            return (space.get("type"), tuple(space.get("shape", ())), space.get("n"))

        if shape(self.observation_space) != shape(data.observation_space) or \
                shape(self.action_space) != shape(data.action_space) or \
                self.has_rewards != (data.rewards is not None):
            raise AocError(
                f"cannot --append to {self.name!r}: its spaces are observation "
                f"{shape(self.observation_space)}, action {shape(self.action_space)}, rewards "
                f"{self.has_rewards}; the new data has observation "
                f"{shape(data.observation_space)}, action {shape(data.action_space)}, rewards "
                f"{data.rewards is not None}"
            )

    # -- arrays --------------------------------------------------------------------------
    def _h5(self) -> h5py.File:
        return h5py.File(self.path / "corpus.h5", "r")

    def read(self, key: str, rows=None) -> np.ndarray:
        """A column (``observations``, ``actions``, ``rewards``, ``tags/<t>``, ``columns/<c>``,
        ...) for all rows or for ``rows`` (any order, repeats allowed)."""
        if key in self._cache:
            arr = self._cache[key]
            return arr if rows is None else arr[np.asarray(rows)]
        with self._h5() as f:
            if key not in f:
                raise AocError(f"corpus {self.name!r} has no column {key!r}")
            ds = f[key]
            if rows is None and ds.size * ds.dtype.itemsize > IN_MEMORY_BYTES:
                mapped = _memmap(ds, self.path / "corpus.h5")
                if mapped is not None:
                    return mapped
            if rows is None or ds.size * ds.dtype.itemsize <= IN_MEMORY_BYTES:
                arr = ds[()]
                if ds.size * ds.dtype.itemsize <= IN_MEMORY_BYTES:
                    self._cache[key] = arr
                return arr if rows is None else arr[np.asarray(rows)]
            mapped = _memmap(ds, self.path / "corpus.h5")
            if mapped is not None:
                return mapped[np.asarray(rows, dtype=np.int64)]
            rows = np.asarray(rows, dtype=np.int64)
            uniq, inverse = np.unique(rows, return_inverse=True)
            return ds[uniq][inverse]

    @property
    def observations(self) -> np.ndarray:
        return self.read("observations")

    @property
    def actions(self) -> np.ndarray:
        return self.read("actions")

    @property
    def rewards(self) -> np.ndarray | None:
        return self.read("rewards") if self.has_rewards else None

    @cached_property
    def episode_starts(self) -> np.ndarray:
        return self.read("episode_starts")

    @property
    def timesteps(self) -> np.ndarray:
        return self.read("timesteps")

    def episode_of(self, rows) -> np.ndarray:
        """(R,) episode index of each row."""
        return np.searchsorted(self.episode_starts, np.asarray(rows), side="right") - 1

    def episode_returns(self) -> np.ndarray | None:
        """(E,) undiscounted return of each episode (None when reward-free)."""
        if not self.has_rewards:
            return None
        return np.add.reduceat(self.rewards, self.episode_starts[:-1]) if self.n_rows else None

    def tag(self, name: str) -> tuple[np.ndarray, list[str]]:
        """(codes (N,) int32, labels) of a tag column."""
        if name not in self.manifest["tags"]:
            known = ", ".join(self.manifest["tags"]) or "none"
            raise AocError(f"corpus {self.name!r} has no tag {name!r} (tags: {known})")
        return self.read(f"tags/{name}"), list(self.manifest["tags"][name])

    def tag_labels_of(self, rows) -> dict[str, list[str]]:
        """For each tag, the label of each of ``rows``."""
        out = {}
        for name, labels in self.manifest["tags"].items():
            codes = self.read(f"tags/{name}", rows)
            out[name] = [labels[c] for c in codes]
        return out

    def column(self, name: str) -> np.ndarray:
        if name not in self.manifest["columns"]:
            known = ", ".join(self.manifest["columns"]) or "none"
            raise AocError(f"corpus {self.name!r} has no numeric column {name!r} "
                           f"(columns: {known})")
        return self.read(f"columns/{name}")

    def history(self, rows, length: int) -> History:
        """The previous ``length`` transitions of each of ``rows`` in its own episode."""
        if length < 0:
            raise AocError(f"history length must be >= 0, got {length}")
        rows = np.asarray(rows, dtype=np.int64)
        starts = self.episode_starts[self.episode_of(rows)]
        return gather_history(rows, starts, length, self.observations, self.actions,
                              self.rewards)

    def load(self) -> CorpusData:
        """The whole corpus in memory."""
        with self._h5() as f:
            ids = [s.decode() if isinstance(s, bytes) else str(s)
                   for s in f["episode_ids"][()]] if "episode_ids" in f else None
            source = json.loads(f.attrs.get("source", "{}"))
        return CorpusData(
            observations=self.observations,
            actions=self.actions,
            rewards=self.rewards,
            terminals=self.read("terminals"),
            truncations=self.read("truncations"),
            episode_starts=self.episode_starts,
            observation_space=self.observation_space,
            action_space=self.action_space,
            tags={k: self.tag(k) for k in self.manifest["tags"]},
            columns={k: self.column(k) for k in self.manifest["columns"]},
            episode_ids=ids,
            source=source,
        )
