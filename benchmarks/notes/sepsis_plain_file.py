"""icu-sepsis from a user's plain file: a log of clinician episodes written as an NPZ with the
D4RL keys (no trace of the task), ingested, ``aoc train`` / ``aoc index`` with no flags, and
every live state decided once by the controller with the settings saved with the model; the
exact survival of that state policy (one linear solve over the package's tables), beside the
clinicians'. docs/notes/results-icu-sepsis.md, "From a user's plain file".

    python benchmarks/notes/sepsis_plain_file.py --episodes 10000 --seed 0 --store /tmp/x \
        [--threads 1] [--train-seed 0]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

import aoc_cli
from aoc_cli.envs import collect, sepsis_tables
from aoc_cli.experiments import state_policy


def plain_npz(data, path: Path) -> Path:
    """The log's D4RL keys only: observations, actions, rewards, terminals, timeouts."""
    ends = np.asarray(data.episode_starts, dtype=np.int64)[1:] - 1
    term = np.asarray(data.terminals, dtype=bool)
    terminals = np.zeros(data.n_rows, bool)
    timeouts = np.zeros(data.n_rows, bool)
    terminals[ends], timeouts[ends] = term[ends], ~term[ends]
    np.savez(path, observations=data.observations, actions=data.actions,
             rewards=data.rewards, terminals=terminals, timeouts=timeouts)
    return path


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--episodes", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--task", default="icu-sepsis")
    ap.add_argument("--store", required=True)
    ap.add_argument("--train-seed", type=int, default=0,
                    help="aoc train's --seed (the split, the weights' initialisation)")
    ap.add_argument("--threads", type=int, default=None,
                    help="aoc train's --threads (default: the cores)")
    args = ap.parse_args()
    root = Path(args.store)
    root.mkdir(parents=True, exist_ok=True)
    data, _ = collect(args.task, episodes=args.episodes, seed=args.seed)
    path = plain_npz(data, root.parent / f"{root.name}-log.npz")
    name = "mine"
    aoc_cli.ingest(str(path), name=name, store=root, overwrite=True)
    started = time.perf_counter()
    seen = {}

    def progress(done, total=None, label=None):  # each stage once on stderr, with its time
        if label and label.split(":")[0].split(" batch")[0] not in seen:
            seen[label.split(":")[0].split(" batch")[0]] = True
            print(f"{time.perf_counter() - started:8.1f} s  {label}", file=sys.stderr,
                  flush=True)

    trained = aoc_cli.train(name, store=root, overwrite=True, progress=progress,
                            threads=args.threads, seed=args.train_seed)
    train_seconds = time.perf_counter() - started
    aoc_cli.build_index(name, store=root)
    session = aoc_cli.open_session(name, store=root)
    t = sepsis_tables("terminate" if args.task.endswith("terminate") else "mean")
    policy = state_policy(session.controller.decide, t)
    print(json.dumps({
        "task": args.task, "episodes": args.episodes, "seed": args.seed,
        "train_seed": args.train_seed,
        "aoc": round(float(t.mdp.value(policy)), 4),
        "clinicians": round(float(t.mdp.value(t.clinicians)), 4),
        "decided": [(r["setting"], r["value"]) for r in trained.metrics["settings"]["decided"]],
        "controller": trained.metrics["controller"], "val_r2": trained.metrics.get("val_r2"),
        "train_seconds": round(train_seconds, 1)}))


if __name__ == "__main__":
    main()
