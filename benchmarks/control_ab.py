"""Benchmark: one control step, this tree against an older tree's decomposition, in one process.

Separate processes drift with the load of a shared machine (+-15 % between runs here); this
script alternates, step by step and in alternating order, the current code and the current code
with an older tree's decomposition: its `aoc_cli/decompose/engine.py` (steps 1-4),
`aoc_cli/decompose/minnorm.py` (the residual QP), `aoc_cli/index/grouped.py` (the exact
grouped scan of a flat index) and `aoc_cli/index/pooled.py` (the batch search of an IVF / HNSW
index), on the same states and the same candidates, and checks that both give the same
decision: `differ` counts the steps whose chosen candidate differs, `rows` the steps whose
neighbour search returned different rows (or the same rows in another order), `d res` and
`d value` are the largest change of a candidate's residual and value over all steps, relative
to the step's largest. Everything else (belief pass, minimal subset) is the current code in
both arms.

Usage: .venv/bin/python benchmarks/control_ab.py --old ../aoc-old --sizes 100k,600k
       --store DIR [--steps 100]   (the store of benchmarks/control.py, already prepared;
       ``git worktree add ../aoc-old REV`` makes the old tree)
"""

from __future__ import annotations

import argparse
import importlib.util
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

import torch  # noqa: E402

import aoc_cli.index.belief_index as BI  # noqa: E402
import aoc_cli.session as build  # noqa: E402
from aoc_cli.control import HistoryBuffer  # noqa: E402
from aoc_cli.session import open_session  # noqa: E402
from aoc_cli.envs import make_env  # noqa: E402
from aoc_cli.store import Store  # noqa: E402

sys.path.insert(0, os.path.dirname(__file__))
from control import advance, parse_size  # noqa: E402


def load(tree: str, rel: str, name: str):
    """The module at tree/rel, imported under `name` (its own imports resolve to this tree)."""
    spec = importlib.util.spec_from_file_location(name, os.path.join(tree, rel))
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


def arms(old_tree: str) -> dict:
    grouped = load(old_tree, "aoc_cli/index/grouped.py", "old_grouped")
    minnorm = load(old_tree, "aoc_cli/decompose/minnorm.py", "old_minnorm")
    engine = load(old_tree, "aoc_cli/decompose/engine.py", "old_engine")
    pooled = load(old_tree, "aoc_cli/index/pooled.py", "old_pooled")
    engine.min_norm_point = minnorm.min_norm_point
    return {"new": {"grouped_search": BI.grouped_search, "ScanData": BI.ScanData,
                    "decompose": build.decompose, "pooled_search": BI.pooled_search,
                    "exact_among": BI._exact_among},
            "old": {"grouped_search": grouped.grouped_search, "ScanData": grouped.ScanData,
                    "decompose": engine.decompose, "pooled_search": pooled.pooled_search,
                    "exact_among": pooled.exact_among}}


def run(store: Store, name: str, steps: int, code: dict) -> str:
    corpus = store.corpus(name)
    session = open_session(corpus)
    ctl, model, index = session.controller, session.model, session.index.index
    scans: dict = {}
    found: dict = {"old": [], "new": []}  # the rows of every search of the step, per arm
    search = type(index).search

    def recorded(self, *a, **kw):
        out = search(self, *a, **kw)
        found[current].append(out[1].copy())
        return out

    def use(arm: str) -> None:
        nonlocal current
        current = arm
        BI.grouped_search, BI.ScanData = code[arm]["grouped_search"], code[arm]["ScanData"]
        BI.pooled_search, BI._exact_among = code[arm]["pooled_search"], code[arm]["exact_among"]
        build.decompose = code[arm]["decompose"]
        index._scan = scans.get(arm)

    current = "new"
    index.search = recorded.__get__(index)

    env = make_env("pendulum-het")
    buf = HistoryBuffer(model.history_length, corpus.observation_dim, 1, False)
    obs, _ = env.reset(seed=1)
    times: dict = {"old": [], "new": []}
    differ, rows, dres, dval = 0, 0, 0.0, 0.0
    for s in range(steps):
        h = buf.history()
        cand = ctl.sample_candidates(np.asarray(obs, np.float32).reshape(-1), h)
        dec = {}
        found["old"].clear()
        found["new"].clear()
        for arm in (("new", "old") if s % 2 else ("old", "new")):
            use(arm)
            t0 = time.perf_counter()
            dec[arm] = ctl.decide(obs, h, candidates=cand)
            times[arm].append(time.perf_counter() - t0)
            scans[arm] = index._scan
        a, b = dec["old"], dec["new"]
        differ += int(a.chosen != b.chosen)
        rows += int(len(found["old"]) != len(found["new"]) or not all(
            np.array_equal(x, y) for x, y in zip(found["old"], found["new"])))
        # largest change of a candidate's residual / value, relative to the step's largest
        dres = max(dres, _rel(a.candidate_residuals, b.candidate_residuals))
        dval = max(dval, _rel(a.candidate_values, b.candidate_values))
        obs = advance(env, buf, obs, b.action)
    use("new")
    del index.search
    o, n = np.array(times["old"][2:]), np.array(times["new"][2:])  # the first steps build scans
    return (f"{corpus.n_rows:>8} {index.kind:>5} {1e3 * np.median(o):>8.2f} {1e3 * np.median(n):>8.2f} "
            f"{np.median(o) / np.median(n):>6.2f} {np.median(o / n):>9.2f} {differ:>7d} {rows:>5d} "
            f"{dres:>8.1e} {dval:>8.1e} {os.getloadavg()[0]:>5.2f}")


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.abs(a - b).max() / max(np.abs(a).max(), 1e-300))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", required=True, help="a checkout of the older tree (git worktree add)")
    ap.add_argument("--sizes", default="100k,600k")
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--store", required=True, help="the store benchmarks/control.py prepared")
    args = ap.parse_args()
    torch.set_num_threads(1)
    code = arms(args.old)
    store = Store(args.store)
    print(f"{'rows':>8} {'kind':>5} {'old ms':>8} {'new ms':>8} {'ratio':>6} {'per-step':>9} "
          f"{'differ':>7} {'rows':>5} {'d res':>8} {'d value':>8} {'load':>5}")
    for size in args.sizes.split(","):
        print(run(store, f"pend{parse_size(size)}", args.steps, code), flush=True)


if __name__ == "__main__":
    main()
