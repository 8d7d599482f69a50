"""Small trained corpora shared by the controller tests (built once per test session)."""

from __future__ import annotations

import numpy as np

from aoc_cli.belief import BeliefConfig, train_model
from aoc_cli.envs import collect
from aoc_cli.index import build_index
from aoc_cli.store import CorpusData, Store, discrete_space, box_space, episode_starts_from_lengths


def maze_store(root) -> Store:
    """A maze corpus (120 trajectories per expert), its value model and index."""
    store = Store(root)
    data, _ = collect("maze", episodes=480, seed=0)
    corpus = store.write("maze", data)
    train_model(corpus, BeliefConfig(seed=0, threads=1, max_epochs=25, patience=5), "default")
    build_index(corpus)
    return store


def pendulum_store(root, steps: int = 40_000) -> Store:
    """A pendulum-het corpus, its value model and index."""
    store = Store(root)
    data, _ = collect("pendulum-het", steps=steps, seed=0)
    corpus = store.write("pend", data)
    train_model(corpus, BeliefConfig(seed=0, threads=1, max_epochs=40, patience=6), "default")
    build_index(corpus)
    return store


def corridor_data(episodes: int = 60, length: int = 12, seed: int = 0) -> CorpusData:
    """A reward-free discrete corpus: position x in [0, 10], the expert steps right (1) below
    5 and left (0) above, so the action is a function of the observation."""
    rng = np.random.default_rng(seed)
    obs, act = [], []
    for _ in range(episodes):
        x = rng.uniform(0, 10)
        for _ in range(length):
            a = int(x < 5)
            obs.append([x, np.sin(x)])
            act.append(a)
            x = np.clip(x + (0.5 if a else -0.5) + rng.normal(0, 0.2), 0, 10)
    n = episodes * length
    starts = episode_starts_from_lengths([length] * episodes)
    term = np.zeros(n, bool)
    return CorpusData(
        observations=np.asarray(obs, np.float32), actions=np.asarray(act), rewards=None,
        terminals=term, truncations=term.copy(), episode_starts=starts,
        observation_space=box_space(2), action_space=discrete_space(2),
    )


def corridor_store(root) -> Store:
    store = Store(root)
    corpus = store.write("corridor", corridor_data())
    train_model(corpus, BeliefConfig(mode="imitation", seed=0, threads=1, max_epochs=30,
                                     patience=5, history_length=2), "default")
    build_index(corpus)
    return store


#: Tag values and episode ids that are markup: pages must show them as text, never run them.
HOSTILE_TAGS = ["<script>alert(1)</script>", '" onload="alert(2)', "c3"]


def hostile_corridor_store(root) -> Store:
    """The corridor corpus with a ``clinician`` tag and episode ids that are markup
    (:data:`HOSTILE_TAGS`, ``<img src=x onerror=alert(3)>``), its imitation model and index."""
    data = corridor_data()
    episodes, length = data.n_episodes, 12
    data.tags = {"clinician": (np.repeat(np.arange(episodes) % 3, length), HOSTILE_TAGS)}
    data.episode_ids = [f"<img src=x onerror=alert(3)>{e}" if e % 2 else f"p{e:02d}"
                        for e in range(episodes)]
    store = Store(root)
    corpus = store.write("corridor", data)
    train_model(corpus, BeliefConfig(mode="imitation", seed=0, threads=1, max_epochs=30,
                                     patience=5, history_length=2), "default")
    build_index(corpus)
    return store
