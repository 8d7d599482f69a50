"""Benchmark: one control step of two source trees, alternated in one run, same decisions?

A refactor moves modules and names (the retired `control_ab.py` swapped an older tree's
decomposition modules into one process), so this script runs each tree whole, in its own Python
process (``PYTHONPATH=TREE``), on the same corpus, model and index, and alternates the trees
round by round (old, new, new, old, ...) so that both see the same load of a shared machine.
Each round opens a session and times ``Controller.decide`` over the same states of a
pendulum-het rollout (K = 100 candidates, one thread for torch, FAISS and BLAS, as `aoc rollout`
runs). It reports the median step of each tree (the median over rounds of each round's
median), their ratio, the median of the rounds' own ratios (``paired``: a round of each tree
run back to back sees about the same load), and whether every decision is the same: the chosen action, its value
and residual, step by step, compared to the bit (same machine, same inputs).

Usage: .venv/bin/python benchmarks/ab/control_trees.py --old ../aoc-old --new . --sizes 100k
       [--steps 100] [--rounds 4] [--store DIR]
  (``git worktree add ../aoc-old f2b73f1`` makes the old tree; the corpora, models and indexes
  are prepared with the new tree's code, in --store, and reused.)
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile

import numpy as np

#: Runs inside each tree: imports what that tree calls the session, times the steps.
WORKER = r"""
import json, sys, time
import numpy as np
import torch
torch.set_num_threads(1)
from aoc_cli.store import Store
try:
    from aoc_cli.control import open_session
except ImportError:  # a tree before the renovation (issue 22): aoc_cli/session.py
    from aoc_cli.session import open_session
from aoc_cli.control import HistoryBuffer
from aoc_cli.envs import make_env

store, name, steps, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
corpus = Store(store).corpus(name)
session = open_session(corpus)
ctl, model = session.controller, session.model
env = make_env("pendulum-het")
buf = HistoryBuffer(model.history_length, corpus.observation_dim, 1, False)
obs, _ = env.reset(seed=1)
times, decisions = [], []
for _ in range(steps):
    h = buf.history()
    t0 = time.perf_counter()
    d = ctl.decide(obs, h)
    times.append(time.perf_counter() - t0)
    decisions.append([float(x) for x in np.ravel(d.action)] + [d.value, d.residual])
    nxt, r, term, trunc, _ = env.step(np.asarray(d.action, np.float32))
    buf.push(obs, d.action, r)
    if term or trunc:
        buf.reset()
        nxt, _ = env.reset()
    obs = nxt
json.dump({"times": times, "decisions": decisions}, open(out, "w"))
"""


def run_tree(tree: str, store: str, name: str, steps: int) -> dict:
    with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
        out = f.name
    env = {**os.environ, "PYTHONPATH": os.path.abspath(tree), "OMP_NUM_THREADS": "1",
           "OMP_WAIT_POLICY": os.environ.get("OMP_WAIT_POLICY", "PASSIVE")}  # as `aoc` sets it
    subprocess.run([sys.executable, "-c", WORKER, store, name, str(steps), out], env=env,
                   check=True, cwd=tempfile.gettempdir())
    with open(out) as f:
        result = json.load(f)
    os.unlink(out)
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="the older tree (a git worktree)")
    ap.add_argument("--new", default=".", help="the newer tree (default: this one)")
    ap.add_argument("--sizes", default="100k")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--rounds", type=int, default=4, help="rounds per tree (alternated)")
    ap.add_argument("--store", default=None, help="reuse corpora across runs (default: a "
                                                  "temporary folder)")
    args = ap.parse_args()
    sys.path.insert(0, os.path.abspath(args.new))
    sys.path.insert(0, os.path.join(os.path.abspath(args.new), "benchmarks", "perf"))
    import _harness as h  # noqa: E402  (the new tree's benchmark harness)
    from control import prepare  # noqa: E402  (the corpus, model and index, through the API)

    from aoc_cli.store import Store  # noqa: E402

    store_dir = args.store or tempfile.mkdtemp(prefix="aoc-bench-trees-")
    print(f"{'rows':>8} {'old ms':>8} {'new ms':>8} {'new/old':>8} {'paired':>7} {'rounds':>6} "
          f"{'same decisions':>15} {'load':>5}")
    for rows in h.sizes(args.sizes):
        name = prepare(Store(store_dir), rows)
        medians: dict = {"old": [], "new": []}
        reference = None
        same = True
        for r in range(args.rounds):
            for arm in (("old", "new") if r % 2 == 0 else ("new", "old")):
                tree = args.old if arm == "old" else args.new
                res = run_tree(tree, store_dir, name, args.steps)
                medians[arm].append(float(np.median(res["times"][2:])))
                decisions = np.asarray(res["decisions"], dtype=np.float64)
                reference = decisions if reference is None else reference
                same &= bool(np.array_equal(decisions, reference, equal_nan=True))
        old, new = 1e3 * np.median(medians["old"]), 1e3 * np.median(medians["new"])
        paired = h.paired(h.Runs(medians["old"]), h.Runs(medians["new"]))
        print(f"{rows:>8} {old:>8.2f} {new:>8.2f} {new / old:>8.2f} {paired:>7.2f} "
              f"{args.rounds:>6} {str(same):>15} {h.load():>5.2f}", flush=True)
        for arm in ("old", "new"):
            rounds = " ".join(f"{1e3 * m:.2f}" for m in medians[arm])
            print(f"{'':>8} {arm} rounds (median ms each): {rounds}", flush=True)


if __name__ == "__main__":
    main()
