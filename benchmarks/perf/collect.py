"""Collect benchmark (issue 3): rows per second of each built-in task's behaviour mix, and the
whole `aoc collect` (collect + store write) for pendulum-het.

    .venv/bin/python benchmarks/perf/collect.py [--repeats 5] [--pendulum-rows 100000]
                                           [--lunar-rows 20000]

Goal: 100k pendulum-het rows in <= 30 s on this machine. pendulum-het is stepped for all of its
episodes at once with numpy (the same equations as gymnasium's Pendulum, bit for bit); lunar
steps gymnasium's Box2D LunarLanderContinuous one episode at a time with the heuristic lander;
maze and two-gates run their default episode counts vectorised. Reported: the median of
``--repeats`` runs (seed = run index) and each run's time.
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

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

from aoc_cli.envs import collect  # noqa: E402


def time_collect(task: str, repeats: int, **budget) -> tuple[list[float], int]:
    times, rows = [], 0
    for seed in range(repeats):
        t0 = time.perf_counter()
        data, _ = collect(task, seed=seed, **budget)
        times.append(time.perf_counter() - t0)
        rows = data.n_rows
    return times, rows


def time_cli(rows: int, repeats: int) -> list[float]:
    """The real `aoc collect pendulum-het` in a subprocess (imports, collect, HDF5 write)."""
    times = []
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, AOC_STORE=tmp)
        for seed in range(repeats):
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-c",
                            "from aoc_cli.cli.app import main; main()", "collect",
                            "pendulum-het", "--steps", str(rows), "--name", f"p{seed}",
                            "--seed", str(seed), "--format", "json"],
                           check=True, env=env, capture_output=True, cwd=ROOT)
            times.append(time.perf_counter() - t0)
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--pendulum-rows", type=int, default=100_000)
    ap.add_argument("--lunar-rows", type=int, default=20_000)
    args = ap.parse_args()
    cases = [("pendulum-het", {"steps": args.pendulum_rows}),
             ("pendulum-het-upright", {"steps": args.pendulum_rows}),
             ("maze", {"episodes": 1000}),
             ("two-gates", {"episodes": 500}),
             ("lunar", {"steps": args.lunar_rows})]
    print(f"{'task':22s} {'rows':>8s} {'median s':>9s} {'rows/s':>10s}  runs (s)")
    for task, budget in cases:
        times, rows = time_collect(task, args.repeats, **budget)
        med = statistics.median(times)
        print(f"{task:22s} {rows:8d} {med:9.3f} {rows / med:10.0f}  "
              + " ".join(f"{t:.3f}" for t in times), flush=True)
    times = time_cli(args.pendulum_rows, args.repeats)
    med = statistics.median(times)
    print(f"{'aoc collect pendulum-het':22s} {args.pendulum_rows:8d} {med:9.3f} "
          f"{args.pendulum_rows / med:10.0f}  " + " ".join(f"{t:.3f}" for t in times))


if __name__ == "__main__":
    main()
