"""Raw (belief-free) features of a decision: standardised o, a and the flattened history.

The nearest-neighbour controllers on raw features, the MPC dynamics model and the offline RL
agents all see the same context as the belief model: the observation, the action (where it is
an input), and the previous L transitions (o, a, r) of the episode, zero-padded with a mask.
Every part is standardised with the corpus's own statistics, so no dimension dominates a
Euclidean distance by its units:

    x(o, a, h) = [ (o - mu_o) / s_o,  (a - mu_a) / s_a,
                   for each of the L history steps: m * ((o' - mu_o) / s_o, (a' - mu_a) / s_a,
                                                         (r' - mu_r) / s_r),  m ]

with m the step's mask (0 on padding). Discrete actions are one-hot instead of standardised.
Shapes: (Q, D) with D = d_o [+ d_a] + L (d_o + d_a + 2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from aoc_cli.store import History, gather_history

_FLOOR = 1e-6


def _stats(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=np.float64).reshape(len(x), -1)
    mean, std = x.mean(axis=0), x.std(axis=0)
    return mean, np.where(std > _FLOOR, std, 1.0)


@dataclass
class RawFeatures:
    """The corpus's standardisation and the feature map ``x(o, a, h)`` (module docstring)."""

    obs_mean: np.ndarray
    obs_std: np.ndarray
    act_mean: np.ndarray | None     # None for discrete actions (one-hot)
    act_std: np.ndarray | None
    rew_mean: float
    rew_std: float
    history_length: int
    discrete: bool
    n_actions: int | None
    with_action: bool = True

    @classmethod
    def fit(cls, corpus, history_length: int, with_action: bool = True) -> "RawFeatures":
        """Statistics of ``corpus``'s observations, actions and rewards."""
        o_mean, o_std = _stats(corpus.observations)
        a_mean = a_std = None
        if not corpus.discrete:
            a_mean, a_std = _stats(corpus.actions)
        rewards = corpus.rewards
        r_mean, r_std = (np.zeros(1), np.ones(1)) if rewards is None else _stats(rewards)
        return cls(o_mean, o_std, a_mean, a_std, float(r_mean[0]), float(r_std[0]),
                   int(history_length), bool(corpus.discrete), corpus.n_actions, with_action)

    @property
    def action_width(self) -> int:
        return int(self.n_actions) if self.discrete else len(self.act_mean)

    @property
    def dim(self) -> int:
        """D, the width of a feature row."""
        d_o, d_a = len(self.obs_mean), self.action_width
        return d_o + (d_a if self.with_action else 0) + self.history_length * (d_o + d_a + 2)

    def observations(self, obs) -> np.ndarray:
        """(..., d_o) -> standardised (..., d_o)."""
        return (np.asarray(obs, np.float64) - self.obs_mean) / self.obs_std

    def actions(self, act) -> np.ndarray:
        """(..., d_a) raw, or (...) int when discrete -> (..., d_a) standardised or one-hot."""
        if self.discrete:
            idx = np.asarray(act, np.int64).reshape(np.shape(act)[:np.ndim(act)])
            return np.eye(int(self.n_actions))[idx]
        act = np.asarray(act, np.float64)
        if act.ndim == 0 or act.shape[-1] != len(self.act_mean):
            act = act[..., None]
        return (act - self.act_mean) / self.act_std

    def context(self, history: History) -> np.ndarray:
        """History (R, L, ...) -> (R, L (d_o + d_a + 2)) flattened, standardised, masked steps."""
        r = len(history.mask)
        if self.history_length == 0:
            return np.zeros((r, 0))
        L = self.history_length
        obs, act, rew, mask = (np.asarray(x)[:, -L:] for x in history)
        m = mask.astype(np.float64)[..., None]
        rew = ((np.asarray(rew, np.float64) - self.rew_mean) / self.rew_std)[..., None]
        steps = np.concatenate([self.observations(obs), self.actions(act), rew], axis=-1) * m
        return np.concatenate([steps, m], axis=-1).reshape(r, -1)

    def transform(self, observations, actions, history: History | None) -> np.ndarray:
        """Observations (Q, d_o), actions (Q, d_a) or (Q,) int (ignored without
        ``with_action``), histories of Q rows or of 1 row (broadcast) -> (Q, D) float32."""
        obs = self.observations(np.asarray(observations).reshape(-1, len(self.obs_mean)))
        q = len(obs)
        parts = [obs]
        if self.with_action:
            act = self.actions(actions)
            act = act.reshape(-1, self.action_width)
            q = max(q, len(act))
            parts.append(act)
        if self.history_length:
            parts.append(self.context(history))
        out = np.empty((q, self.dim), np.float32)
        col = 0
        for p in parts:
            out[:, col:col + p.shape[1]] = p  # broadcasts one-row parts over the Q rows
            col += p.shape[1]
        return out

    def corpus_features(self, corpus, batch: int = 200_000) -> np.ndarray:
        """(N, D) float32 features of every corpus row: its own o, a and history."""
        n = corpus.n_rows
        out = np.empty((n, self.dim), np.float32)
        observations, actions, rewards = corpus.observations, corpus.actions, corpus.rewards
        starts = corpus.episode_starts
        start_of = np.repeat(starts[:-1], np.diff(starts))
        for i in range(0, n, batch):
            rows = np.arange(i, min(n, i + batch))
            hist = gather_history(rows, start_of[rows], self.history_length, observations,
                                  actions, rewards) if self.history_length else None
            out[rows] = self.transform(observations[rows], actions[rows], hist)
        return out
