"""The belief network b and its linear head l, and the input encoding they share.

Shapes: Q rows, L = history length, d_o observation dims, d_a action dims (continuous) or
n actions (discrete, one-hot: d_a_in = n), F = d_o + d_a_in + 2 features per history step
(observation, action, reward, mask), d_b belief dims.

    steps (Q, L, F) --GRU(hidden)--> g (Q, hidden)            (absent when L = 0)
    [g, o (Q, d_o), a (Q, d_a_in)]   (a only in value mode)
        --fc1-relu--> (Q, hidden) --fc2-relu--> (Q, hidden) --fc3-act--> belief (Q, d_b)
    belief --head (linear)--> (Q, out): standardised value (1), standardised action (d_a)
                                        or action logits (n)
    belief --dynamics (linear)--> (Q, d_o): standardised o' - o (value mode, training only;
                                            absent when the dynamics weight is 0)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

_STD_FLOOR = 1e-6


def _stats(x: np.ndarray) -> tuple[list[float], list[float]]:
    x = np.asarray(x, dtype=np.float64)
    mean = x.mean(axis=0)
    std = x.std(axis=0)
    std = np.where(std > _STD_FLOOR, std, 1.0)
    return np.atleast_1d(mean).tolist(), np.atleast_1d(std).tolist()


@dataclass
class Normalisation:
    """Standardisation learned from the corpus and saved with the model (config.json)."""

    observation_mean: list[float]
    observation_std: list[float]
    action_mean: list[float] | None      # None for discrete actions (one-hot instead)
    action_std: list[float] | None
    reward_mean: float
    reward_std: float
    target_mean: list[float] | None      # value mode: (1,); continuous imitation: (d_a,)
    target_std: list[float] | None

    @classmethod
    def fit(cls, observations, actions, rewards, discrete: bool, targets=None) -> "Normalisation":
        """Statistics of (N, d_o) observations, (N, d_a) actions, (N,) rewards (or None) and
        (N,) or (N, k) regression targets (None for classification)."""
        o_mean, o_std = _stats(observations)
        a_mean = a_std = None
        if not discrete:
            a_mean, a_std = _stats(actions)
        r_mean, r_std = ([0.0], [1.0]) if rewards is None else _stats(rewards)
        t_mean = t_std = None
        if targets is not None:
            t = np.asarray(targets, dtype=np.float64)
            t_mean, t_std = _stats(t.reshape(len(t), -1))
        return cls(o_mean, o_std, a_mean, a_std, r_mean[0], r_std[0], t_mean, t_std)

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    @classmethod
    def from_dict(cls, data: dict) -> "Normalisation":
        return cls(**data)


class Encoder:
    """Turns raw numpy/torch inputs into the network's standardised float32 tensors."""

    def __init__(self, norm: Normalisation, discrete: bool, n_actions: int | None,
                 device: torch.device):
        self.norm = norm
        self.discrete = discrete
        self.n_actions = n_actions
        self.device = device

        def t(x):
            return None if x is None else torch.tensor(x, dtype=torch.float32, device=device)

        self.o_mean, self.o_std = t(norm.observation_mean), t(norm.observation_std)
        self.a_mean, self.a_std = t(norm.action_mean), t(norm.action_std)
        self.t_mean, self.t_std = t(norm.target_mean), t(norm.target_std)

    def _tensor(self, x, dtype=torch.float32) -> torch.Tensor:
        return torch.as_tensor(np.asarray(x), device=self.device).to(dtype)

    def observations(self, obs) -> torch.Tensor:
        """(..., d_o) raw -> (..., d_o) standardised."""
        return (self._tensor(obs) - self.o_mean) / self.o_std

    def actions(self, act) -> torch.Tensor:
        """(..., d_a) raw, or (...) int when discrete -> (..., d_a_in)."""
        if self.discrete:
            idx = self._tensor(act, torch.int64)
            return nn.functional.one_hot(idx, self.n_actions).to(torch.float32)
        return (self._tensor(act) - self.a_mean) / self.a_std

    def rewards(self, rew) -> torch.Tensor:
        """(...) raw -> (..., 1) standardised."""
        return ((self._tensor(rew) - self.norm.reward_mean) / self.norm.reward_std)[..., None]

    def steps(self, obs, act, rew, mask) -> torch.Tensor:
        """History (Q, L, ...) -> (Q, L, F) step features, all zero where mask is false."""
        m = self._tensor(mask)[..., None]
        feats = torch.cat([self.observations(obs), self.actions(act), self.rewards(rew), m],
                          dim=-1)
        return feats * m

    def targets(self, y) -> torch.Tensor:
        """Regression targets (Q,) or (Q, k) raw -> (Q, k) standardised."""
        y = self._tensor(y)
        if y.ndim == 1:
            y = y[:, None]
        return (y - self.t_mean) / self.t_std

    def untarget(self, z: torch.Tensor) -> torch.Tensor:
        """(Q, k) standardised head output -> original units."""
        return z * self.t_std + self.t_mean


