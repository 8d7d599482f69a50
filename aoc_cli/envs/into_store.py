"""A built-in task's behaviour policies run into a corpus of the store: the whole job of
``aoc collect`` (the checks of the request, one writer per corpus, the existence check, one
process or independently seeded chunks on Ray workers, the write), as
:func:`aoc_cli.formats.ingest` is the whole job of ``aoc ingest``. Ward's CSV form
(:func:`collect_csv`) writes the two files of a real log instead of a corpus."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from aoc_cli.envs import TASKS, collect, get_task
from aoc_cli.envs.base import Task
from aoc_cli.envs.chunked import CHUNK_EPISODES, CHUNK_STEPS, collect_chunked
from aoc_cli.errors import AocError, BadSetting, call, param
from aoc_cli.progress import Progress
from aoc_cli.store import Corpus, Store, check_name, writing_corpus
from aoc_cli.store.paths import check_output


@dataclass
class Collected:
    """What a collect wrote: the corpus and one summary row per behaviour policy (with its
    ``chunk`` and ``seed`` when collected in chunks)."""

    task: str
    seed: int
    corpus: Corpus
    summary: list[dict]


def check_request(task: str | None, name: str | None, *, steps: int | None = None,
                  episodes: int | None = None, behaviour: str = "mix",
                  policy: str | None = None, workers: int | None = None,
                  chunk: int | None = None) -> Task:
    """The task of a collect request, once the request is checked (a known task and
    behaviour, a policy the task lets one choose, a corpus name, positive counts, rows or
    episodes but not both); else an AocError."""
    if task is None:
        raise BadSetting("task", None, f"{param('task')} must name a built-in task: one of "
                         f"{', '.join(TASKS)}")
    t = get_task(task)
    if behaviour not in t.behaviours:
        raise BadSetting("behaviour", behaviour, f"{param('behaviour')} {behaviour!r}: task "
                         f"{task!r} has {', '.join(t.behaviours)}")
    if policy is not None and not t.extra.get("choose_policy"):
        raise BadSetting("policy", policy, f"{param('policy')}: task {task!r} logs its own mix "
                         f"of policies ({', '.join(t.policies)}); {param('policy')} is for "
                         "icu-sepsis")
    if policy is not None and policy not in t.policies:
        raise BadSetting("policy", policy, f"{param('policy')} {policy!r}: task {task!r} has "
                         f"{' or '.join(t.policies)}")
    if name is None:
        raise AocError(f"give the corpus name: {call('collect', task, name='NAME')}", "name")
    for key, value in (("steps", steps), ("episodes", episodes), ("workers", workers),
                       ("chunk", chunk)):
        if value is not None and value <= 0:
            raise BadSetting(key, value, f"{param(key)} must be a positive integer, got {value}")
    if steps is not None and episodes is not None:
        raise BadSetting("steps", steps, f"give {param('steps')} or {param('episodes')}, not "
                         "both")
    return t


def collect_csv(store: Store, t: Task, folder: str | Path, name: str, *,
                steps: int | None = None, episodes: int | None = None,
                seed: int = 0) -> tuple[Path, Path]:
    """Ward's log as the CSV files ``folder/name.csv`` and ``folder/name-static.csv`` (for
    ``aoc ingest --static``), ``episodes`` stays (default the task's); the two paths."""
    write = t.extra.get("write_csv")
    if write is None:
        raise BadSetting("csv", str(folder), f"{param('csv')}: task {t.name!r} has no CSV form "
                         "(ward has)")
    if steps is not None:
        raise BadSetting("steps", steps, f"{param('csv')} writes whole stays: give "
                         f"{param('episodes')}, not {param('steps')}")
    check_output(folder, "--csv", store.root, folder=True)
    return write(folder, name, episodes or t.default_episodes, seed)


def collect_corpus(store: Store, t: Task, name: str, *, steps: int | None = None,
                   episodes: int | None = None, seed: int = 0, behaviour: str = "mix",
                   policy: str | None = None, overwrite: bool = False,
                   workers: int | None = None, ray_address: str | None = None,
                   chunk: int | None = None, progress: Progress | None = None) -> Collected:
    """Run task ``t``'s behaviour policies for ``steps`` rows (or ``episodes``; neither: the
    task's default) and write corpus ``name`` (``overwrite`` replaces one). One writer per
    corpus; an existing corpus is refused unless ``overwrite``. ``workers`` / ``ray_address``:
    independently seeded chunks of ``chunk`` rows (episodes) as Ray tasks
    (:mod:`aoc_cli.envs.chunked`). Same seed, same corpus."""
    with writing_corpus(store.root, check_name(name)):
        if store.exists(name) and not overwrite:
            raise AocError(f"corpus {name!r} already exists in {store.root}: pass "
                           f"{param('overwrite', True)} to replace it, or choose another "
                           f"{param('name')}")
        if workers is None and ray_address is None:
            if progress is not None:
                progress(0, None, f"collect {t.name}")
            data, summary = collect(t.name, steps=steps, episodes=episodes, seed=seed,
                                    progress=progress, behaviour=behaviour, policy=policy)
        else:
            if progress is not None:
                progress(0, None, f"collect {t.name} in chunks")
            data, summary = collect_chunked(
                t.name, steps, episodes, seed, workers=workers, address=ray_address,
                chunk_steps=chunk or CHUNK_STEPS, chunk_episodes=chunk or CHUNK_EPISODES,
                progress=progress, behaviour=behaviour, policy=policy)
        corpus = store.write(name, data, overwrite=overwrite)
    return Collected(t.name, seed, corpus, summary)
