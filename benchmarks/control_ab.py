"""Benchmark: one control step, this tree against an older tree's decomposition, in one process.

Separate processes drift with the load of a shared machine (+-15 % between runs here); this
script alternates, step by step and in alternating order, the current code and the current code
with an older tree's decomposition and search: its `aoc_cli/decompose/engine.py` (steps 1-4),
`aoc_cli/decompose/minnorm.py` (the residual QP) and its `aoc_cli/index/belief_index.py` with
the batch searches it uses (`scan_kernels.py`, `grouped.py`, `cells.py`, `pooled.py`, those the
tree has), each arm's `BeliefIndex` over the same FAISS index and beliefs, on the same states
and the same candidates, and checks that both give the same
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
    """The module at tree/rel, imported under `name` (its own imports resolve to this tree,
    except the modules already swapped in by `arms`)."""
    spec = importlib.util.spec_from_file_location(name, os.path.join(tree, rel))
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


#: The older tree's modules of the step, loaded in this order; while they load, each stands in
#: for its name in ``sys.modules`` so the later ones import the older ones (then restored).
OLD = ("aoc_cli/index/scan_kernels.py", "aoc_cli/index/grouped.py", "aoc_cli/index/cells.py",
       "aoc_cli/index/pooled.py", "aoc_cli/index/belief_index.py",
       "aoc_cli/decompose/minnorm.py", "aoc_cli/decompose/engine.py")


def arms(old_tree: str) -> dict:
    saved, old = {}, {}
    try:
        for rel in OLD:
            if not os.path.exists(os.path.join(old_tree, rel)):
                continue
            name = rel[:-3].replace("/", ".")
            old[name] = load(old_tree, rel, "old_" + name.rsplit(".", 1)[1])
            saved[name] = sys.modules.get(name)
            sys.modules[name] = old[name]
    finally:
        for name, module in saved.items():
            if module is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = module
    return {"new": {"decompose": build.decompose, "index": BI.BeliefIndex},
            "old": {"decompose": old["aoc_cli.decompose.engine"].decompose,
                    "index": old["aoc_cli.index.belief_index"].BeliefIndex}}


def run(store: Store, name: str, steps: int, code: dict) -> str:
    corpus = store.corpus(name)
    session = open_session(corpus)
    ctl, model, base = session.controller, session.model, session.index.index
    found: dict = {"old": [], "new": []}  # the rows of every search of the step, per arm
    index = {}
    for arm in ("old", "new"):  # each arm's BeliefIndex over the same FAISS index and beliefs
        ix = code[arm]["index"](base.index, base.config, base.kind, base.n_rows, None, base.beliefs)
        search = type(ix).search

        def recorded(*a, _arm=arm, _ix=ix, _search=search, **kw):
            out = _search(_ix, *a, **kw)
            found[_arm].append(out[1].copy())
            return out

        ix.search = recorded
        index[arm] = ix

    def use(arm: str) -> None:
        build.decompose = code[arm]["decompose"]
        session.index.index = index[arm]

    env = make_env("pendulum-het")
    buf = HistoryBuffer(model.history_length, corpus.observation_dim, 1, False)
    obs, _ = env.reset(seed=1)
    times: dict = {"old": [], "new": []}
    cpu: dict = {"old": [], "new": []}
    differ, rows, dres, dval = 0, 0, 0.0, 0.0
    for s in range(steps):
        h = buf.history()
        cand = ctl.sample_candidates(np.asarray(obs, np.float32).reshape(-1), h)
        dec = {}
        found["old"].clear()
        found["new"].clear()
        for arm in (("new", "old") if s % 2 else ("old", "new")):
            use(arm)
            t0, c0 = time.perf_counter(), time.process_time()
            dec[arm] = ctl.decide(obs, h, candidates=cand)
            times[arm].append(time.perf_counter() - t0)
            cpu[arm].append(time.process_time() - c0)
        a, b = dec["old"], dec["new"]
        differ += int(a.chosen != b.chosen)
        rows += int(len(found["old"]) != len(found["new"]) or not all(
            np.array_equal(x, y) for x, y in zip(found["old"], found["new"])))
        # largest change of a candidate's residual / value, relative to the step's largest
        dres = max(dres, _rel(a.candidate_residuals, b.candidate_residuals))
        dval = max(dval, _rel(a.candidate_values, b.candidate_values))
        obs = advance(env, buf, obs, b.action)
    use("new")
    o, n = np.array(times["old"][2:]), np.array(times["new"][2:])  # the first steps build scans
    co, cn = np.median(cpu["old"][2:]), np.median(cpu["new"][2:])
    return (f"{corpus.n_rows:>8} {base.kind:>5} {1e3 * np.median(o):>8.2f} {1e3 * np.median(n):>8.2f} "
            f"{np.median(o) / np.median(n):>6.2f} {np.median(o / n):>9.2f} {1e3 * co:>7.2f} "
            f"{1e3 * cn:>7.2f} {co / cn:>6.2f} {differ:>7d} {rows:>5d} "
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
          f"{'old cpu':>7} {'new cpu':>7} {'cpu x':>6} "
          f"{'differ':>7} {'rows':>5} {'d res':>8} {'d value':>8} {'load':>5}")
    for size in args.sizes.split(","):
        print(run(store, f"pend{parse_size(size)}", args.steps, code), flush=True)


if __name__ == "__main__":
    main()
