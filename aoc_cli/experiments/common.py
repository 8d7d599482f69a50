"""What every experiment shares: the run context, sessions, and the scale of a run."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from aoc_cli.belief import BeliefConfig
from aoc_cli.control import ControllerConfig, open_session
from aoc_cli.experiments.methods import Runner
from aoc_cli.experiments.prepare import Artefacts
from aoc_cli.control.episodes import action_space_of
from aoc_cli.envs import make_env
from aoc_cli.store import DEFAULT_INDEX, DEFAULT_MODEL

SCALES = ("tiny", "quick", "full")


@dataclass
class Context:
    """One bench run: where artefacts and outputs go, seeds, progress and log."""

    experiment: str
    scale: str
    out: Path
    artefacts: Artefacts
    runner: Runner
    seeds: list[int]
    episodes: int | None = None          # override of the scale's episodes per setting
    methods: list[str] | None = None     # override of the experiment's methods
    log: object = None
    plots: list[str] = field(default_factory=list)
    #: ControllerConfig overrides for AOC where the experiment does not vary them (--epsilon).
    aoc_config: dict = field(default_factory=dict)

    def say(self, text: str) -> None:
        if self.log is not None:
            self.log(text)

    def n_episodes(self, default: int) -> int:
        return int(self.episodes) if self.episodes else int(default)

    def pick_methods(self, default: list[str]) -> list[str]:
        if not self.methods:
            return list(default)
        return [m for m in self.methods]


def session(corpus, env, model_id: str = DEFAULT_MODEL, index_id: str = DEFAULT_INDEX,
            seed: int = 0, selection=None, **config):
    """An AOC session on ``corpus``: the experiment's ControllerConfig fields ``config`` over
    the paper's defaults (the paper's experiments state their controller)."""
    return open_session(corpus, model_id, index_id, ControllerConfig(**config), selection,
                        seed, action_space_of(env))


def belief_config(scale: dict, mode: str = "value", seed: int = 0, **overrides):
    """The belief model of a scale: the paper's network, the scale's epoch budget, and any
    other BeliefConfig field in ``overrides``."""
    return BeliefConfig(mode=mode, max_epochs=int(scale["epochs"]),
                        patience=int(scale.get("patience", 10)), seed=int(seed),
                        threads=int(scale.get("threads", 1)), **overrides)


def make_task_env(task: str, scale: dict):
    """The task's evaluation environment; a scale's ``max_steps`` shortens its episodes (tiny
    runs only: the paper's horizons otherwise)."""
    if scale.get("max_steps"):
        return make_env(task, max_episode_steps=int(scale["max_steps"]))
    return make_env(task)
