"""A small pendulum-het corpus with a value model, a bc model and an index, shared by the
baseline tests (built once per test session and worker)."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def pendulum(tmp_path_factory):
    """(store root, corpus) of 2000 pendulum-het rows, models 'default' and 'bc', index."""
    import torch

    from aoc_cli.belief import BeliefConfig, train_model
    from aoc_cli.envs import collect
    from aoc_cli.index import build_index
    from aoc_cli.store import Store

    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("baselines") / "store"
    store = Store.open(root)
    data, _ = collect("pendulum-het", steps=2000, seed=3)
    corpus = store.write("pend", data)
    small = dict(max_epochs=2, patience=1, threads=1, hidden=32, belief_dim=6)
    train_model(corpus, BeliefConfig(**small), "default")
    train_model(corpus, BeliefConfig(mode="imitation", **small), "bc")
    build_index(corpus, "default")
    return root, corpus


@pytest.fixture
def session(pendulum):
    from aoc_cli.experiments.common import session as make_session
    from aoc_cli.envs import make_env

    _root, corpus = pendulum
    env = make_env("pendulum-het")
    return make_session(corpus, env, seed=0), env


def replay_history(corpus, row: int, length: int):
    """The control-time history of corpus row ``row``, rebuilt step by step with the
    controller's HistoryBuffer (as a rollout would)."""
    from aoc_cli.control import HistoryBuffer

    ep = int(corpus.episode_of([row])[0])
    start = int(corpus.episode_starts[ep])
    buf = HistoryBuffer(length, corpus.observation_dim, corpus.action_dim, corpus.discrete)
    obs, act, rew = corpus.observations, corpus.actions, corpus.rewards
    for t in range(start, row):
        buf.push(obs[t], act[t], float(rew[t]))
    return buf.history()


@pytest.fixture
def rng():
    return np.random.default_rng(0)
