"""Benchmark: the control step's cost for each ``--belief`` kind, in one process.

Opens one AOC session per model of a corpus (the same corpus, its own index each), and times
``Controller.decide`` on the same states with the same candidate actions, alternating the
models step by step (so the machine's load drifts into every arm alike). The states are those
of one rollout driven by the first model's decisions. Prints, per model, the mean, median and
90th percentile seconds per step, the belief pass alone (``model.beliefs`` of the K
candidates, median), the step-2 problems that fell back to the reference QP (piqp +
Caratheodory: ``Decomposition.fallbacks``) out of all problems solved, and ``step3``, the share
of the problems whose minimal subset step 3 searches by pivots (y* inside the neighbours' hull
or on a face that other neighbours share: the rest keep step 2's support; counted in this
tree's ``hull.py`` only, so 0 in an ``--old`` arm). A rollout's cost is the
mean step: fallbacks cluster on a few steps, which a median hides.

``--old TREE`` adds, for every model, an arm whose steps 2 and 3 are the older tree's
(``aoc_cli/decompose/minnorm.py``'s residual QP and ``hull.py``'s minimal subset; everything
else this tree's code), on the same states and candidates in alternating order: the
before/after of the decomposition in one process. ``differ`` counts the steps whose chosen
candidate differs between the two arms, ``d_res`` is the largest change of a candidate's
residual (absolute, in belief units) and ``new_above`` the candidates whose residual in this
tree exceeds the old arm's by more than 1e-9 (the new one is certified optimal, so it should
be 0: where they differ, the old arm's reference-QP answer was the less precise).

Usage: python benchmarks/notes/belief_cost.py --store bench/store --corpus pendulum-het-30000r-s0 \\
           --models default,dynamics,critic,reward [--env pendulum-het] [--steps 60] \\
           [--old ../aoc-old]
(with --old, set NUMBA_CACHE_DIR to a directory of its own: the old module is compiled under
another name.)
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import sys
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

# internal: this note counts the engine's step-2 solves and step 3's tableaux by wrapping them
import aoc_cli.decompose.engine as engine  # noqa: E402
import aoc_cli.decompose.hull as hull  # noqa: E402
from aoc_cli.control import HistoryBuffer  # noqa: E402
from aoc_cli.envs import make_env  # noqa: E402
import aoc_cli  # noqa: E402
from aoc_cli.store import Store  # noqa: E402


def old_steps(tree: str) -> dict:
    """The older tree's steps 2 and 3: ``min_norm_point`` and ``minimal_subset`` (its minnorm.py
    and hull.py imported under other names)."""
    out = {}
    for name, fn in (("minnorm", "min_norm_point"), ("hull", "minimal_subset")):
        path = os.path.join(tree, "aoc_cli", "decompose", name + ".py")
        spec = importlib.util.spec_from_file_location("old_" + name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules["old_" + name] = module
        spec.loader.exec_module(module)
        out[fn] = getattr(module, fn)
    return out


class Counted:
    """Wraps the engine's step-2 function (problems solved and fallbacks) and step 3's tableau
    (the problems it pivots), per arm."""

    def __init__(self):
        self.solve = engine._residual_weights
        self.problems = 0
        self.failed = 0
        self.step3 = 0
        build = hull._Tableau.build.__func__

        def counted(cls, zt, *rest):
            self.step3 += zt.shape[0]
            return build(cls, zt, *rest)

        hull._Tableau.build = classmethod(counted)

    def __call__(self, B, Y, P, valid, reference, qp_tol):
        weights, failed = self.solve(B, Y, P, valid, reference, qp_tol)
        self.problems += len(Y)
        self.failed += len(failed)
        return weights, failed


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--store", default="bench/store")
    p.add_argument("--corpus", default="pendulum-het-30000r-s0")
    p.add_argument("--models", default="default,dynamics,critic,reward")
    p.add_argument("--env", default="pendulum-het", help="the task whose rollout gives the states")
    p.add_argument("--steps", type=int, default=60)
    p.add_argument("--old", default=None, help="an older tree: its step-2 solver as a second arm")
    args = p.parse_args()
    corpus = Store.open(args.store).corpus(args.corpus)
    models = args.models.split(",")
    # each model its index, the paper's settings (pendulum-het sets none), the public entry
    sessions = {m: aoc_cli.open_session(args.corpus, store=args.store, model=m) for m in models}
    solvers = {"new": {"min_norm_point": engine.min_norm_point,
                       "minimal_subset": engine.minimal_subset}}
    if args.old:
        solvers["old"] = old_steps(args.old)
    counter = Counted()
    engine._residual_weights = counter
    arms = [(m, a) for m in models for a in solvers]
    env = make_env(args.env)
    first = sessions[models[0]]
    buf = HistoryBuffer(first.model.history_length, corpus.observation_dim,
                        1 if corpus.discrete else corpus.action_dim, corpus.discrete)
    obs, _ = env.reset(seed=1)
    step = {x: [] for x in arms}
    belief = {m: [] for m in models}
    falls = {x: [0, 0] for x in arms}
    inside = {x: 0 for x in arms}  # problems step 3 pivots (this tree's hull.py only)
    differ = {m: 0 for m in models}
    dres = {m: 0.0 for m in models}
    above = {m: 0 for m in models}
    for i in range(args.steps):
        h = buf.history()
        cand = first.controller.sample_candidates(np.asarray(obs, np.float32).reshape(-1), h)
        decided = {}
        for m, a in (arms if i % 2 == 0 else arms[::-1]):
            s = sessions[m]
            for fn, f in solvers[a].items():
                setattr(engine, fn, f)
            counter.problems = counter.failed = counter.step3 = 0
            t0 = time.perf_counter()
            decided[m, a] = s.controller.decide(obs, h, candidates=cand)
            step[m, a].append(time.perf_counter() - t0)
            falls[m, a][0] += counter.problems
            falls[m, a][1] += counter.failed
            inside[m, a] += counter.step3
        for fn, f in solvers["new"].items():
            setattr(engine, fn, f)
        for m in models:
            t0 = time.perf_counter()
            sessions[m].model.beliefs(np.asarray(obs, np.float32)[None], cand, h)
            belief[m].append(time.perf_counter() - t0)
            if args.old:
                a, b = decided[m, "old"], decided[m, "new"]
                differ[m] += int(a.chosen != b.chosen)
                ro, rn = np.asarray(a.candidate_residuals), np.asarray(b.candidate_residuals)
                dres[m] = max(dres[m], float(np.abs(ro - rn).max()))
                above[m] += int((rn > ro + 1e-9).sum())
        action = decided[models[0], "new"].action
        nxt, r, term, trunc, _ = env.step(np.asarray(action, np.float32))
        buf.push(obs, action, r)
        obs = nxt
        if term or trunc:
            buf.reset()
            obs, _ = env.reset()
    with open("/proc/loadavg") as f:
        load = f.read().split()[0]
    for m, a in arms:
        t = np.array(step[m, a][2:])  # the first steps load the scans' compiled code
        row = {"model": m, "belief": sessions[m].model.config.belief, "arm": a,
               "mean_step_s": round(float(t.mean()), 5),
               "median_step_s": round(float(np.median(t)), 5),
               "p90_step_s": round(float(np.quantile(t, 0.9)), 5),
               "median_belief_pass_s": round(float(np.median(belief[m])), 5),
               "problems": falls[m, a][0], "fallbacks": falls[m, a][1],
               "step3": round(inside[m, a] / max(falls[m, a][0], 1), 3),
               "steps": args.steps, "loadavg": load}
        if args.old:
            row.update(differ=differ[m], d_res=float(f"{dres[m]:.2e}"), new_above=above[m])
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
