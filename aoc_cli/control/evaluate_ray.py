"""``aoc evaluate NAME --data HELD_OUT --workers N``: the chunks of episodes scored as Ray tasks.

The held-out episodes are cut into the same chunks as in one process
(:func:`aoc_cli.control.evaluate.chunks`); the chunks are dealt in contiguous runs to the
tasks. Each task opens the store by its path, builds the session and the evaluation context
as :func:`aoc_cli.control.evaluate.evaluate` does (the same seed, so the same candidates and
search structure), scores its chunks with :func:`score_episodes` and returns their
:class:`StepScores`; the driver merges them in chunk order and summarises. The per-step results
and the metrics are therefore those of the run in one process. On a cluster the store must be
on a path every node mounts (each task reads NAME's corpus, model and index and the held-out
corpus from it).
"""

from __future__ import annotations

import time

import numpy as np

from aoc_cli.control.evaluate import CHUNK_STEPS, chunks, merge, score_episodes, summarise


def _context(spec: dict):
    from aoc_cli.control.evaluate_inputs import EvalContext
    from aoc_cli.session import open_session
    from aoc_cli.store import Store

    store = Store.open(spec["store"])
    corpus = store.corpus(spec["name"])
    data = corpus if spec["data"] == spec["name"] else store.corpus(spec["data"])
    session = open_session(corpus, spec["model"], spec["index"], spec["config"],
                           seed=spec["seed"])
    return EvalContext.build(session, data, spec["baselines"], spec["seed"], spec["exact"])


def _score(spec: dict, groups: list) -> list:
    from aoc_cli.threads import one_thread

    with one_thread():
        ctx = _context(spec)
        return [score_episodes(ctx, group) for group in groups]


def evaluate_on_ray(store_root, name: str, data: str, model: str | None, index_id: str,
                    config, baselines, seed: int = 0, exact: bool | None = None,
                    workers: int | None = None, address: str | None = None,
                    chunk_steps: int = CHUNK_STEPS, progress=None):
    """(summary, StepScores) of ``aoc evaluate`` with the chunks on Ray (module docstring)."""
    from aoc_cli.experiments.distributed import start_ray

    started = time.perf_counter()
    spec = {"store": str(store_root), "name": name, "data": data, "model": model,
            "index": index_id, "config": config, "baselines": list(baselines), "seed": int(seed),
            "exact": exact}
    ctx = _context(spec)
    groups = chunks(ctx, chunk_steps)
    ray = start_ray(workers, address)
    n_tasks = int(workers) if workers else max(1, int(ray.cluster_resources().get("CPU", 1)))
    runs = [list(r) for r in np.array_split(np.arange(len(groups)), min(n_tasks, len(groups)))]
    remote = ray.remote(num_cpus=1, max_retries=1)(_score)
    refs = {remote.remote(spec, [groups[i] for i in run]): j for j, run in enumerate(runs)}
    results: list = [None] * len(runs)
    pending, done = list(refs), 0
    while pending:
        finished, pending = ray.wait(pending, num_returns=1)
        j = refs[finished[0]]
        results[j] = ray.get(finished[0])
        done += sum(len(p.row) for p in results[j])
        if progress is not None:
            progress(done, ctx.data.n_rows)
    res = merge([part for parts in results for part in parts])
    summary = summarise(ctx, res)
    summary["seconds"] = time.perf_counter() - started
    summary["steps_per_second"] = summary["steps"] / max(summary["seconds"], 1e-9)
    return summary, res
