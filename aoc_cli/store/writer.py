"""Writing a corpus: validate, then build ``corpus.h5`` + ``manifest.json`` in a temporary
folder beside the corpus folder and rename it into place, under the corpus's writer lock.

The manifest records the content hash of the arrays (:func:`content_hash`), a CRC-32 of each of
them (``arrays``, so that a changed array is named), the size and CRC-32 of ``corpus.h5``
(``files``: damage found; the content hash is what identifies the data) and is sealed with
the SHA-256 of its own content, so ``aoc verify`` can tell a
changed byte anywhere.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import time
import zlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import h5py
import numpy as np

from aoc_cli.store.atomic import (array_bytes, array_checksum, atomic_dir, content_hash,
                                  file_record, seal, write_json)
from aoc_cli.store.columns import BLOCK_ROWS, ColumnStack
from aoc_cli.store.corpus import CorpusData, action_labels, episode_starts_from_lengths
from aoc_cli.store.layout import models_dir
from aoc_cli.store.lock import writing_corpus
from aoc_cli.store.reader import SCHEMA_VERSION, Corpus


def write_corpus(store, name: str, data: CorpusData, *, overwrite: bool = False,
                 append: bool = False, float_opts: dict | None = None) -> Corpus:
    """Validate and store ``data`` as corpus ``name`` of ``store`` (a
    :class:`aoc_cli.store.Store`; atomically, under its lock).

    ``append`` adds the episodes to an existing corpus with the same spaces (a missing one is
    created; ``aoc ingest`` warns); derived models are kept but become stale (their corpus
    hash no longer matches). A damaged corpus folder (no manifest) is replaced only with
    ``overwrite``. ``float_opts``: h5py dataset options of the float columns instead of
    :data:`FLOAT_OPTS` (benchmarks/perf/ingest.py compares compressions with it).
    """
    root = store.root
    data.validate()
    with writing_corpus(root, name):
        store.check_writable(name, overwrite=overwrite, append=append, notify=False)
        keep_models = None
        sources = [data.source]
        if append and store.exists(name):
            old = store.corpus(name)
            old.check_same_spaces(data)
            sources = old.manifest.get("sources", []) + [data.source]
            data = concat(old.load(), data)
            keep_models = old.models_dir
        Path(root).mkdir(parents=True, exist_ok=True)
        with atomic_dir(store.path(name)) as tmp:
            digest, crcs = _write_h5(tmp / "corpus.h5", data,
                                     FLOAT_OPTS if float_opts is None else float_opts)
            arrays = {key: crcs[key] if key in crcs else array_checksum(arr)
                      for key, arr in hashed_arrays(data).items()}
            if keep_models is not None and keep_models.is_dir():
                shutil.copytree(keep_models, models_dir(tmp))
            files = {"corpus.h5": file_record(tmp / "corpus.h5", checksum="crc32")}
            write_json(tmp / "manifest.json",
                       _manifest(name, data, digest, sources, files, arrays))
        return store.corpus(name)


def concat(a: CorpusData, b: CorpusData) -> CorpusData:
    """Episodes of ``a`` then ``b`` (same spaces); tags merged by label, and labelled discrete
    actions likewise (``a``'s codes kept, ``b``'s new labels numbered after them)."""
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
    actions_b, action_space = b.actions, a.action_space
    labels_a, labels_b = action_labels(a.action_space), action_labels(b.action_space)
    if labels_a is not None and labels_b is not None:  # labelled actions: a's codes kept
        labels = labels_a + [x for x in labels_b if x not in labels_a]
        actions_b = np.array([labels.index(x) for x in labels_b], np.int64)[b.actions]
        action_space = {**a.action_space, "n": len(labels), "names": labels}
    return CorpusData(
        observations=np.concatenate([a.observations, b.observations]).astype(obs_dtype),
        actions=np.concatenate([a.actions, actions_b]),
        rewards=None if a.rewards is None else np.concatenate([a.rewards, b.rewards]),
        terminals=np.concatenate([a.terminals, b.terminals]),
        truncations=np.concatenate([a.truncations, b.truncations]),
        episode_starts=episode_starts_from_lengths(
            np.concatenate([np.diff(a.episode_starts), np.diff(b.episode_starts)])),
        observation_space=a.observation_space,
        action_space=action_space,
        tags=tags,
        columns=columns,
        episode_ids=ids,
        source=b.source,
        imputed=None if a.imputed is None and b.imputed is None else np.concatenate(
            [np.zeros(x.observations.shape, bool) if x.imputed is None else x.imputed
             for x in (a, b)]),
        preprocessing=a.preprocessing,
    )


#: Float columns (observations, actions, rewards, numeric columns) are stored contiguous and
#: uncompressed: measured on 1M random-walk rows (benchmarks/perf/ingest.py, docs/notes/benchmarks-rounds.md),
#: gzip-1 + shuffle saved 25% of the bytes for 20x the write time and lzf 2%, and a contiguous
#: uncompressed dataset can be memory-mapped (:meth:`Corpus.read` of large columns).
#: Flags, step counters and tag codes compress 50-100x cheaply: gzip-1 + shuffle, chunked.
#: (Constants: a different setting is passed to :func:`write_corpus`, never patched here.)
FLOAT_OPTS: dict = {}
SMALL_OPTS: dict = dict(compression="gzip", compression_opts=1, shuffle=True)
CHUNK_ROWS = 1 << 16


def _write_h5(path: Path, data: CorpusData, float_opts: dict) -> tuple[str, dict]:
    """Write the arrays (float columns with ``float_opts``: contiguous when empty; the rest
    chunked gzip-1 + shuffle) and return their content hash and the CRC-32s (hex) of the
    observations and the imputed mask, summed as they were written.

    The observations are written, SHA-256-hashed and CRC-32-summed in one pass, block by block
    while each block is in the CPU's cache (a :class:`ColumnStack` is only ever made into rows
    so: never the whole (N, d_o) matrix beside its columns; :func:`_write_rows`)."""

    def put(f, key, arr):
        arr = np.ascontiguousarray(arr)
        if np.issubdtype(arr.dtype, np.floating) and not float_opts:
            f.create_dataset(key, data=arr)
            return
        opts = float_opts if np.issubdtype(arr.dtype, np.floating) else SMALL_OPTS
        chunks = (max(1, min(len(arr), CHUNK_ROWS)),) + arr.shape[1:]
        f.create_dataset(key, data=arr, chunks=chunks, **opts)

    timesteps = data.timesteps()
    sha = hashlib.sha256()
    with h5py.File(path, "w") as f:
        obs = data.observations
        if float_opts:  # a benchmark's comparison of compressions: the plain array
            obs = np.asarray(obs)
            put(f, "observations", obs)
        ds = f.create_dataset("observations", shape=obs.shape, dtype=obs.dtype) \
            if not float_opts else None
        crcs = {"observations": f"{_write_rows(ds, obs, sha):08x}"}
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
        if data.imputed is not None:  # contiguous: gzip of the (N, d_o) mask cost ~0.4 s
            ds = f.create_dataset("imputed", shape=data.imputed.shape, dtype=bool)  # per 230k
            crcs["imputed"] = f"{_write_rows(ds, data.imputed):08x}"  # rows
        if data.episode_ids is not None:
            f.create_dataset("episode_ids", data=np.array(data.episode_ids, dtype=object),
                             dtype=h5py.string_dtype())
        f.attrs["schema_version"] = SCHEMA_VERSION
        f.attrs["observation_space"] = json.dumps(data.observation_space)
        f.attrs["action_space"] = json.dumps(data.action_space)
        f.attrs["source"] = json.dumps(data.source)
    digest = content_hash(None, data.actions, data.rewards, data.terminals,
                          data.truncations, data.episode_starts,
                          {k: c for k, (c, _labels) in data.tags.items()}, data.columns,
                          hasher=sha)
    return digest, crcs


def _write_rows(ds, obs, sha=None) -> int:
    """Write ``obs`` (an array or a :class:`ColumnStack`) into dataset ``ds`` (None: only
    hash) block by block, feeding ``sha`` (when given) its :func:`array_bytes`; return their
    CRC-32.

    The hashing of each block runs in one worker thread while the next block is made and
    written (hashlib and zlib let go of the GIL on large buffers), in order: two buffers
    alternate, a buffer reused only once its hashing is done."""
    header = next(array_bytes(obs))
    if sha is not None:
        sha.update(header)
    crc = [zlib.crc32(header)]

    def digest(view) -> None:
        if sha is not None:
            sha.update(view)
        crc[0] = zlib.crc32(view, crc[0])

    stack = obs if isinstance(obs, ColumnStack) else None
    arr = None if stack is not None else np.ascontiguousarray(obs)
    n, size = len(obs), BLOCK_ROWS if stack is not None else 1 << 16
    buffers = [np.empty((min(size, n), obs.shape[1]), obs.dtype) for _ in range(2)] \
        if stack is not None else [None, None]
    pending: list = [None, None]
    with ThreadPoolExecutor(max_workers=1) as pool:
        for k, start in enumerate(range(0, n, size)):
            stop = min(start + size, n)
            if pending[k % 2] is not None:
                pending[k % 2].result()  # its buffer hashed: free to refill
            block = stack.rows(start, stop, buffers[k % 2]) if stack is not None \
                else arr[start:stop]
            if ds is not None:
                ds.write_direct(block, dest_sel=np.s_[start:stop])
            pending[k % 2] = pool.submit(digest, memoryview(block).cast("B"))
        for job in pending:
            if job is not None:
                job.result()
    return crc[0]


def hashed_arrays(data: CorpusData) -> dict[str, np.ndarray]:
    """The arrays the content hash covers, by their key in corpus.h5 (what ``arrays`` of the
    manifest records a checksum of)."""
    out = {"observations": data.observations, "actions": data.actions}
    if data.rewards is not None:
        out["rewards"] = data.rewards
    out.update(terminals=data.terminals, truncations=data.truncations,
               episode_starts=data.episode_starts)
    out.update({f"tags/{k}": c for k, (c, _labels) in sorted(data.tags.items())})
    out.update({f"columns/{k}": data.columns[k] for k in sorted(data.columns)})
    if data.imputed is not None:
        out["imputed"] = data.imputed
    return out


def _manifest(name: str, data: CorpusData, digest: str, sources: list[dict],
              files: dict, arrays: dict) -> dict:
    return seal({
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
        "arrays": arrays,
        "sources": sources,
        "files": files,
        "imputed": data.imputed is not None,
        "preprocessing": data.preprocessing,
    })


