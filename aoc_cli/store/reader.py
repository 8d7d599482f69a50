"""Reading a stored corpus: the manifest (checked when opened), columns read lazily from
``corpus.h5`` (large contiguous ones memory-mapped), histories.

Opening checks what is cheap: the manifest parses, is intact (its seal) and holds every key,
and ``corpus.h5`` has the recorded size. Damage inside the arrays is found by
:meth:`Corpus.verify_content` (train and index call it on the columns they read anyway) and by
``aoc verify``. Every damage is one :class:`AocError` naming the file and pointing to
``aoc verify``.
"""

from __future__ import annotations

import contextlib
import json
from functools import cached_property
from pathlib import Path
from typing import Iterator

import h5py
import numpy as np

from aoc_cli.errors import AocError, Damaged, param
from aoc_cli.store.atomic import array_checksum, content_hash, seal_status
from aoc_cli.store.corpus import CorpusData, History, action_labels, gather_history
from aoc_cli.store.layout import models_dir

SCHEMA_VERSION = 1
#: Columns up to this many bytes are read into memory once; larger ones are sliced from disk.
IN_MEMORY_BYTES = 2 << 30
#: Manifest keys and their types: a manifest without one of them is damaged.
MANIFEST_KEYS = {"rows": int, "episodes": int, "observation_space": dict,
                 "action_space": dict, "has_rewards": bool, "tags": dict, "columns": list,
                 "content_hash": str}


def _first_line(err: Exception) -> str:
    text = str(err).strip()
    return text.splitlines()[0][:160] if text else type(err).__name__


def read_manifest(folder: Path) -> dict:
    """The manifest of a corpus folder; a missing, unparsable, changed or incomplete one is
    an AocError naming the file."""
    path = Path(folder) / "manifest.json"
    name = Path(folder).name
    try:
        manifest = json.loads(path.read_text())
    except FileNotFoundError:
        raise Damaged(name, f"{path} is missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise Damaged(name, f"{path} is not valid JSON "
                       f"({_first_line(err)})") from None
    if not isinstance(manifest, dict):
        raise Damaged(name, f"{path} is not a JSON object")
    bad = [k for k, t in MANIFEST_KEYS.items()
           if not isinstance(manifest.get(k), t) or (t is int and isinstance(manifest[k], bool))]
    if bad:
        raise Damaged(name, f"{path} lacks valid {', '.join(bad)}")
    if seal_status(manifest) is False:
        raise Damaged(name, f"{path} was changed after it was written "
                       f"(its sha256 does not match)")
    return manifest


def _memmap(ds: h5py.Dataset, path: Path) -> np.ndarray | None:
    """A read-only memory map of a contiguous, uncompressed dataset (None if it is not)."""
    offset = ds.id.get_offset()
    if ds.chunks is not None or ds.compression is not None or offset is None:
        return None
    return np.memmap(path, mode="r", dtype=ds.dtype, shape=ds.shape, offset=offset)




