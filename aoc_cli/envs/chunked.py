"""``aoc collect TASK --workers N``: a corpus collected as independent seeded chunks.

The budget (rows, or episodes) is cut into chunks of ``chunk_steps`` rows (or
``chunk_episodes`` episodes), the last one taking the rest. Chunk ``i`` of a collection with
seed ``s`` is exactly ``collect(task, steps=<its rows>, seed=chunk_seed(s, i), behaviour=...)`` (or
with ``episodes=``), where ``chunk_seed(s, i) = SeedSequence([s, i]).generate_state(1)[0]`` (numpy),
and the corpus is the chunks' episodes in chunk order. So the corpus depends on the seed and
the chunk size, not on the number of workers nor on where a chunk ran; it is not the corpus of
a serial ``aoc collect`` with the same seed (that is one chunk with seed ``s`` itself). Each
chunk ends its last episode where its rows end (a truncated episode), as a serial collect does
at the end of its budget.

The chunks run as Ray tasks (:func:`aoc_cli.parallel.map_chunks`) or, with
``workers=None`` and no address, one after the other here.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.envs import collect, get_task
from aoc_cli.envs.base import budget
from aoc_cli.parallel import map_chunks
from aoc_cli.store.writer import concat

#: Rows (or episodes) per chunk.
CHUNK_STEPS = 100_000
CHUNK_EPISODES = 1_000


def chunk_seed(seed: int, i: int) -> int:
    """The collect seed of chunk ``i`` of a collection with seed ``seed``."""
    return int(np.random.SeedSequence([int(seed), int(i)]).generate_state(1)[0])


def plan(task, steps: int | None, episodes: int | None, chunk_steps: int = CHUNK_STEPS,
         chunk_episodes: int = CHUNK_EPISODES) -> list[dict]:
    """The chunks' budgets: ``[{"steps": n} or {"episodes": n}, ...]``."""
    steps, episodes = budget(steps, episodes, task.default_steps, task.default_episodes)
    total, size, key = (steps, chunk_steps, "steps") if steps is not None \
        else (episodes, chunk_episodes, "episodes")
    return [{key: min(size, total - a)} for a in range(0, total, size)]


def _collect_chunk(task: str, seed: int, i: int, part: dict, behaviour: str = "mix",
                   policy: str | None = None):
    data, summary = collect(task, seed=chunk_seed(seed, i), behaviour=behaviour, policy=policy,
                            **part)
    if data.episode_ids is not None:  # unique across chunks: the chunk's index in front
        data.episode_ids = [f"c{i}-{e}" for e in data.episode_ids]
    return data, [{"chunk": i, "seed": chunk_seed(seed, i), **rec} for rec in summary]


def collect_chunked(task: str, steps: int | None = None, episodes: int | None = None,
                    seed: int = 0, workers: int | None = None, address: str | None = None,
                    chunk_steps: int = CHUNK_STEPS, chunk_episodes: int = CHUNK_EPISODES,
                    progress=None, behaviour: str = "mix", policy: str | None = None):
    """(CorpusData, summary): the chunks' episodes in chunk order and each chunk's per-policy
    summary (with its ``chunk`` and ``seed``); ``progress(done_chunks, chunks)``."""
    parts = plan(get_task(task), steps, episodes, chunk_steps, chunk_episodes)
    results = [None] * len(parts)
    if workers is None and address is None:
        for i, part in enumerate(parts):
            results[i] = _collect_chunk(task, seed, i, part, behaviour, policy)
            if progress is not None:
                progress(i + 1, len(parts))
    else:
        finished = []

        def done(_i, _result):
            finished.append(_i)
            if progress is not None:
                progress(len(finished), len(parts))

        results = map_chunks(_collect_chunk,
                             [(task, seed, i, part, behaviour, policy)
                              for i, part in enumerate(parts)],
                             workers=workers, address=address, retries=1, done=done)
    data = results[0][0]
    for other, _summary in results[1:]:
        data = concat(data, other)
    summary = [rec for _data, recs in results for rec in recs]
    return data.validate(), summary
