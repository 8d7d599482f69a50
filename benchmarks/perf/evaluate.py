"""Evaluate benchmark (issue 14): held-out steps scored per second by `aoc evaluate`, the whole
process (interpreter start, imports, loading, beliefs, decompositions, baselines, metrics).

    .venv/bin/python benchmarks/perf/evaluate.py [--patients 10000] [--repeats 3] [--store DIR]

Goal: at least 2,000 steps a second on a 100k-row corpus. Reported per case: steps per wall
second of the whole process, and steps per CPU second (user + system time of the process:
what the wall figure would be on an idle core, since evaluate runs one thread). Builds (once, in ``--store``) a ward
corpus of ``--patients`` stays (about 10 rows each), an imitation model (``--paper``, 4 epochs:
the speed does not depend on how well it is trained) with its index, and a value model on the
``outcome`` column; a held-out ward log of a tenth as many patients. Then times, ``--repeats``
times each (median reported, and every run), in one process per run:

* ``imitation, held out``: ``aoc evaluate ward100k --data held`` (knn and bc baselines);
* ``imitation, own``: ``aoc evaluate ward100k --data ward100k`` (every corpus step, its own
  episode left out), baselines on;
* ``imitation, own, exact``: the same with ``--exact`` (the index's exact search);
* ``value, held out``: ``aoc evaluate ward100k --model value --data held`` (the logged action's
  v_hat and the controller's choice over the 2 actions: 3 decompositions a step);
* ``held-per-action``, ``own-per-action``: the imitation cases with the nearest rows of each
  action (an index built with ``--candidates per_action``, the default up to 20,000 rows).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
AOC = [sys.executable, "-c", "from aoc_cli.cli.app import main; main()"]


def aoc(store: Path, *args: str) -> tuple[float, str, float]:
    """(wall seconds, stdout, CPU seconds (user + system) of the child process)."""
    env = {**os.environ, "AOC_STORE": str(store), "OMP_NUM_THREADS": "1",
           "PYTHONPATH": str(ROOT)}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    proc = subprocess.run([*AOC, *args], capture_output=True, text=True, env=env)
    seconds = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if proc.returncode != 0:
        raise SystemExit(f"aoc {' '.join(args)} failed: {proc.stderr.strip()}")
    return seconds, proc.stdout, cpu


def build(store: Path, patients: int) -> None:
    per_action = store / "ward100k" / "models" / "default" / "index" / "per-action"
    if (store / "ward100k" / "models" / "value" / "index").is_dir():
        if not per_action.is_dir():  # a store built before the candidates of every action
            aoc(store, "index", "ward100k", "--index", "per-action", "--candidates",
                "per_action", "-f", "json")
        return
    aoc(store, "collect", "ward", "--name", "ward100k", "--episodes", str(patients),
        "--overwrite", "-f", "json")
    aoc(store, "collect", "ward", "--name", "held", "--episodes", str(patients // 10),
        "--seed", "1", "--overwrite", "-f", "json")
    for model, extra in (("default", ["--mode", "imitation"]),
                         ("value", ["--value", "outcome"])):
        aoc(store, "train", "ward100k", "--model", model, *extra, "--paper", "--epochs", "4",
            "--threads", "1", "--overwrite", "-f", "json")
        aoc(store, "index", "ward100k", "--model", model, "-f", "json")
    aoc(store, "index", "ward100k", "--index", "per-action", "--candidates", "per_action",
        "-f", "json")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--patients", type=int, default=10_000)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--store", type=Path, default=ROOT / "bench" / "evaluate-store")
    ap.add_argument("--cases", default="held,own,value,exact",
                    help="comma-separated: held, own, exact, value, held-per-action, "
                         "own-per-action "
                         "(run interleaved, each --repeats times)")
    args = ap.parse_args()
    args.store.mkdir(parents=True, exist_ok=True)
    build(args.store, args.patients)
    known = {
        "held": ("imitation, held out", ["evaluate", "ward100k", "--data", "held"]),
        "own": ("imitation, own", ["evaluate", "ward100k", "--data", "ward100k"]),
        "value": ("value, held out", ["evaluate", "ward100k", "--model", "value", "--data",
                                      "held"]),
        "exact": ("imitation, own, exact", ["evaluate", "ward100k", "--data", "ward100k",
                                            "--exact"]),
        # the nearest rows of each action (the default up to 20,000 rows) instead of the
        # (d_b + 1) / the rarest share nearest rows (the default above)
        "held-per-action": ("imitation, held out, per action",
                            ["evaluate", "ward100k", "--data", "held", "--index", "per-action"]),
        "own-per-action": ("imitation, own, per action",
                           ["evaluate", "ward100k", "--data", "ward100k", "--index",
                            "per-action"]),
    }
    cases = dict(known[c.strip()] for c in args.cases.split(","))
    with open("/proc/loadavg") as fh:
        print(f"load before: {fh.read().split()[:3]}")
    results = {name: [] for name in cases}
    for _ in range(args.repeats):  # the cases interleaved, so a load change hits them alike
        for name, argv in cases.items():
            seconds, out, cpu = aoc(args.store, *argv, "-f", "json")
            summary = json.loads(out)
            results[name].append((seconds, summary["steps"], summary["seconds"], cpu,
                                  summary.get("accuracy"), summary.get("auc")))
    for name, runs in results.items():
        whole = statistics.median(r[1] / r[0] for r in runs)
        per_cpu = statistics.median(r[1] / r[3] for r in runs)
        inner = statistics.median(r[1] / r[2] for r in runs)
        print(f"{name}: {runs[0][1]} steps; whole process {whole:.0f} steps/s wall (runs "
              + ", ".join(f"{r[0]:.1f} s" for r in runs) + f"), {per_cpu:.0f} steps per CPU "
              "second (runs " + ", ".join(f"{r[3]:.1f}" for r in runs)
              + f"); inside evaluate() {inner:.0f} steps/s wall"
              + ("" if runs[0][4] is None else
                 f"; accuracy {runs[0][4]:.4f}, AUC {runs[0][5]:.4f}"), flush=True)
    with open("/proc/loadavg") as fh:
        print(f"load after: {fh.read().split()[:3]}")


if __name__ == "__main__":
    main()
