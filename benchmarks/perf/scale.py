"""Benchmark: a corpus beyond memory end to end — ingest, train (one epoch), index, control.

For each size (pendulum-het rows, collected with seed 0), four stages, each in its own Python
process so that its peak resident memory (VmHWM of /proc/self/status) is its own:

* ingest: collect the rows and write the corpus (``Store.write``);
* train: one epoch of the default value model (streamed above 2M rows, see
  aoc_cli/belief/stream.py), one torch thread;
* index: the beliefs of every row (written chunk by chunk into beliefs.npy) and the default
  index (IVF above 200k rows: trained on a sample, filled chunk by chunk);
* control: ``--steps`` control steps of AOC (K = 100 candidates) on a pendulum-het rollout,
  one thread; median step time (and the first step's, which builds the batch search's
  cells), the peak memory after the steps (before the recall, which reads every belief);
  recall@k of the neighbours the decomposition used against
  exact search (faiss.knn over the memory-mapped beliefs, in chunks) on the candidate beliefs
  of the first ``--recall-steps`` steps.

Each stage records seconds, peak memory (VmHWM), memory after the imports (the baseline),
and the 1-minute load average, in STORE/scale.json; a stage already recorded is skipped, so a
run that was interrupted resumes (``--redo STAGE`` runs a stage again; the earlier records
are kept under ``earlier``). Memory is set against
the corpus's float arrays (observations, actions, rewards) and the belief array (N, d_b).

Usage: .venv/bin/python benchmarks/perf/scale.py --sizes 1m,3m,10m --store DIR [--steps 200]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import _harness as h

h.omp_threads(1)

STAGES = ("ingest", "train", "index", "control")


def name_of(rows: int) -> str:
    return f"pend{rows}"


def stage_ingest(store, rows: int) -> dict:
    import aoc_cli

    corpus = aoc_cli.collect("pendulum-het", name_of(rows), store=store, steps=rows, seed=0,
                             overwrite=True).corpus
    return {"rows": corpus.n_rows, "episodes": corpus.n_episodes}


def stage_train(store, rows: int) -> dict:
    """The library's training call, not the API entry: ``aoc_cli.train`` first checks the
    corpus's content hash, reading every column, which at 10M rows would change the peak
    memory this stage has always measured (the training alone)."""
    from aoc_cli.belief import BeliefConfig, train_model
    from aoc_cli.belief.stream import streams
    from aoc_cli.store import DEFAULT_MODEL

    corpus = store.corpus(name_of(rows))
    cfg = BeliefConfig(seed=0, max_epochs=1, patience=1, threads=1)
    m = train_model(corpus, cfg, DEFAULT_MODEL, overwrite=True)
    return {"streamed": streams(corpus, cfg), "val_r2": m.get("val_r2"),
            "train_rows": m.get("train_rows")}


def stage_index(store, rows: int) -> dict:
    import aoc_cli

    ci = aoc_cli.build_index(name_of(rows), store=store).index
    return {"kind": ci.index.kind, "build_seconds": ci.meta["build_seconds"]}


def _exact_knn(beliefs, queries, k: int, chunk: int = 1 << 20):
    """(Q, k) exact nearest rows of ``queries`` among ``beliefs`` (memory-mapped), by chunks."""
    import faiss
    import numpy as np

    best_d = np.full((len(queries), k), np.inf, np.float32)
    best_i = np.full((len(queries), k), -1, np.int64)
    for a in range(0, len(beliefs), chunk):
        block = np.ascontiguousarray(beliefs[a:a + chunk], dtype=np.float32)
        d, i = faiss.knn(queries, block, k)
        d_all = np.concatenate([best_d, d], axis=1)
        i_all = np.concatenate([best_i, i + a], axis=1)
        order = np.argsort(d_all, axis=1, kind="stable")[:, :k]
        best_d = np.take_along_axis(d_all, order, 1)
        best_i = np.take_along_axis(i_all, order, 1)
    return best_i


def stage_control(store, rows: int, steps: int, recall_steps: int) -> dict:
    import faiss
    import numpy as np
    import torch

    import aoc_cli

    torch.set_num_threads(1)
    faiss.omp_set_num_threads(1)
    session, open_s, _ = h.timed(lambda: aoc_cli.open_session(name_of(rows), store=store))
    ctl, model, index = session.controller, session.model, session.index
    times, queries, found = [], [], []
    k = ctl.k  # the k rule: --k, else the index's

    def decide(obs, hist):
        d, wall, _ = h.timed(lambda: ctl.decide(obs, hist))
        times.append(wall)
        if len(times) <= recall_steps:  # outside the timing: the same beliefs and neighbours
            b = model.beliefs(np.asarray(obs, np.float32)[None], d.candidates, hist)
            queries.append(b)
            found.append(index.decompose(b, k=k).neighbours)
        return d

    h.drive(session, "pendulum-het", steps, decide)
    ms = np.asarray(times) * 1000
    out = {"steps": steps, "step_ms": float(np.median(ms)), "p90_ms": float(np.percentile(ms, 90)),
           "first_ms": float(ms[0]), "open_seconds": open_s, "kind": index.index.kind,
           "steps_peak_mb": h.memory()["VmHWM"]}  # before the recall reads every belief
    if not queries:
        return out
    q = np.concatenate(queries).astype(np.float32)
    got = np.concatenate(found)
    t0 = time.perf_counter()
    exact = _exact_knn(index.beliefs, q, got.shape[1])
    exact_s = time.perf_counter() - t0
    hits = [len(set(g[g >= 0]) & set(e)) / len(e) for g, e in zip(got, exact)]
    return {**out, "k": int(got.shape[1]), "recall": float(np.mean(hits)),
            "recall_min": float(np.min(hits)), "recall_queries": int(len(q)),
            "exact_seconds": exact_s}


def run_stage(stage: str, store_dir: str, rows: int, steps: int, recall_steps: int) -> None:
    """In the child: import, note the baseline memory, run the stage, print one JSON line."""
    import numpy as np  # noqa: F401 - part of the baseline
    import torch  # noqa: F401

    from aoc_cli.store import Store

    store = Store.open(store_dir)
    base = h.memory()
    t0 = time.perf_counter()
    if stage == "control":
        out = stage_control(store, rows, steps, recall_steps)
    else:
        out = {"ingest": stage_ingest, "train": stage_train, "index": stage_index}[stage](
            store, rows)
    out.update(seconds=time.perf_counter() - t0, peak_mb=h.memory()["VmHWM"],
               base_mb=base["VmRSS"], load=h.load())
    print("RESULT " + json.dumps(out), flush=True)


def sizes_of(store_dir: str, rows: int) -> dict:
    """Bytes of the corpus's float arrays and of the belief array."""
    import h5py

    from aoc_cli.store import DEFAULT_MODEL, Store, model_dir

    path = Store.open(store_dir).path(name_of(rows))
    out = {}
    with h5py.File(path / "corpus.h5", "r") as f:
        out["corpus_float_mb"] = sum(f[k].size * f[k].dtype.itemsize for k in
                                     ("observations", "actions", "rewards") if k in f) / 2**20
    beliefs = model_dir(path, DEFAULT_MODEL) / "beliefs.npy"
    if beliefs.is_file():
        import numpy as np

        b = np.load(beliefs, mmap_mode="r")
        out["belief_mb"] = b.size * b.dtype.itemsize / 2**20
    return out


