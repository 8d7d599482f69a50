"""Export benchmark (issue 23): a 1M-row corpus (17-d float32 observations, 6-d actions,
rewards, two tags, one numeric column, 1000-step episodes with ids) written out by
``aoc export``.

    .venv/bin/python benchmarks/perf/export.py [--rows 1000000] [--repeats 5] [--other-rows 100000]

Goal: >= 1M rows/s to D4RL HDF5 on the 1M-row corpus. Reported: the median of ``--repeats``
runs of the library call (``aoc_cli.formats.export``) and of the command (``aoc export`` in a
fresh process, its start and imports included), each run's time, and the rows a second; then,
on ``--other-rows`` rows (Minari and CSV write row by row through Python: minari's writer per
episode, the csv module per line), the same for Minari and CSV, and the read back
(``aoc ingest``) of each export with its content hash checked against the corpus's.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def corpus_data(rows: int, d_o: int = 17, d_a: int = 6, episode: int = 1000, seed: int = 0):
    """Random-walk observations within episodes, uniform actions, normal rewards; every other
    episode terminal, the rest truncated; tags ``policy`` (4 labels) and ``site`` (2)."""
    from aoc_cli.store import CorpusData, box_space, episode_starts_from_lengths

    rng = np.random.default_rng(seed)
    obs = np.cumsum(rng.standard_normal((rows, d_o)).astype(np.float32) * 0.05, axis=0,
                    dtype=np.float32)
    lengths = np.full(rows // episode, episode)
    if rows % episode:
        lengths = np.append(lengths, rows % episode)
    starts = episode_starts_from_lengths(lengths)
    ends = starts[1:] - 1
    terminals = np.zeros(rows, bool)
    truncations = np.zeros(rows, bool)
    terminals[ends[0::2]] = True
    truncations[ends[1::2]] = True
    ep_policy = rng.integers(0, 4, len(lengths)).astype(np.int32)
    return CorpusData(
        observations=obs, actions=rng.uniform(-1, 1, (rows, d_a)).astype(np.float32),
        rewards=rng.standard_normal(rows), terminals=terminals, truncations=truncations,
        episode_starts=starts, observation_space=box_space(d_o),
        action_space=box_space(d_a, -1.0, 1.0),
        tags={"policy": (np.repeat(ep_policy, lengths), ["pi1", "pi2", "pi3", "pi4"]),
              "site": (rng.integers(0, 2, rows).astype(np.int32), ["north", "east"])},
        columns={"score": rng.standard_normal(rows)},
        episode_ids=[f"e{i:05d}" for i in range(len(lengths))], source={"kind": "benchmark"})


def time_library(store, name: str, fmt: str, out: Path, repeats: int) -> list[float]:
    from aoc_cli.formats import export

    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        export(name, fmt, out, store=store, overwrite=True)
        times.append(time.perf_counter() - t)
    return times


def time_cli(store_root: Path, name: str, fmt: str, out: Path, repeats: int) -> list[float]:
    exe = [sys.executable, "-c", "from aoc_cli.cli.app import main; main()"]
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        subprocess.run(exe + ["--store", str(store_root), "export", name, "--to", fmt, "--out",
                              str(out), "--overwrite", "-f", "json"],
                       check=True, capture_output=True)
        times.append(time.perf_counter() - t)
    return times


def read_back(store, name: str, out: Path) -> tuple[float, bool]:
    """Seconds to ingest ``out`` and whether its content hash is the corpus's."""
    from aoc_cli.formats import ingest

    t = time.perf_counter()
    ingest(out, f"{name}-back", store=store, overwrite=True)
    seconds = time.perf_counter() - t
    return seconds, store.corpus(f"{name}-back").hash == store.corpus(name).hash


def report(label: str, rows: int, times: list[float]) -> None:
    med = statistics.median(times)
    print(f"{label}: median {med:.3f} s ({rows / med / 1e6:.2f}M rows/s); runs "
          + ", ".join(f"{t:.3f}" for t in times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--other-rows", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--dir", type=Path, default=None,
                        help="Working folder (default: a temporary one, removed after).")
    args = parser.parse_args()
    from aoc_cli.store import Store

    work = Path(args.dir or tempfile.mkdtemp(prefix="aoc-export-bench-"))
    try:
        store = Store(work / "store")
        store.write("big", corpus_data(args.rows), overwrite=True)
        store.write("small", corpus_data(args.other_rows, seed=1), overwrite=True)
        out = work / "out"
        print(f"corpus: {args.rows} rows, 17-d observations, 6-d actions, 2 tags, 1 column")
        report("d4rl, library", args.rows,
               time_library(store, "big", "d4rl", out / "big.hdf5", args.repeats))
        report("d4rl, aoc export (process)", args.rows,
               time_cli(store.root, "big", "d4rl", out / "big.hdf5", args.repeats))
        seconds, same = read_back(store, "big", out / "big.hdf5")
        print(f"d4rl, read back: {seconds:.3f} s, same content hash: {same}")
        paths = {"minari": out / "small-v0", "csv": out / "small.csv", "d4rl":
                 out / "small.hdf5"}
        for fmt, path in paths.items():
            report(f"{fmt}, library, {args.other_rows} rows", args.other_rows,
                   time_library(store, "small", fmt, path, max(1, args.repeats // 2)))
            seconds, same = read_back(store, "small", path)
            print(f"{fmt}, read back: {seconds:.3f} s, same content hash: {same}")
    finally:
        if args.dir is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    main()