class SeededDropout(nn.Module):
    """Dropout whose masks come from its own generator (seeded), so a training run is
    repeatable whatever else drew from torch's global generator; identity in eval mode."""

    def __init__(self, p: float, seed: int = 0):
        super().__init__()
        self.p = float(p)
        self.generator = torch.Generator().manual_seed(int(seed))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.training or self.p == 0.0:
            return x
        keep = torch.rand(x.shape, generator=self.generator).to(x.device) >= self.p
        return x * keep / (1.0 - self.p)


class BeliefNet(nn.Module):
    """b (GRU over the history, then three fully connected layers) and the linear head l."""

    def __init__(self, d_o: int, d_a_in: int, out_dim: int, history_length: int,
                 hidden: int = 128, belief_dim: int = 20, use_action: bool = True,
                 belief_activation: str = "tanh", dynamics_dim: int = 0,
                 dropout: float = 0.0, seed: int = 0):
        super().__init__()
        self.history_length = int(history_length)
        self.use_action = bool(use_action)
        step_dim = d_o + d_a_in + 2
        self.gru = nn.GRU(step_dim, hidden, num_layers=1, batch_first=True) \
            if self.history_length > 0 else None
        joined = (hidden if self.gru is not None else 0) + d_o + (d_a_in if use_action else 0)
        self.fc1 = nn.Linear(joined, hidden)
        self.fc2 = nn.Linear(hidden, hidden)
        self.fc3 = nn.Linear(hidden, belief_dim)
        self.head = nn.Linear(belief_dim, out_dim)
        #: Auxiliary linear head b -> next-observation change; used by training only.
        self.dynamics = nn.Linear(belief_dim, dynamics_dim) if dynamics_dim > 0 else None
        self.belief_activation = torch.tanh if belief_activation == "tanh" else torch.relu
        #: Dropout after fc1 and fc2 (active in training mode only; no parameters).
        self.drop = SeededDropout(dropout, seed) if dropout > 0 else nn.Identity()

    def belief(self, obs: torch.Tensor, act: torch.Tensor | None,
               steps: torch.Tensor | None) -> torch.Tensor:
        """obs (Q, d_o), act (Q, d_a_in) or None, steps (Q, L, F) -> belief (Q, d_b)."""
        return self.belief_from_memory(self.memory(steps), obs, act)

    def memory(self, steps: torch.Tensor | None) -> torch.Tensor | None:
        """The GRU's summary of histories: steps (R, L, F) -> (R, hidden); None when L = 0."""
        if self.gru is None:
            return None
        _, h_n = self.gru(steps)
        return h_n[-1]

    def belief_from_memory(self, memory: torch.Tensor | None, obs: torch.Tensor,
                           act: torch.Tensor | None) -> torch.Tensor:
        """The belief given the history summary (Q, hidden) (or None), obs (Q, d_o) and act
        (Q, d_a_in): a control step summarises its one history once and broadcasts it to the
        K candidates."""
        parts = [] if memory is None else [memory]
        parts.append(obs)
        if self.use_action:
            parts.append(act)
        x = self.drop(torch.relu(self.fc1(torch.cat(parts, dim=-1))))
        x = self.drop(torch.relu(self.fc2(x)))
        return self.belief_activation(self.fc3(x))

    def forward(self, obs, act, steps) -> tuple[torch.Tensor, torch.Tensor]:
        """-> (belief (Q, d_b), head output (Q, out))."""
        b = self.belief(obs, act, steps)
        return b, self.head(b)
