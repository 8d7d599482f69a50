"""Benchmark: seconds per control step (K = 100 candidates) end to end.

For each size: collect pendulum-het rows, train the belief model (a short training: the
benchmark measures the step, not the policy), index, then time ``Controller.decide`` on states
of real rollouts (belief pass for the K candidates + neighbours + decomposition + choice),
median over steps (wall clock, and `cpu ms` the process's CPU time of the same step: on a
shared, oversubscribed machine the wall time includes waiting for a core), and split into the
belief pass, the decomposition and, inside it, the neighbour search. One thread for torch, FAISS and BLAS (as `aoc rollout` runs). The 1-minute
load average is printed with each line: the machine is shared.

Usage: .venv/bin/python benchmarks/perf/control.py --sizes 100k,600k [--steps 200] [--store DIR]
       [--kind auto|flat|ivf|hnsw]   (auto: flat up to 200k rows, IVF beyond; flat is exact)
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
from aoc_cli.threads import wait_passively  # noqa: E402

wait_passively()  # OpenMP threads wait passively, as under the aoc command (aoc_cli/threads.py)

import torch  # noqa: E402

from aoc_cli.belief import BeliefConfig, train_model  # noqa: E402
from aoc_cli.control import HistoryBuffer  # noqa: E402
from aoc_cli.envs import collect, make_env  # noqa: E402
from aoc_cli.control import open_session  # noqa: E402
from aoc_cli.corpus_index import build_index  # noqa: E402
from aoc_cli.store import Store  # noqa: E402


def parse_size(text: str) -> int:
    text = text.strip().lower()
    mult = {"k": 1_000, "m": 1_000_000}.get(text[-1], 1)
    return int(float(text.rstrip("km")) * mult)


def prepare(store: Store, rows: int, kind: str = "auto") -> str:
    name = f"pend{rows}"
    if not store.exists(name):
        data, _ = collect("pendulum-het", steps=rows, seed=0)
        store.write(name, data)
    corpus = store.corpus(name)
    if not (corpus.models_dir / "default" / "config.json").is_file():
        train_model(corpus, BeliefConfig(seed=0, max_epochs=2, patience=1), "default")
    build_index(corpus, "default", kind=kind)
    return name


def advance(env, buf, obs, action):
    """Step ``env`` with ``action``, record it in the history ``buf``; the next observation
    (a new episode's first when this one ended)."""
    nxt, r, term, trunc, _ = env.step(np.asarray(action, np.float32))
    buf.push(obs, action, r)
    if term or trunc:
        buf.reset()
        nxt, _ = env.reset()
    return nxt


def time_steps(store: Store, name: str, steps: int) -> dict:
    corpus = store.corpus(name)
    session = open_session(corpus)
    ctl, model, index = session.controller, session.model, session.index
    env = make_env("pendulum-het")
    buf = HistoryBuffer(model.history_length, corpus.observation_dim, 1, False)
    obs, _ = env.reset(seed=1)
    total, cpu, belief, decomp, search = [], [], [], [], []
    for _ in range(steps):
        h = buf.history()
        t0, c0 = time.perf_counter(), time.process_time()
        d = ctl.decide(obs, h)
        total.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
        t0 = time.perf_counter()
        b = model.beliefs(np.asarray(obs, np.float32)[None], d.candidates, h)  # as decide()
        belief.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        index.decompose(b)
        decomp.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        index.index.search(b, 2 * (b.shape[1] + 1))  # step 1 of the decomposition alone
        search.append(time.perf_counter() - t0)
        obs = advance(env, buf, obs, d.action)
    ms = lambda xs: 1000 * float(np.median(xs))  # noqa: E731
    return {"rows": corpus.n_rows, "step_ms": ms(total), "cpu_ms": ms(cpu), "belief_ms": ms(belief),
            "decompose_ms": ms(decomp), "search_ms": ms(search), "kind": index.index.kind}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="100k,600k")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--store", default=None, help="reuse corpora across runs (default: a temp dir)")
    ap.add_argument("--kind", default="auto", help="index kind: auto, flat (exact), ivf, hnsw")
    args = ap.parse_args()
    torch.set_num_threads(1)
    store = Store(args.store or tempfile.mkdtemp(prefix="aoc-bench-control-"))
    print(f"{'rows':>8} {'kind':>5} {'step ms':>8} {'cpu ms':>7} {'belief ms':>10} {'decompose ms':>13} "
          f"{'search ms':>10} {'load':>5}")
    for size in args.sizes.split(","):
        name = prepare(store, parse_size(size), args.kind)
        r = time_steps(store, name, args.steps)
        print(f"{r['rows']:>8} {r['kind']:>5} {r['step_ms']:>8.2f} {r['cpu_ms']:>7.2f} {r['belief_ms']:>10.2f} "
              f"{r['decompose_ms']:>13.2f} {r['search_ms']:>10.2f} {os.getloadavg()[0]:>5.2f}",
              flush=True)


if __name__ == "__main__":
    main()
