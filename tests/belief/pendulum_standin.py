"""A small numpy stand-in for pendulum-het, used only while ``aoc_cli.envs.collect`` is absent.

Gymnasium's Pendulum-v1 equations (dt 0.05, g 10, m = l = 1, |u| <= 2, |theta_dot| <= 8) in two
systems, *normal* and *converse* (the applied torque is the negated command), vectorised over
episodes. Behaviour: energy swing-up plus a PD balancer, good in its own system, with Gaussian
action noise of std 0, 0.5, 1 or 2, and purely random torques; half of the episodes per system.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.store import CorpusData, box_space, episode_starts_from_lengths


def _angle_normalize(x):
    return ((x + np.pi) % (2 * np.pi)) - np.pi


def pendulum_het(episodes: int, horizon: int = 200, seed: int = 0) -> CorpusData:
    rng = np.random.default_rng(seed)
    sign = np.where(np.arange(episodes) % 2 == 0, 1.0, -1.0)          # system of each episode
    policy = rng.integers(0, 5, episodes)                             # 0-3 noise levels, 4 random
    noise = np.array([0.0, 0.5, 1.0, 2.0, 0.0])[policy]
    theta = rng.uniform(-np.pi, np.pi, episodes)
    theta_dot = rng.uniform(-1, 1, episodes)
    obs = np.empty((horizon, episodes, 3), np.float32)
    act = np.empty((horizon, episodes), np.float32)
    rew = np.empty((horizon, episodes))
    for t in range(horizon):
        obs[t] = np.stack([np.cos(theta), np.sin(theta), theta_dot], 1)
        th = _angle_normalize(theta)
        energy = 0.5 * theta_dot ** 2 + 15.0 * (np.cos(theta) - 1.0)
        pump = np.clip(0.3 * theta_dot * -energy, -2, 2)
        balance = np.clip(-(11.0 * th + 2.5 * theta_dot), -2, 2)
        u = np.where(np.abs(th) < 0.8, balance, pump) * sign
        u = np.where(policy == 4, rng.uniform(-2, 2, episodes),
                     u + noise * rng.standard_normal(episodes))
        u = np.clip(u, -2, 2).astype(np.float32)
        act[t] = u
        applied = sign * u
        rew[t] = -(th ** 2 + 0.1 * theta_dot ** 2 + 0.001 * applied ** 2)
        theta_dot = np.clip(theta_dot + (15.0 * np.sin(theta) + 3.0 * applied) * 0.05, -8, 8)
        theta = theta + theta_dot * 0.05
    n = episodes * horizon
    starts = episode_starts_from_lengths(np.full(episodes, horizon))
    truncations = np.zeros(n, bool)
    truncations[starts[1:] - 1] = True
    return CorpusData(
        observations=obs.transpose(1, 0, 2).reshape(n, 3),
        actions=act.T.reshape(n, 1),
        rewards=rew.T.reshape(n),
        terminals=np.zeros(n, bool), truncations=truncations, episode_starts=starts,
        observation_space=box_space(3, [-1, -1, -8], [1, 1, 8]),
        action_space=box_space(1, -2, 2),
        tags={"system": (np.repeat((sign < 0).astype(np.int32), horizon), ["normal", "converse"])},
    )
