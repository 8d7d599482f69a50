"""What training and inference share: input encoding, network construction, device choice.

Every corpus row is encoded once as tensors: the standardised observations (N, d_o), the
encoded actions (N, d_a_in), a table of history-step features (N + 1, F) whose last row is the
zero padding, and the history index (N, L) into that table. A mini-batch is then three gathers,
so there is no Python work per sample. Both :mod:`aoc_cli.belief.train` (which writes a model)
and :mod:`aoc_cli.belief.artefact` (which loads one) import from here, not from each other.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from aoc_cli.belief.config import BeliefConfig
from aoc_cli.belief.model import BeliefNet, Encoder
from aoc_cli.errors import BadSetting, param


def history_index(episode_starts: np.ndarray, n_rows: int, length: int) -> np.ndarray:
    """(N, L) int64: row of each history step, or N (the padding row) before the episode."""
    rows = np.arange(n_rows, dtype=np.int64)
    start = np.repeat(episode_starts[:-1], np.diff(episode_starts))
    idx = rows[:, None] - length + np.arange(length)[None, :]
    return np.where(idx >= start[:, None], idx, n_rows)


@dataclass
class CorpusInputs:
    """Every corpus row, encoded once (see the module docstring)."""

    obs: torch.Tensor           # (N, d_o)
    act: torch.Tensor | None    # (N, d_a_in), None in imitation mode
    table: torch.Tensor | None  # (N + 1, F), None when L = 0
    hist: torch.Tensor | None   # (N, L) int64

    def batch(self, rows: torch.Tensor):
        """Inputs of ``rows`` (B,): obs (B, d_o), act (B, d_a_in) or None, steps (B, L, F)."""
        act = None if self.act is None else self.act[rows]
        steps = None if self.table is None else self.table[self.hist[rows]]
        return self.obs[rows], act, steps


def encode_corpus(corpus, encoder: Encoder, history_length: int, use_action: bool,
                  device: torch.device) -> CorpusInputs:
    """Encode every row of ``corpus`` for the network."""
    observations = corpus.observations
    actions = corpus.actions
    n = len(observations)
    obs = encoder.observations(observations)
    act_all = encoder.actions(actions)
    table = hist = None
    if history_length > 0:
        rewards = corpus.rewards
        rew = encoder.rewards(np.zeros(n, np.float32) if rewards is None else rewards)
        ones = torch.ones((n, 1), dtype=torch.float32, device=device)
        table = torch.cat([obs, act_all, rew, ones], dim=1)
        table = torch.cat([table, torch.zeros((1, table.shape[1]), device=device)], dim=0)
        hist = torch.as_tensor(history_index(corpus.episode_starts, n, history_length),
                               device=device)
    return CorpusInputs(obs, act_all if use_action else None, table, hist)


def pick_device(name: str) -> torch.device:
    if name == "cuda" or (name == "auto" and torch.cuda.is_available()):
        if not torch.cuda.is_available():
            raise BadSetting("device", "cuda", f"{param('device', 'cuda')} asked for, but torch "
                             f"sees no GPU: use {param('device', 'cpu')}")
        return torch.device("cuda")
    return torch.device("cpu")


def network_dims(corpus, mode: str) -> dict:
    """The network's input and output sizes for ``corpus`` in ``mode`` (value|imitation)."""
    discrete = corpus.discrete
    d_a = corpus.action_dim
    d_a_in = corpus.n_actions if discrete else d_a
    if mode == "value":
        out = 1
    else:
        out = corpus.n_actions if discrete else d_a
    return {"observation": corpus.observation_dim, "action": d_a, "action_input": d_a_in,
            "discrete": discrete, "n_actions": corpus.n_actions, "output": out,
            "use_action": mode == "value"}


def build_net(dims: dict, config: BeliefConfig) -> BeliefNet:
    """The belief network of ``dims`` (:func:`network_dims`) and ``config``, untrained."""
    return BeliefNet(dims["observation"], dims["action_input"], dims["output"],
                     config.history_length, hidden=config.hidden,
                     belief_dim=config.belief_dim, use_action=dims["use_action"],
                     belief_activation=config.belief_activation, dropout=config.dropout,
                     seed=config.seed,
                     dynamics_dim=dims.get("dynamics", 0))