class Corpus:
    """A stored corpus, read lazily. Small columns are cached in memory on first use."""

    def __init__(self, path: Path):
        self.path = Path(path)
        self.name = self.path.name
        self.manifest = read_manifest(self.path)
        self._cache: dict[str, np.ndarray] = {}
        self._check_size()

    def damaged(self, what: str) -> AocError:
        """The error for a damaged corpus file: names it and what to do."""
        return Damaged(self.name, what)

    def _check_size(self) -> None:
        """The fast check of every open: corpus.h5 exists and has the size recorded."""
        path = self.path / "corpus.h5"
        try:
            size = path.stat().st_size
        except OSError:
            raise self.damaged(f"{path} is missing") from None
        recorded = (self.manifest.get("files") or {}).get("corpus.h5", {}).get("bytes")
        if recorded is not None and size != recorded:
            raise self.damaged(f"{path} has {size} bytes, the manifest records {recorded}")

    def verify_content(self) -> None:
        """Recompute the content hash from the columns (read anyway by train and index, and
        cached) and refuse a corpus whose data changed since it was written."""
        if self.content_hash() != self.hash:
            changed = self.changed_arrays()
            which = f" (changed: {', '.join(changed)})" if changed else ""
            raise self.damaged(f"its arrays no longer match the manifest's content hash{which}")

    def changed_arrays(self) -> list[str] | None:
        """The arrays of corpus.h5 whose checksum differs from the one the manifest records
        (``arrays``), or that cannot be read; None for a corpus written without them."""
        recorded = self.manifest.get("arrays")
        if not isinstance(recorded, dict):
            return None
        changed = []
        for key, crc in recorded.items():
            try:
                same = array_checksum(self.read(key)) == crc
            except Exception:  # noqa: BLE001 - an unreadable array is a changed one
                same = False
            if not same:
                changed.append(key)
        return changed

    def content_hash(self) -> str:
        """The content hash of the arrays as stored now (reads every hashed column)."""
        return content_hash(self.observations, self.actions, self.rewards,
                            self.read("terminals"), self.read("truncations"),
                            self.episode_starts,
                            {k: self.read(f"tags/{k}") for k in self.manifest["tags"]},
                            {k: self.read(f"columns/{k}") for k in self.manifest["columns"]})

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
        return models_dir(self.path)

    def check_same_spaces(self, data: CorpusData) -> None:
        def shape(space):  # labelled actions may differ in labels: appending merges them
            n = "labelled" if action_labels(space) is not None else space.get("n")
            return (space.get("type"), tuple(space.get("shape", ())), n)

        if shape(self.observation_space) != shape(data.observation_space) or \
                shape(self.action_space) != shape(data.action_space) or \
                self.has_rewards != (data.rewards is not None):
            raise AocError(
                f"cannot {param('append', True)} to {self.name!r}: its spaces are observation "
                f"{shape(self.observation_space)}, action {shape(self.action_space)}, rewards "
                f"{self.has_rewards}; the new data has observation "
                f"{shape(data.observation_space)}, action {shape(data.action_space)}, rewards "
                f"{data.rewards is not None}"
            )

    # -- arrays --------------------------------------------------------------------------
    @contextlib.contextmanager
    def _h5(self) -> Iterator[h5py.File]:
        """corpus.h5 open for reading; HDF5 errors (damaged metadata or chunks, a truncated
        file) become one AocError naming the file."""
        path = self.path / "corpus.h5"
        try:
            f = h5py.File(path, "r")
        except OSError as err:
            raise self.damaged(f"{path} is not a readable HDF5 file ({_first_line(err)})") \
                from None
        try:
            with f:
                yield f
        except (OSError, RuntimeError, KeyError, ValueError, TypeError) as err:
            raise self.damaged(f"reading {path} failed ({type(err).__name__}: "
                               f"{_first_line(err)})") from None

    def read(self, key: str, rows=None) -> np.ndarray:
        """A column (``observations``, ``actions``, ``rewards``, ``tags/<t>``, ``columns/<c>``,
        ...) for all rows or for ``rows`` (any order, repeats allowed)."""
        if key in self._cache:
            arr = self._cache[key]
            return arr if rows is None else arr[np.asarray(rows)]
        arr = self._read(key, rows)
        expect = self.n_episodes + 1 if key == "episode_starts" else self.n_rows
        if rows is None and len(arr) != expect:
            raise self.damaged(f"column {key!r} of {self.path / 'corpus.h5'} has {len(arr)} "
                               f"entries, the manifest records {expect}")
        return arr

    def _read(self, key: str, rows=None) -> np.ndarray:
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

    @property
    def imputed_mask(self) -> np.ndarray | None:
        """(N, d_o) bool, true where an observation cell was empty in the source and imputed
        (the rule and medians: :attr:`preprocessing`); None when nothing was imputed."""
        if not self.manifest.get("imputed"):
            return None
        return np.asarray(self.read("imputed"), dtype=bool)

    @property
    def preprocessing(self) -> dict:
        """What was fitted while reading the corpus: ``impute`` (rule, medians), ``bins``
        (dose-bin edges), ``split``; {} when none."""
        return dict(self.manifest.get("preprocessing") or {})

    @cached_property
    def episode_ids(self) -> list[str] | None:
        """The episodes' own ids (E,) (e.g. patient ids kept by a CSV ingest), or None."""
        with self._h5() as f:
            if "episode_ids" not in f:
                return None
            return [s.decode() if isinstance(s, bytes) else str(s)
                    for s in f["episode_ids"][()]]

    def load(self) -> CorpusData:
        """The whole corpus in memory."""
        with self._h5() as f:
            ids = [s.decode() if isinstance(s, bytes) else str(s)
                   for s in f["episode_ids"][()]] if "episode_ids" in f else None
            try:
                source = json.loads(f.attrs.get("source", "{}"))
            except json.JSONDecodeError:
                raise self.damaged(f"the source attribute of {self.path / 'corpus.h5'} is not "
                                   "JSON") from None
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
            imputed=self.imputed_mask,
            preprocessing=self.preprocessing,
        )
