"""Small synthetic corpora with known structure for the belief tests."""

from __future__ import annotations

import numpy as np

from aoc_cli.store import CorpusData, box_space, discrete_space, episode_starts_from_lengths


def _episodes(episodes: int, length: int):
    n = episodes * length
    starts = episode_starts_from_lengths(np.full(episodes, length))
    terminals = np.zeros(n, bool)
    terminals[starts[1:] - 1] = True
    return n, starts, terminals


def known_value(o: np.ndarray, a: np.ndarray) -> np.ndarray:
    """(N,) v = sin(2 o_0) + o_1 a_0 + 0.5 a_0^2 - 0.5 o_2."""
    return np.sin(2 * o[:, 0]) + o[:, 1] * a[:, 0] + 0.5 * a[:, 0] ** 2 - 0.5 * o[:, 2]


def synthetic_value(episodes: int = 60, length: int = 50, seed: int = 0,
                    rewards: bool = True) -> CorpusData:
    """Continuous corpus whose column ``v`` is :func:`known_value` of (o, a)."""
    rng = np.random.default_rng(seed)
    n, starts, terminals = _episodes(episodes, length)
    obs = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    act = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
    return CorpusData(
        observations=obs, actions=act,
        rewards=rng.standard_normal(n) if rewards else None,
        terminals=terminals, truncations=np.zeros(n, bool), episode_starts=starts,
        observation_space=box_space(3), action_space=box_space(1, -1, 1),
        columns={"v": known_value(obs, act), "broken": np.where(np.arange(n) == 7, np.nan, 1.0)},
    )


def discrete_imitation(episodes: int = 60, length: int = 50, seed: int = 0) -> CorpusData:
    """Reward-free corpus whose action (of 3) is a noisy function of the observation; class 0
    is the majority (about half of the rows)."""
    rng = np.random.default_rng(seed)
    n, starts, terminals = _episodes(episodes, length)
    obs = rng.standard_normal((n, 4)).astype(np.float32)
    act = np.where(obs[:, 0] > 0, 0, np.where(obs[:, 1] > 0, 1, 2))
    flip = rng.random(n) < 0.05
    act = np.where(flip, rng.integers(0, 3, n), act).astype(np.int64)
    return CorpusData(
        observations=obs, actions=act, rewards=None,
        terminals=terminals, truncations=np.zeros(n, bool), episode_starts=starts,
        observation_space=box_space(4), action_space=discrete_space(3),
    )


def continuous_imitation(episodes: int = 60, length: int = 50, seed: int = 0) -> CorpusData:
    """Reward-free corpus whose 2-d action is a smooth function of the observation."""
    rng = np.random.default_rng(seed)
    n, starts, terminals = _episodes(episodes, length)
    obs = rng.standard_normal((n, 3)).astype(np.float32)
    act = np.stack([np.tanh(obs[:, 0] - obs[:, 1]), 0.5 * obs[:, 2] ** 2], 1).astype(np.float32)
    return CorpusData(
        observations=obs, actions=act, rewards=None,
        terminals=terminals, truncations=np.zeros(n, bool), episode_starts=starts,
        observation_space=box_space(3), action_space=box_space(2),
    )


def history_dependent(episodes: int = 80, length: int = 40, seed: int = 0) -> CorpusData:
    """Discrete-action corpus with rewards where the value depends on the previous action
    only (v = reward = previous action's one-hot weight): no (o, a) alone can predict it."""
    rng = np.random.default_rng(seed)
    n, starts, terminals = _episodes(episodes, length)
    obs = rng.standard_normal((n, 2)).astype(np.float32)
    act = rng.integers(0, 3, n).astype(np.int64)
    prev = np.concatenate([[0], act[:-1]])
    first = np.zeros(n, bool)
    first[starts[:-1]] = True
    reward = np.where(first, 0.0, np.array([-1.0, 0.0, 2.0])[prev])
    return CorpusData(
        observations=obs, actions=act, rewards=reward,
        terminals=terminals, truncations=np.zeros(n, bool), episode_starts=starts,
        observation_space=box_space(2), action_space=discrete_space(3),
    )


def hidden_system(episodes: int = 80, length: int = 30, seed: int = 0) -> CorpusData:
    """Two systems, hidden per episode: x' = 0.8 x + s a with s = +1 or -1 (tag ``system``).
    The value column ``v = s (1 + a)`` rewards actions aligned with the system, so only the
    history (how x moved under the previous actions) tells a good action from a bad one.
    The rewards are noise: they say nothing about s."""
    rng = np.random.default_rng(seed)
    n, starts, terminals = _episodes(episodes, length)
    s = np.where(np.arange(episodes) % 2 == 0, 1.0, -1.0)
    x = rng.uniform(-1, 1, episodes)
    obs = np.empty((length, episodes), np.float32)
    act = rng.uniform(-1, 1, (length, episodes)).astype(np.float32)
    for t in range(length):
        obs[t] = x
        x = 0.8 * x + s * act[t]
    system = np.repeat((s < 0).astype(np.int32), length)
    actions = act.T.reshape(n, 1)
    return CorpusData(
        observations=obs.T.reshape(n, 1), actions=actions, rewards=rng.standard_normal(n),
        terminals=terminals, truncations=np.zeros(n, bool), episode_starts=starts,
        observation_space=box_space(1), action_space=box_space(1, -1, 1),
        tags={"system": (system, ["plus", "minus"])},
        columns={"v": np.repeat(s, length) * (1.0 + actions[:, 0])},
    )
