"""``aoc evaluate NAME --data HELD_OUT --workers N``: the chunks of episodes scored as Ray tasks.

The held-out episodes are cut into the same chunks as in one process
(:func:`aoc_cli.evaluation.score.chunks`); the chunks are dealt in contiguous runs to the
tasks. Each task opens the store by its path, builds the session and the evaluation context
as :func:`aoc_cli.evaluation.score.score_log` does (the same seed, so the same candidates and
search structure), scores its chunks with :func:`score_episodes` and returns their
:class:`StepScores`; the driver merges them in chunk order and summarises. The per-step results
and the metrics are therefore those of the run in one process. On a cluster the store must be
on a path every node mounts (each task reads NAME's corpus, model and index and the held-out
corpus from it).
"""

from __future__ import annotations

import time

import numpy as np

from aoc_cli.control.session import open_session
from aoc_cli.evaluation.context import EvalContext
from aoc_cli.evaluation.score import (
    CHUNK_STEPS,
    chunk_size,
    chunks,
    conclude,
    merge,
    score_episodes,
)
from aoc_cli.ope.evaluate_block import wanted
from aoc_cli.parallel import capacity, map_chunks, start_ray
from aoc_cli.store import Store
from aoc_cli.threads import one_thread


def _context(spec: dict):
    store = Store.open(spec["store"])
    corpus = store.corpus(spec["name"])
    data = corpus if spec["data"] == spec["name"] else store.corpus(spec["data"])
    session = open_session(corpus, spec["model"], spec["index"], spec["config"],
                           seed=spec["seed"])
    return EvalContext.build(session, data, spec["baselines"], spec["seed"], spec["exact"])


def _score(spec: dict, groups: list) -> list:
    with one_thread():
        ctx = _context(spec)
        return [score_episodes(ctx, group) for group in groups]


def evaluate_on_ray(store_root, name: str, data: str, model: str | None, index_id: str,
                    config, baselines, seed: int = 0, exact: bool | None = None,
                    workers: int | None = None, address: str | None = None,
                    chunk_steps: int = CHUNK_STEPS, progress=None, ope=None):
    """(summary, StepScores) of ``aoc evaluate`` with the chunks on Ray (module docstring)."""
    started = time.perf_counter()
    spec = {"store": str(store_root), "name": name, "data": data, "model": model,
            "index": index_id, "config": config, "baselines": list(baselines), "seed": int(seed),
            "exact": exact}
    ctx = _context(spec)
    wanted(ope, ctx.mode, ctx.data)     # a log the OPE cannot use is refused before deciding
    groups = chunks(ctx, chunk_size(ctx, chunk_steps))
    n_tasks = capacity(start_ray(workers, address), workers)
    runs = [list(r) for r in np.array_split(np.arange(len(groups)), min(n_tasks, len(groups)))]
    rows = [0]

    def done(_j, parts):
        rows[0] += sum(len(p.row) for p in parts)
        if progress is not None:
            progress(rows[0], ctx.data.n_rows)

    results = map_chunks(_score, [(spec, [groups[i] for i in run]) for run in runs],
                         workers=workers, address=address, retries=1, done=done)
    res = merge([part for parts in results for part in parts])
    # the OPE and the value targets are the driver's alone: the tasks never compute them
    return conclude(ctx, ctx.data, res, ope, seed, started)
