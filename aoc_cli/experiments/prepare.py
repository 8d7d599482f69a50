"""The artefacts an experiment needs, built through the library and reused when they exist.

The bench keeps its own store (default ``bench/store``, ``--bench-store`` to change it), apart
from the user's ``corpora/``. Names say what was built:

* corpus ``<task>-<rows or episodes>-s<seed>`` (e.g. ``pendulum-het-30000r-s0``,
  ``maze-1000e-s0``), collected by ``aoc_cli.envs.collect`` with that seed; reused when its
  manifest records the same task, budget and seed;
* model ``default`` (value mode) and ``bc`` (imitation mode) of a corpus, trained with
  ``aoc_cli.belief.train_model``; reused when the saved config equals the wanted one and the
  corpus hash matches (``load_model`` refuses stale models anyway);
* index ``default`` and derived indexes (e.g. ``pi1x0.5``: ``--episode-rate policy=pi1:0.5``),
  built by ``aoc_cli.index.build_index``; reused when ``load_index`` accepts them and
  they were built with the same rates.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

from aoc_cli.belief import BeliefConfig
from aoc_cli.index import build_index, load_index
from aoc_cli.envs import TASKS, collect, replay
from aoc_cli.errors import AocError
from aoc_cli.progress import stage
from aoc_cli.store import DEFAULT_INDEX, Store, model_dir

#: BeliefConfig fields that do not change the trained model.
_RUNTIME = ("threads", "device")


def corpus_name(task: str, rows: int | None = None, episodes: int | None = None,
                seed: int = 0, behaviour: str = "mix") -> str:
    budget = f"{rows}r" if rows is not None else f"{episodes}e"
    return f"{task}-{budget}-s{seed}" + ("" if behaviour == "mix" else f"-{behaviour}")


def _same_policies(corpus, task: str, behaviour: str = "mix") -> bool:
    """Whether the corpus was collected with the task's current behaviour policies (a corpus
    of an earlier behaviour mix, e.g. other noise levels, is collected again)."""
    known = TASKS.get(task)
    if known is None or "policy" not in corpus.manifest.get("tags", {}):
        return True
    wanted = replay.POLICIES if behaviour == "replay" else known.policies
    return list(corpus.tag("policy")[1]) == list(wanted)


class Artefacts:
    """Builds or reuses corpora, models and indexes in the bench store; logs what it did."""

    def __init__(self, store_root: str | Path, log=None, progress=None,
                 behaviour: str = "mix"):
        self.store = Store.open(store_root)
        #: How the tasks that have one (pendulum-het, lunar) collect their data: ``mix`` or
        #: ``replay`` (``aoc bench --behaviour``; aoc_cli/envs/replay.py).
        self.behaviour = behaviour
        self.log = log or (lambda text: None)
        self.progress = progress
        self.built: list[dict] = []

    def _stage(self, label: str, total: int | None):
        """The Progress of one preparation step (:func:`aoc_cli.progress.stage`)."""
        return stage(self.progress, label, total)

    # -- corpus ----------------------------------------------------------------------------
    def corpus(self, task: str, rows: int | None = None, episodes: int | None = None,
               seed: int = 0):
        behaviour = self.behaviour if self.behaviour in TASKS[task].behaviours else "mix"
        name = corpus_name(task, rows, episodes, seed, behaviour)
        if self.store.exists(name):
            c = self.store.corpus(name)
            src = (c.manifest.get("sources") or [{}])[-1]
            if src.get("task") == task and src.get("seed") == seed and \
                    src.get("steps") == rows and src.get("episodes") == episodes and \
                    src.get("behaviour", "mix") == behaviour and \
                    _same_policies(c, task, behaviour):
                return c
        started = time.perf_counter()
        data, _summary = collect(task, steps=rows, episodes=episodes, seed=seed,
                                 progress=self._stage(f"collect {name}", rows or episodes),
                                 behaviour=behaviour)
        c = self.store.write(name, data, overwrite=True)
        self._record("collect", name, started)
        return c

    # -- models ----------------------------------------------------------------------------
    def model(self, corpus, model_id: str, config: BeliefConfig):
        """Train ``model_id`` with ``config`` unless an identical one exists."""
        from aoc_cli.belief import train_model  # lazy: torch; listing experiments must not

        path = model_dir(corpus.path, model_id) / "config.json"
        if path.is_file():
            meta = json.loads(path.read_text())
            # through BeliefConfig, so a field added since the model was saved takes its default
            known = asdict(BeliefConfig.from_dict(meta.get("config", {}), strict=False))
            # the critic's steps mean nothing to another belief (None since issue 24, 10,000
            # in the configs saved before)
            skip = set(_RUNTIME) | ({"critic_steps"} if config.belief != "critic" else set())
            saved = {k: v for k, v in known.items() if k not in skip}
            wanted = {k: v for k, v in asdict(config).items() if k not in skip}
            if saved == wanted and meta.get("corpus_hash") == corpus.hash:
                return model_id
        started = time.perf_counter()
        train_model(corpus, config, model_id, overwrite=True,
                    progress=self._stage(f"train {corpus.name}/{model_id}", config.max_epochs))
        self._record("train", f"{corpus.name}/{model_id}", started)
        return model_id

    # -- indexes ---------------------------------------------------------------------------
    def index(self, corpus, model_id: str, index_id: str = DEFAULT_INDEX,
              resample: dict | None = None, seed: int = 0):
        try:
            ci = load_index(corpus, model_id, index_id)
            built = ci.meta.get("episode_rates", ci.meta.get("resample")) or {}
            if built == (resample or {}):
                return ci
        except AocError:
            pass
        started = time.perf_counter()
        ci = build_index(corpus, model_id, index_id=index_id, episode_rates=resample, seed=seed)
        self._record("index", f"{corpus.name}/{model_id}/{index_id}", started)
        return ci

    def _record(self, what: str, name: str, started: float) -> None:
        seconds = time.perf_counter() - started
        self.built.append({"step": what, "name": name, "seconds": round(seconds, 2)})
        self.log(f"{what} {name}: {seconds:.1f} s")
