"""Writers of small source datasets in every format, with the expected corpus beside them."""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import h5py
import numpy as np


@dataclass
class Expected:
    """What the corpus must hold: rows (N, ...) in episode order and episode offsets."""

    observations: np.ndarray
    actions: np.ndarray
    rewards: np.ndarray
    terminals: np.ndarray
    truncations: np.ndarray
    episode_starts: np.ndarray

    @property
    def returns(self) -> np.ndarray:
        return np.add.reduceat(self.rewards, self.episode_starts[:-1])


def flat_arrays(n=400, d_o=5, d_a=2, seed=0, ends=((49, "t"), (149, "o"), (299, "t"))):
    """D4RL-style arrays: terminals/timeouts at the given rows; the rest is a trailing
    episode with neither flag (kept, truncated)."""
    rng = np.random.default_rng(seed)
    terminals = np.zeros(n, bool)
    timeouts = np.zeros(n, bool)
    for row, kind in ends:
        (terminals if kind == "t" else timeouts)[row] = True
    arrays = dict(
        observations=rng.standard_normal((n, d_o)).astype(np.float32),
        actions=rng.uniform(-1, 1, (n, d_a)).astype(np.float32),
        rewards=rng.standard_normal(n),
        terminals=terminals,
        timeouts=timeouts,
    )
    stops = sorted(r + 1 for r, _ in ends)
    starts = np.array([0] + stops + ([n] if stops[-1] != n else []), np.int64)
    trunc = timeouts.copy()
    trunc[-1] |= not (terminals[-1] or timeouts[-1])
    expected = Expected(arrays["observations"], arrays["actions"], arrays["rewards"],
                        terminals, trunc, starts)
    return arrays, expected


def write_d4rl(path, arrays, infos=None):
    with h5py.File(path, "w") as f:
        for k, v in arrays.items():
            f.create_dataset(k, data=v)
        f.create_dataset("next_observations", data=np.roll(arrays["observations"], -1, 0))
        for k, v in (infos or {}).items():
            f.create_dataset(f"infos/{k}", data=v)
    return path


def write_d3rlpy(path, episodes, tuple_obs=False):
    """A d3rlpy 2.x ReplayBuffer dump: episodes = [(obs (T, d_o), act, rew (T,), terminated)]."""
    with h5py.File(path, "w") as f:
        f.create_dataset("columns", data=["observations", "actions", "rewards", "terminated"])
        f.create_dataset("num_episodes", data=len(episodes))
        for i, (o, a, r, term) in enumerate(episodes):
            if tuple_obs:
                f.create_dataset(f"observations_{i}_0", data=o[:, :2])
                f.create_dataset(f"observations_{i}_1", data=o[:, 2:])
            else:
                f.create_dataset(f"observations_{i}", data=o)
            f.create_dataset(f"actions_{i}", data=a)
            f.create_dataset(f"rewards_{i}", data=r.reshape(-1, 1))
            f.create_dataset(f"terminated_{i}", data=np.float32(term))
        f.create_dataset("version", data="2.1")
    return path


def d3rlpy_episodes(lengths=(7, 12, 5), d_o=4, discrete=False, seed=0):
    rng = np.random.default_rng(seed)
    eps = []
    for i, t in enumerate(lengths):
        o = rng.standard_normal((t, d_o)).astype(np.float32)
        a = rng.integers(0, 3, (t, 1)).astype(np.int32) if discrete else \
            rng.uniform(-1, 1, (t, 2)).astype(np.float32)
        eps.append((o, a, rng.standard_normal(t).astype(np.float32), i % 2 == 0))
    return eps


def write_minari(dataset_id, lengths=(6, 9, 4), dict_obs=True, discrete=True, seed=0,
                 infos=False):
    """A Minari dataset written by minari's own create_dataset_from_buffers into
    $MINARI_DATASETS_PATH; returns (dataset, per-episode buffers as written)."""
    import gymnasium as gym
    import minari
    from minari.data_collector import EpisodeBuffer

    rng = np.random.default_rng(seed)
    if dict_obs:  # keys deliberately given out of sorted order
        obs_space = gym.spaces.Dict({"vel": gym.spaces.Box(-5, 5, (1,), np.float32),
                                     "pos": gym.spaces.Box(-5, 5, (2,), np.float32)})
    else:
        obs_space = gym.spaces.Box(-5, 5, (3,), np.float32)
    act_space = gym.spaces.Discrete(3) if discrete else gym.spaces.Box(-1, 1, (2,), np.float32)
    buffers = []
    for i, t in enumerate(lengths):
        if dict_obs:
            obs = {"vel": rng.uniform(-5, 5, (t + 1, 1)).astype(np.float32),
                   "pos": rng.uniform(-5, 5, (t + 1, 2)).astype(np.float32)}
        else:
            obs = rng.uniform(-5, 5, (t + 1, 3)).astype(np.float32)
        act = rng.integers(0, 3, t) if discrete else rng.uniform(-1, 1, (t, 2)).astype(np.float32)
        term = [False] * t
        trunc = [False] * t
        (term if i % 2 == 0 else trunc)[-1] = True
        info = {"policy": np.array([i % 2] * (t + 1))} if infos else {}
        buffers.append(EpisodeBuffer(id=i, observations=obs, actions=act,
                                     rewards=list(rng.standard_normal(t)), terminations=term,
                                     truncations=trunc, infos=info))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = minari.create_dataset_from_buffers(dataset_id, buffers, observation_space=obs_space,
                                                action_space=act_space, algorithm_name="test")
    return ds, buffers


def write_csv(path, header, rows):
    with open(path, "w") as fh:
        fh.write(",".join(header) + "\n")
        for r in rows:
            fh.write(",".join(str(x) for x in r) + "\n")
    return path
