"""Ingest benchmark (issue 2): a generated 1M-row D4RL-style file (17-d observations, 6-d
actions) into the store, and history lookups for 100k random rows.

    .venv/bin/python benchmarks/perf/ingest.py [--rows 1000000] [--repeats 5] [--compare-compression]

Goal: >= 1M rows/s for ingest; < 1 s for the histories (L = 4) of 100k random rows.
The generated data are smooth random walks within 1000-step episodes (like logged control
trajectories: consecutive observations are close), actions uniform in [-1, 1], rewards normal;
an episode ends every 1000 rows, alternately by a terminal and a timeout. The source file is
written uncompressed (as a file straight from a simulator's logger would be). Rows: the
library call (``aoc_cli.ingest``), the command (``aoc ingest`` in a fresh process), the history
lookups cold (open the corpus + look up) and warm; the median of ``--repeats`` runs, and each
run's time.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import _harness as h
import h5py
import numpy as np

import aoc_cli
from aoc_cli.formats.ingest import read_dataset
from aoc_cli.store import Store


def generate(path: Path, rows: int, d_o: int = 17, d_a: int = 6, episode: int = 1000,
             seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    steps = rng.standard_normal((rows, d_o)).astype(np.float32) * 0.05
    starts = np.arange(0, rows, episode)
    steps[starts] = rng.standard_normal((len(starts), d_o)).astype(np.float32)
    obs = np.cumsum(steps, axis=0, dtype=np.float32)
    # restart the walk at every episode start
    offsets = np.repeat(obs[starts] - steps[starts], np.diff(np.append(starts, rows)), axis=0)
    obs -= offsets
    ends = np.minimum(starts + episode, rows) - 1
    terminals = np.zeros(rows, bool)
    timeouts = np.zeros(rows, bool)
    terminals[ends[0::2]] = True
    timeouts[ends[1::2]] = True
    with h5py.File(path, "w") as f:
        f["observations"] = obs
        f["actions"] = rng.uniform(-1, 1, (rows, d_a)).astype(np.float32)
        f["rewards"] = rng.standard_normal(rows).astype(np.float32)
        f["terminals"] = terminals
        f["timeouts"] = timeouts


def time_ingest(src: Path, store_root: Path, repeats: int,
                float_opts: dict | None = None) -> h.Runs:
    """Runs of ingesting ``src`` (the API entry); with ``float_opts``, of reading it and
    writing it with those dataset options for the float columns (Store.write's
    ``float_opts``, no API entry has them)."""
    store = Store(store_root)
    if float_opts is None:
        return h.repeat(lambda _: aoc_cli.ingest(src, "bench", store=store, overwrite=True),
                        repeats)
    return h.repeat(lambda _: store.write("bench", read_dataset(src, None, None),
                                          overwrite=True, float_opts=float_opts), repeats)


def time_history(store_root: Path, repeats: int, lookups: int = 100_000,
                 length: int = 4) -> tuple[h.Runs, h.Runs]:
    """(cold: open the corpus and look up, warm: a second lookup on the open corpus)."""
    rng = np.random.default_rng(1)
    cold, warm = h.Runs(), h.Runs()
    for _ in range(repeats):
        rows = rng.integers(0, Store(store_root).corpus("bench").n_rows, lookups)
        corpus, wall, cpu = h.timed(lambda: Store(store_root).corpus("bench"))
        hist, wall2, cpu2 = h.timed(lambda: corpus.history(rows, length))
        cold.add(wall + wall2, cpu + cpu2)
        rows = rng.integers(0, corpus.n_rows, lookups)
        hist, wall, cpu = h.timed(lambda: corpus.history(rows, length))
        warm.add(wall, cpu)
        assert hist.observations.shape == (lookups, length, corpus.observation_dim)
    return cold, warm


def compare_compression(src: Path, root: Path, repeats: int) -> list[dict]:
    settings = {
        "none (contiguous)": {},
        "lzf": dict(compression="lzf"),
        "lzf + shuffle": dict(compression="lzf", shuffle=True),
        "gzip-1": dict(compression="gzip", compression_opts=1),
        "gzip-1 + shuffle": dict(compression="gzip", compression_opts=1, shuffle=True),
    }
    out = []
    for label, opts in settings.items():
        folder = root / label.replace(" ", "_")
        runs = time_ingest(src, folder, repeats, float_opts=opts)
        cold, warm = time_history(folder, repeats)
        size = (folder / "bench" / "corpus.h5").stat().st_size
        out.append(h.row(f"float columns {label}", None, runs, size_mb=size / 1e6,
                         history_cold_s=cold.median, history_warm_s=warm.median))
    return out


def main() -> None:
    parser = h.parser(__doc__, repeats=5)
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--lookups", type=int, default=100_000, help="history lookups")
    parser.add_argument("--compare-compression", action="store_true")
    parser.add_argument("--workdir", type=Path, default=None,
                        help="where to write the file and store (default: a temporary folder)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(dir=args.workdir) as tmp:
        tmp = Path(tmp)
        src = tmp / "generated.hdf5"
        generate(src, args.rows)
        print(f"source: {args.rows} rows, {src.stat().st_size / 1e6:.0f} MB, "
              f"{os.cpu_count()} cores", file=sys.stderr)
        rows = [h.row("ingest (library call)", args.rows,
                      time_ingest(src, tmp / "store", args.repeats))]
        cli = h.interleave({"cli": lambda _: h.aoc(
            ["ingest", str(src), "--name", "bench-cli", "--overwrite", "-f", "json"],
            store=tmp / "store")}, max(3, args.repeats // 2))["cli"]
        rows.append(h.row("aoc ingest (whole process)", args.rows, cli))
        cold, warm = time_history(tmp / "store", args.repeats, args.lookups)
        rows.append(h.row(f"history of {args.lookups} random rows, L=4, cold (open corpus + "
                          "lookup)", args.lookups, cold, unit="lookups"))
        rows.append(h.row(f"history of {args.lookups} random rows, L=4, warm", args.lookups,
                          warm, unit="lookups"))
        if args.compare_compression:
            rows += compare_compression(src, tmp / "cmp", args.repeats)
        h.emit(rows, args.format)


if __name__ == "__main__":
    main()
