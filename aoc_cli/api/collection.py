"""The API's collect entry: a built-in task's behaviour policies run into a corpus (and the
list of the tasks)."""

from __future__ import annotations

import os
from pathlib import Path

from aoc_cli.api.common import StoreLike, open_store
from aoc_cli.envs import TASKS
from aoc_cli.envs.into_store import Collected, check_request, collect_corpus, collect_csv
from aoc_cli.progress import Progress


def tasks() -> list[dict]:
    """One row per built-in task (name, gym id, horizon, default size, policies, success):
    what ``aoc collect --list`` prints."""
    return [t.describe() for t in TASKS.values()]


def collect(task: str | None, name: str | None, *, store: StoreLike = None,
            steps: int | None = None, episodes: int | None = None, seed: int = 0,
            behaviour: str = "mix", policy: str | None = None, overwrite: bool = False,
            workers: int | None = None, ray_address: str | None = None,
            chunk: int | None = None, csv: str | os.PathLike | None = None,
            progress: Progress | None = None) -> Collected | tuple[Path, Path]:
    """Run built-in ``task``'s behaviour policies (``behaviour`` mix or replay; ``policy``:
    icu-sepsis's one policy) for ``steps`` rows or ``episodes`` episodes (default the task's)
    and write corpus ``name``: a :class:`~aoc_cli.envs.into_store.Collected` (the corpus, one
    summary row per policy). ``workers`` / ``ray_address``: seeded chunks of ``chunk`` rows
    as Ray tasks. ``csv`` (ward): write the log as the two CSV files ``csv/name.csv`` and
    ``csv/name-static.csv`` instead, and return their paths. Same seed, same corpus."""
    t = check_request(task, name, steps=steps, episodes=episodes, behaviour=behaviour,
                      policy=policy, workers=workers, chunk=chunk)
    s = open_store(store)
    if csv is not None:
        return collect_csv(s, t, csv, name, steps=steps, episodes=episodes, seed=seed)
    return collect_corpus(s, t, name, steps=steps, episodes=episodes, seed=seed,
                          behaviour=behaviour, policy=policy, overwrite=overwrite,
                          workers=workers, ray_address=ray_address, chunk=chunk,
                          progress=progress)