def main() -> None:
    ap = h.parser(__doc__, rows=False)  # its record: STORE/scale.json
    ap.add_argument("--sizes", default="1m,3m,10m")
    ap.add_argument("--store", required=True, help="store folder; results in STORE/scale.json")
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--recall-steps", type=int, default=20)
    ap.add_argument("--redo", default="", help="comma-separated stages to run again")
    ap.add_argument("--stage", help=argparse.SUPPRESS)
    ap.add_argument("--rows", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.stage:
        run_stage(args.stage, args.store, args.rows, args.steps, args.recall_steps)
        return
    Path(args.store).mkdir(parents=True, exist_ok=True)
    record = Path(args.store) / "scale.json"
    results = json.loads(record.read_text()) if record.is_file() else {}
    redo = {s for s in args.redo.split(",") if s}
    for rows in h.sizes(args.sizes):
        done = results.setdefault(str(rows), {})
        for stage in STAGES:
            if stage in done and stage not in redo:
                continue
            proc = subprocess.run([sys.executable, __file__, "--stage", stage, "--rows",
                                   str(rows), "--store", args.store, "--steps",
                                   str(args.steps), "--recall-steps", str(args.recall_steps)],
                                  capture_output=True, text=True)
            line = next((x for x in proc.stdout.splitlines() if x.startswith("RESULT ")), None)
            if proc.returncode != 0 or line is None:
                sys.exit(f"{stage} at {rows} rows failed:\n{proc.stderr[-3000:]}")
            if stage in done:  # a stage run again: the earlier records are kept beside it
                done.setdefault("earlier", []).append({stage: done[stage]})
            done[stage] = json.loads(line[len("RESULT "):])
            done.update(sizes_of(args.store, rows))
            tmp = record.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(results, indent=1) + "\n")
            os.replace(tmp, record)
            r = done[stage]
            print(f"{rows:>9} {stage:>8} {r['seconds']:>9.1f} s  peak {r['peak_mb']:>7.0f} MB "
                  f"(base {r['base_mb']:.0f})  load {r['load']:.1f}  "
                  + " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}"
                             for k, v in r.items()
                             if k not in ("seconds", "peak_mb", "base_mb", "load")),
                  flush=True)


if __name__ == "__main__":
    main()
