"""Benchmark: seconds per control step (K = 100 candidates) end to end.

For each size: collect pendulum-het rows, train the belief model (a short training: the
benchmark measures the step, not the policy), index, then time ``Controller.decide`` on states
of real rollouts (belief pass for the K candidates + neighbours + decomposition + choice),
median over steps (wall clock, and `cpu ms` the process's CPU time of the same step: on a
shared, oversubscribed machine the wall time includes waiting for a core), and split into the
belief pass, the decomposition and, inside it, the neighbour search. One thread for torch, FAISS and BLAS (as `aoc rollout` runs). The 1-minute
load average is printed with each line: the machine is shared.

The corpus (``pend<rows>``), its model and index are made through the API (aoc_cli.collect,
train with the paper's settings, build_index); the session is ``aoc_cli.open_session``. One row
per size: ``work`` the steps timed, ``median_s`` / ``step_ms`` the median step.

Usage: .venv/bin/python benchmarks/perf/control.py --sizes 100k,600k [--steps 200] [--store DIR]
       [--kind auto|flat|ivf|hnsw] [-f json]
       (kind auto: flat up to 200k rows, IVF beyond; flat is exact)
"""

from __future__ import annotations

import tempfile
import time

import _harness as h

h.omp_threads(1)

import numpy as np  # noqa: E402
import torch  # noqa: E402

import aoc_cli  # noqa: E402
from aoc_cli.store import Store  # noqa: E402


def prepare(store: Store, rows: int, kind: str = "auto") -> str:
    """Corpus ``pend<rows>`` (pendulum-het, seed 0), a short training (2 epochs: the benchmark
    measures the step, not the policy) and the index of ``kind`` (built again each time), all
    through the API; its name."""
    name = f"pend{rows}"
    h.corpus_ready(store, name, "pendulum-het", steps=rows, seed=0,
                   train=dict(paper=True, seed=0, max_epochs=2, patience=1),
                   index=dict(kind=kind), rebuild_index=True)
    return name


def time_steps(store: Store, name: str, steps: int) -> dict:
    session = aoc_cli.open_session(name, store=store)
    ctl, model, index = session.controller, session.model, session.index
    total, cpu, belief, decomp, search = [], [], [], [], []

    def decide(obs, hist):
        d, wall, c = h.timed(lambda: ctl.decide(obs, hist))
        total.append(wall)
        cpu.append(c)
        t0 = time.perf_counter()
        b = model.beliefs(np.asarray(obs, np.float32)[None], d.candidates, hist)  # as decide()
        belief.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        index.decompose(b)
        decomp.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        index.index.search(b, 2 * (b.shape[1] + 1))  # step 1 of the decomposition alone
        search.append(time.perf_counter() - t0)
        return d

    h.drive(session, "pendulum-het", steps, decide)
    runs = h.Runs(total, cpu, [None] * len(total))
    ms = lambda xs: 1000 * float(np.median(xs))  # noqa: E731
    return h.row(f"control step, {session.corpus.n_rows} rows", steps, runs, unit="steps",
                 kind=index.index.kind, step_ms=ms(total), cpu_ms=ms(cpu),
                 belief_ms=ms(belief), decompose_ms=ms(decomp), search_ms=ms(search),
                 load=h.load())


def main() -> None:
    ap = h.parser(__doc__)
    ap.add_argument("--sizes", default="100k,600k")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--store", default=None, help="reuse corpora across runs (default: a temp dir)")
    ap.add_argument("--kind", default="auto", help="index kind: auto, flat (exact), ivf, hnsw")
    args = ap.parse_args()
    torch.set_num_threads(1)
    store = Store(args.store or tempfile.mkdtemp(prefix="aoc-bench-control-"))
    rows = [time_steps(store, prepare(store, n, args.kind), args.steps)
            for n in h.sizes(args.sizes)]
    h.emit(rows, args.format)


if __name__ == "__main__":
    main()
