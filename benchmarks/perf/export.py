"""Export benchmark (issue 23): a 1M-row corpus (17-d float32 observations, 6-d actions,
rewards, two tags, one numeric column, 1000-step episodes with ids) written out by
``aoc export``.

    .venv/bin/python benchmarks/perf/export.py [--rows 1000000] [--repeats 5] [--other-rows 100000]

Goal: >= 1M rows/s to D4RL HDF5 on the 1M-row corpus. Reported: the median of ``--repeats``
runs of the library call (``aoc_cli.export``) and of the command (``aoc export`` in a
fresh process, its start and imports included), each run's time, and the rows a second; then,
on ``--other-rows`` rows (Minari and CSV write row by row through Python: minari's writer per
episode, the csv module per line), the same for Minari and CSV, and the read back
(``aoc_cli.ingest``) of each export with its content hash checked against the corpus's
(``read_back_s``, ``same_hash``).
"""

from __future__ import annotations

import shutil
import sys
import tempfile
from pathlib import Path

import _harness as h

h.omp_threads(1)

import numpy as np  # noqa: E402

import aoc_cli  # noqa: E402
from aoc_cli.store import (CorpusData, Store, box_space,  # noqa: E402
                           episode_starts_from_lengths)


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


def time_library(store, name: str, fmt: str, out: Path, repeats: int) -> h.Runs:
    return h.repeat(lambda _: aoc_cli.export(name, fmt, out, store=store, overwrite=True),
                    repeats)


def time_cli(store_root: Path, name: str, fmt: str, out: Path, repeats: int) -> h.Runs:
    return h.interleave({"cli": lambda _: h.aoc(
        ["export", name, "--to", fmt, "--out", str(out), "--overwrite", "-f", "json"],
        store=store_root)}, repeats)["cli"]


def read_back(store, name: str, out: Path) -> tuple[float, bool]:
    """Seconds to ingest ``out`` and whether its content hash is the corpus's."""
    _, seconds, _ = h.timed(lambda: aoc_cli.ingest(out, f"{name}-back", store=store,
                                                   overwrite=True))
    return seconds, store.corpus(f"{name}-back").hash == store.corpus(name).hash


def main() -> None:
    parser = h.parser(__doc__, repeats=5)
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--other-rows", type=int, default=100_000)
    parser.add_argument("--dir", type=Path, default=None,
                        help="Working folder (default: a temporary one, removed after).")
    args = parser.parse_args()
    work = Path(args.dir or tempfile.mkdtemp(prefix="aoc-export-bench-"))
    try:
        store = Store(work / "store")
        store.write("big", corpus_data(args.rows), overwrite=True)
        store.write("small", corpus_data(args.other_rows, seed=1), overwrite=True)
        out = work / "out"
        print(f"corpus: {args.rows} rows, 17-d observations, 6-d actions, 2 tags, 1 column",
              file=sys.stderr)
        rows = [h.row("d4rl, library", args.rows,
                      time_library(store, "big", "d4rl", out / "big.hdf5", args.repeats)),
                h.row("d4rl, aoc export (process)", args.rows,
                      time_cli(store.root, "big", "d4rl", out / "big.hdf5", args.repeats))]
        seconds, same = read_back(store, "big", out / "big.hdf5")
        rows[-1].update(read_back_s=seconds, same_hash=same)
        paths = {"minari": out / "small-v0", "csv": out / "small.csv", "d4rl":
                 out / "small.hdf5"}
        for fmt, path in paths.items():
            runs = time_library(store, "small", fmt, path, max(1, args.repeats // 2))
            seconds, same = read_back(store, "small", path)
            rows.append(h.row(f"{fmt}, library", args.other_rows, runs, read_back_s=seconds,
                              same_hash=same))
        h.emit(rows, args.format)
    finally:
        if args.dir is None:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
