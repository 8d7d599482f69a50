"""Benchmark: does a control step depend on OMP_WAIT_POLICY? (aoc_cli/threads.py)

OpenMP reads OMP_WAIT_POLICY once, when torch or FAISS load it, so the settings cannot share a
process: this script runs the same rollout of `Controller.decide` (pendulum-het, the task's
controller settings, seed 0) in fresh processes, alternating PASSIVE and unset round by round,
with OMP_NUM_THREADS=1 and unset, and prints the median step of each process, the 1-minute
load, and a checksum of the actions chosen (the same in every process: the same decisions).

Usage: .venv/bin/python benchmarks/notes/wait_policy.py --store STORE --corpus NAME [--model ID]
       [--steps 150] [--rounds 4]   (a store with a trained model and its index, e.g. the
       bench store of `aoc bench pendulum-het --quick`)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time


def child(store: str, corpus_name: str, model: str | None, steps: int) -> None:
    import numpy as np

    from aoc_cli.control import ControllerConfig, HistoryBuffer
    from aoc_cli.envs import make_env
    from aoc_cli.control import open_session
    from aoc_cli.store import Store

    corpus = Store(store).corpus(corpus_name)
    session = open_session(corpus, model, config=ControllerConfig.for_task("pendulum-het"),
                           seed=0)
    env = make_env("pendulum-het")
    obs, _ = env.reset(seed=0)
    buf = HistoryBuffer(session.model.history_length, obs.shape[0], 1, discrete=False)
    times, actions = [], []
    for _ in range(steps):
        t = time.perf_counter()
        d = session.controller.decide(obs, buf.history())
        times.append(time.perf_counter() - t)
        actions.append(float(d.action[0]))
        nxt, r, term, trunc, _ = env.step(np.asarray(d.action, np.float32))
        buf.push(obs, d.action, r)
        obs = nxt
        if term or trunc:
            buf.reset()
            obs, _ = env.reset()
    print(json.dumps({"ms": 1000 * statistics.median(times[5:]),
                      "actions": float(np.sum(actions)),
                      "load": float(open("/proc/loadavg").read().split()[0])}))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--store", required=True)
    ap.add_argument("--corpus", required=True)
    ap.add_argument("--model", default=None)
    ap.add_argument("--steps", type=int, default=150)
    ap.add_argument("--rounds", type=int, default=4)
    ap.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        return child(args.store, args.corpus, args.model, args.steps)
    base = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "OMP_NUM_THREADS")}
    cmd = [sys.executable, __file__, "--child", "--store", args.store, "--corpus", args.corpus,
           "--steps", str(args.steps)] + (["--model", args.model] if args.model else [])
    runs: dict = {}
    for _ in range(args.rounds):
        for policy in ("PASSIVE", None):
            for threads in ("1", None):
                env = dict(base)
                if policy:
                    env["OMP_WAIT_POLICY"] = policy
                if threads:
                    env["OMP_NUM_THREADS"] = threads
                out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True)
                rec = json.loads(out.stdout.strip().splitlines()[-1])
                runs.setdefault((policy or "unset", threads or "unset"), []).append(rec)
    print(f"{'OMP_WAIT_POLICY':>16} {'OMP_NUM_THREADS':>16} {'median ms':>10} "
          f"{'per process':>28} {'load':>5} {'actions':>12}")
    for (policy, threads), recs in runs.items():
        ms = [r["ms"] for r in recs]
        print(f"{policy:>16} {threads:>16} {statistics.median(ms):10.2f} "
              f"{' '.join(f'{m:.1f}' for m in ms):>28} "
              f"{statistics.median(r['load'] for r in recs):5.2f} "
              f"{recs[0]['actions']:12.6f}" + ("" if len({r['actions'] for r in recs}) == 1
                                                else " (differ!)"))


if __name__ == "__main__":
    main()
