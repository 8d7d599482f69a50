"""Benchmark: the control step's cost for each ``--belief`` kind, in one process.

Opens one AOC session per model of a corpus (the same corpus, its own index each), and times
``Controller.decide`` on the same states, alternating the models step by step (so the machine's
load drifts into every arm alike). Prints the median seconds per step of each, and of the
belief pass alone (``model.beliefs`` of the K candidates).

Usage: python benchmarks/belief_cost.py --store bench/store --corpus pendulum-het-30000r-s0 \\
           --models default,dynamics,critic,reward [--steps 60]
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

from aoc_cli.control import HistoryBuffer  # noqa: E402
from aoc_cli.envs import make_env  # noqa: E402
from aoc_cli.session import open_session  # noqa: E402
from aoc_cli.store import Store  # noqa: E402


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--store", default="bench/store")
    p.add_argument("--corpus", default="pendulum-het-30000r-s0")
    p.add_argument("--models", default="default,dynamics,critic,reward")
    p.add_argument("--steps", type=int, default=60)
    args = p.parse_args()
    corpus = Store.open(args.store).corpus(args.corpus)
    models = args.models.split(",")
    sessions = {m: open_session(corpus, m, "default") for m in models}  # each model its index
    env = make_env("pendulum-het")
    first = sessions[models[0]]
    buf = HistoryBuffer(first.model.history_length, corpus.observation_dim, 1, False)
    obs, _ = env.reset(seed=1)
    step = {m: [] for m in models}
    belief = {m: [] for m in models}
    for i in range(args.steps):
        h = buf.history()
        order = models if i % 2 == 0 else models[::-1]
        decided = {}
        for m in order:
            s = sessions[m]
            t0 = time.perf_counter()
            d = decided[m] = s.controller.decide(obs, h)
            step[m].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            s.model.beliefs(np.asarray(obs, np.float32)[None], d.candidates, h)
            belief[m].append(time.perf_counter() - t0)
        action = decided[models[0]].action
        nxt, r, term, trunc, _ = env.step(np.asarray(action, np.float32))
        buf.push(obs, action, r)
        obs = nxt
        if term or trunc:
            buf.reset()
            obs, _ = env.reset()
    with open("/proc/loadavg") as f:
        load = f.read().split()[0]
    for m in models:
        print(json.dumps({"model": m, "belief": sessions[m].model.config.belief,
                          "median_step_s": round(float(np.median(step[m])), 5),
                          "median_belief_pass_s": round(float(np.median(belief[m])), 5),
                          "steps": args.steps, "loadavg": load}))


if __name__ == "__main__":
    main()
