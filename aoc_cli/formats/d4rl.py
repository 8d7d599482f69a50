"""D4RL-style HDF5: one flat file, ``observations (N, d_o)``, ``actions (N, d_a)``,
``rewards (N,)``, ``terminals (N,)``, ``timeouts (N,)``; optional ``next_observations``
(not needed: the next observation is the next row of the episode), ``infos/*``, ``metadata/*``.

Episodes end at ``terminals | timeouts``; a trailing episode with neither is kept, marked
truncated; timeouts become truncations. 1-d numeric ``infos/<key>`` arrays become corpus
columns ``<key>``; ``--tag-column KEY`` takes a top-level or ``infos/`` array as a tag.

A file written by ``aoc export --to d4rl`` (:mod:`aoc_cli.formats.export_d4rl`) also holds
``metadata/aoc`` and ``metadata/episode_starts``: it is read back as the corpus that was
exported (:func:`aoc_cli.formats.spec.restore`).
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from aoc_cli.errors import AocError, param
from aoc_cli.formats.common import ReadOptions, encode_labels, from_flat, open_h5
from aoc_cli.formats.spec import parse_spec, restore
from aoc_cli.store import CorpusData

STANDARD = ("observations", "actions", "rewards", "terminals", "timeouts", "next_observations")


def read_d4rl(path: Path, options: ReadOptions) -> CorpusData:
    """Read a D4RL-style HDF5 file."""
    with open_h5(path) as f:
        missing = [k for k in ("observations", "actions")
                   if not isinstance(f.get(k), h5py.Dataset)]
        if missing:
            raise AocError(f"{path} is not a D4RL-style file: it has no {', '.join(missing)} "
                           f"(top-level keys: {', '.join(sorted(f.keys())) or 'none'})")
        if isinstance(f.get("metadata/aoc"), h5py.Dataset):
            return _read_exported(f, path, options)
        get = {k: (f[k][()] if isinstance(f.get(k), h5py.Dataset) else None)
               for k in ("observations", "actions", "rewards", "terminals", "timeouts")}
        n = len(get["observations"])
        extra = {}
        infos = f.get("infos")
        if isinstance(infos, h5py.Group):
            for key, ds in infos.items():
                if isinstance(ds, h5py.Dataset) and (
                        key in options.tag_columns or
                        (ds.ndim == 1 and ds.dtype.kind in "fiub" and len(ds) == n)):
                    extra[key] = ds[()]
        for key in options.tag_columns:
            if key not in extra and key not in STANDARD and isinstance(f.get(key), h5py.Dataset):
                extra[key] = f[key][()]
        attrs = {k: _plain(v) for k, v in f.attrs.items()}
    source = {"format": "d4rl", "path": str(Path(path).resolve())}
    if attrs:
        source["attrs"] = attrs
    return from_flat(get["observations"], get["actions"], get["rewards"], get["terminals"],
                     get["timeouts"], source, options, extra=extra)


def _read_exported(f: h5py.File, path: Path, options: ReadOptions) -> CorpusData:
    """A file of ``aoc export --to d4rl``: the arrays as written, episodes from
    ``metadata/episode_starts``, tags and columns from ``infos/`` as the spec lists them."""
    spec = parse_spec(f["metadata/aoc"][()], path)
    starts = f.get("metadata/episode_starts")
    if not isinstance(starts, h5py.Dataset):
        raise AocError(f"{path}: metadata/aoc without metadata/episode_starts; re-export it")
    get = {k: (f[k][()] if isinstance(f.get(k), h5py.Dataset) else None)
           for k in ("observations", "actions", "rewards", "terminals", "timeouts")}
    n = len(get["observations"])
    tags = {}
    for key in list(spec["tags"]) + list(options.tag_columns):
        if not isinstance(f.get(f"infos/{key}"), h5py.Dataset):
            raise AocError(f"{path}: no infos/{key} (a tag of the export metadata or "
                           f"{param('tag_columns')}); re-export it")
        if key in spec["tags"]:
            tags[key] = (f[f"infos/{key}"][()], spec["tags"][key])
        else:
            tags[key] = encode_labels(f[f"infos/{key}"][()])
    columns = {}
    for key in spec["columns"]:
        if not isinstance(f.get(f"infos/{key}"), h5py.Dataset):
            raise AocError(f"{path}: no infos/{key} (a column of the export metadata); "
                           "re-export it")
        columns[key] = f[f"infos/{key}"][()]
    missing = [k for k in ("terminals", "timeouts") if get[k] is None]
    if missing:
        raise AocError(f"{path}: no {', '.join(missing)} beside metadata/aoc; re-export it")
    data = CorpusData(
        observations=get["observations"], actions=get["actions"], rewards=get["rewards"],
        terminals=np.asarray(get["terminals"], bool).reshape(n),
        truncations=np.asarray(get["timeouts"], bool).reshape(n),
        episode_starts=starts[()], observation_space=spec["observation_space"],
        action_space=spec["action_space"], tags=tags, columns=columns,
        source={"format": "d4rl", "path": str(Path(path).resolve())})
    return restore(data, spec, path)


def _plain(value):
    """An HDF5 attribute as JSON-able Python."""
    if isinstance(value, bytes):
        return value.decode("utf-8", "replace")
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value if isinstance(value, (str, int, float, bool, list)) else str(value)
