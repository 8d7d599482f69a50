"""A corpus as one D4RL-style HDF5 file.

Datasets: ``observations`` (N, d_o) and ``actions`` (N, d_a), or (N,) int64 when discrete, in
the corpus's dtypes; ``rewards`` (N,) float64 (absent for a reward-free corpus, rather than
made-up zeros); ``terminals`` and ``timeouts`` (N,) bool, the corpus's terminal and
truncation flags (an episode that ends with neither is flagged a timeout, so that tools which
split episodes at ``terminals | timeouts`` see it end; the spec records which); ``infos/<tag>``
(N,) int32 tag codes, their labels in the attribute ``labels`` (JSON), as in the store;
``infos/<column>`` (N,) float64. ``metadata/aoc`` holds the export spec as JSON
(:mod:`aoc_cli.formats.spec`), ``metadata/episode_starts`` the (E + 1,) offsets.

Contiguous and uncompressed like the store's float columns: a 1M-row corpus is written at
disk speed (benchmarks/perf/export.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from aoc_cli.errors import AocError
from aoc_cli.progress import Progress
from aoc_cli.store import CorpusData, atomic_path

#: Top-level datasets the D4RL layout names; a tag or column is stored under ``infos/``.
STANDARD = ("observations", "actions", "rewards", "terminals", "timeouts")


def write_d4rl(data: CorpusData, spec: dict, out: Path,
               progress: Progress | None = None) -> list[Path]:
    """Write ``data`` (with its export ``spec``) to ``out`` atomically; returns [out]."""
    clash = sorted(set(data.tags) & set(data.columns))
    if clash:
        raise AocError(f"{clash[0]!r} is both a tag and a column of the corpus: both would be "
                       f"infos/{clash[0]}; export to CSV or Minari instead")
    timeouts = np.asarray(data.truncations, bool).copy()
    last = np.asarray(data.episode_starts[1:]) - 1
    timeouts[last[np.asarray(spec["unflagged_ends"], np.int64)]] = True
    steps = 5 + len(data.tags) + len(data.columns)
    done = 0

    def put(f, key, arr, **attrs):
        nonlocal done
        ds = f.create_dataset(key, data=np.ascontiguousarray(arr))
        for k, v in attrs.items():
            ds.attrs[k] = v
        done += 1
        if progress is not None:
            progress(done, steps, "writing D4RL HDF5")

    with atomic_path(out) as tmp:
        with h5py.File(tmp, "w") as f:
            put(f, "observations", data.observations)
            put(f, "actions", data.actions)
            if data.rewards is not None:
                put(f, "rewards", np.asarray(data.rewards, np.float64))
            put(f, "terminals", np.asarray(data.terminals, bool))
            put(f, "timeouts", timeouts)
            for key, (codes, labels) in data.tags.items():
                put(f, f"infos/{key}", np.asarray(codes, np.int32), labels=json.dumps(labels))
            for key, col in data.columns.items():
                put(f, f"infos/{key}", np.asarray(col, np.float64))
            f.create_dataset("metadata/episode_starts",
                             data=np.asarray(data.episode_starts, np.int64))
            f.create_dataset("metadata/aoc", data=json.dumps(spec),
                             dtype=h5py.string_dtype())
    return [out]
