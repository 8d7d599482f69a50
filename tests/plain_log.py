"""A collected log written as a user's plain file: an NPZ with the D4RL keys only
(``observations``, ``actions``, ``rewards`` where the log has them, ``terminals``,
``timeouts``), no task, no tags, no episode ids, then ingested under another name. What
``aoc train`` decides for it can come only from the log's own evidence."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from tests.conftest import run_aoc


def write_plain_npz(data, path: Path) -> Path:
    """``data`` (a CorpusData or a stored corpus) as a plain NPZ at ``path``."""
    n = int(data.n_rows)
    ends = np.asarray(data.episode_starts, dtype=np.int64)[1:] - 1
    terminals = np.zeros(n, bool)
    timeouts = np.zeros(n, bool)
    term = np.asarray(data.terminals, dtype=bool)
    terminals[ends] = term[ends]
    timeouts[ends] = ~term[ends]
    arrays = {"observations": np.asarray(data.observations),
              "actions": np.asarray(data.actions), "terminals": terminals,
              "timeouts": timeouts}
    if data.rewards is not None:
        arrays["rewards"] = np.asarray(data.rewards, dtype=np.float64)
    np.savez(path, **arrays)
    return path


def ingest_plain(data, root: Path, name: str = "mine") -> dict:
    """Write ``data`` as a plain NPZ beside the store ``root`` and ``aoc ingest`` it as
    ``name``; the environment to run ``aoc`` with (``AOC_STORE`` set)."""
    env = {**os.environ, "AOC_STORE": str(root), "OMP_NUM_THREADS": "1"}
    path = write_plain_npz(data, Path(root).parent / f"{name}.npz")
    code, _out, err = run_aoc("ingest", str(path), "--name", name, "--format", "json", env=env)
    assert code == 0, err
    return env
