"""Ingest benchmark (issue 2): a generated 1M-row D4RL-style file (17-d observations, 6-d
actions) into the store, and history lookups for 100k random rows.

    .venv/bin/python benchmarks/perf/ingest.py [--rows 1000000] [--repeats 5] [--compare-compression]

Goal: >= 1M rows/s for ingest; < 1 s for the histories (L = 4) of 100k random rows.
The generated data are smooth random walks within 1000-step episodes (like logged control
trajectories: consecutive observations are close), actions uniform in [-1, 1], rewards normal;
an episode ends every 1000 rows, alternately by a terminal and a timeout. The source file is
written uncompressed (as a file straight from a simulator's logger would be). Reported: the
median of ``--repeats`` runs, and each run's time.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np


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
                float_opts: dict | None = None) -> list[float]:
    """Seconds to ingest ``src``; with ``float_opts``, to read it and write it with those
    dataset options for the float columns (Store.write's ``float_opts``)."""
    from aoc_cli.formats import ingest
    from aoc_cli.formats.ingest import read_dataset
    from aoc_cli.store import Store

    store = Store(store_root)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        if float_opts is None:
            ingest(src, "bench", store=store, overwrite=True)
        else:
            store.write("bench", read_dataset(src, None, None), overwrite=True,
                        float_opts=float_opts)
        times.append(time.perf_counter() - t)
    return times


def time_cli(src: Path, store_root: Path, repeats: int) -> list[float]:
    exe = [sys.executable, "-c", "from aoc_cli.cli.app import main; main()"]
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        subprocess.run(exe + ["--store", str(store_root), "ingest", str(src), "--name",
                              "bench-cli", "--overwrite", "-f", "json"],
                       check=True, capture_output=True)
        times.append(time.perf_counter() - t)
    return times


def time_history(store_root: Path, repeats: int, lookups: int = 100_000, length: int = 4):
    """(cold: open the corpus and look up, warm: a second lookup on the open corpus)."""
    from aoc_cli.store import Store

    rng = np.random.default_rng(1)
    cold, warm = [], []
    for _ in range(repeats):
        rows = rng.integers(0, Store(store_root).corpus("bench").n_rows, lookups)
        t = time.perf_counter()
        corpus = Store(store_root).corpus("bench")
        h = corpus.history(rows, length)
        cold.append(time.perf_counter() - t)
        rows = rng.integers(0, corpus.n_rows, lookups)
        t = time.perf_counter()
        h = corpus.history(rows, length)
        warm.append(time.perf_counter() - t)
        assert h.observations.shape == (lookups, length, corpus.observation_dim)
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
        times = time_ingest(src, root / label.replace(" ", "_"), repeats, float_opts=opts)
        size = (root / label.replace(" ", "_") / "bench" / "corpus.h5").stat().st_size
        cold, warm = time_history(root / label.replace(" ", "_"), repeats)
        out.append({"float columns": label, "ingest s": statistics.median(times),
                    "size MB": size / 1e6, "history cold s": statistics.median(cold),
                    "history warm s": statistics.median(warm)})
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rows", type=int, default=1_000_000)
    parser.add_argument("--repeats", type=int, default=5)
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
        times = time_ingest(src, tmp / "store", args.repeats)
        cli = time_cli(src, tmp / "store", max(3, args.repeats // 2))
        cold, warm = time_history(tmp / "store", args.repeats)
        med = statistics.median(times)
        print("| measure | median | runs |")
        print("| --- | --- | --- |")
        print(f"| ingest (library call), s | {med:.3f} ({args.rows / med / 1e6:.2f} M rows/s) | "
              + ", ".join(f"{t:.3f}" for t in times) + " |")
        med_cli = statistics.median(cli)
        print(f"| `aoc ingest` (whole process), s | {med_cli:.3f} "
              f"({args.rows / med_cli / 1e6:.2f} M rows/s) | "
              + ", ".join(f"{t:.3f}" for t in cli) + " |")
        print(f"| history of 100k random rows, L=4, cold (open corpus + lookup), s | "
              f"{statistics.median(cold):.3f} | " + ", ".join(f"{t:.3f}" for t in cold) + " |")
        print(f"| history of 100k random rows, L=4, warm, s | {statistics.median(warm):.3f} | "
              + ", ".join(f"{t:.3f}" for t in warm) + " |")
        if args.compare_compression:
            rows = compare_compression(src, tmp / "cmp", args.repeats)
            print()
            print("| float columns | ingest s | corpus.h5 MB | history cold s | history warm s |")
            print("| --- | --- | --- | --- | --- |")
            for r in rows:
                print(f"| {r['float columns']} | {r['ingest s']:.3f} | {r['size MB']:.0f} | "
                      f"{r['history cold s']:.3f} | {r['history warm s']:.3f} |")


if __name__ == "__main__":
    main()
