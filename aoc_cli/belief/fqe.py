"""Fitted Q evaluation of the logged behaviour: a bootstrapped value v^c of every corpus row.

``--value fqe`` (docs/design.md, "The method, precisely"): the value of row c is the
behaviour's action value Q(o^c, a^c), learned from the corpus alone (observations, actions,
rewards and the episode structure) by fitted Q evaluation with expected SARSA targets::

    Q_0 = 0;   Q_{i+1} = argmin_Q  sum_c ( Q(o^c, a^c) - y_i^c )^2,
    y_i^c = r^c + gamma V_i(o^{c+1})              (row c + 1 the next row of c's episode)
    y_i^c = r^c                                   (c the last row of its episode)
    y_i^c = r^c + gamma v_cut,i(e)                (c the cut of a censored stay e)
    V_i(o) = mean of Q_i(o, a^d) over the rows d of the log at observation o

so the backup follows the actions the behaviour took at the next observation: the fixed point
is the behaviour's own Q, with no behaviour model and no propensities. Where no observation
repeats, V_i(o^{c+1}) is the next row's own Q_i(o^{c+1}, a^{c+1}) (SARSA;
``FQEConfig(next_value="logged")`` keeps that everywhere). As the ``return`` target, a logged
episode's end is its end (no bootstrapping past a truncation), except the cut of a stay a
clinical ingest marked censored: v_cut,i(e) is the mean Q_i of the uncensored stays' rows at
the step of the cut (:mod:`aoc_cli.belief.censoring`). Unlike the Monte-Carlo return,
each target averages the next step's value over every row that shares its input, so on a log
whose states repeat (ICU-Sepsis) the noise of one patient's outcome, and of the dose they were
given next, is shared out among all the patients that reached the same state:
docs/results/icu-sepsis.md.

Q is a small MLP on the standardised observation with one output per action (discrete
actions) or on [o, a] with one output (continuous). Rows with the same input are regressed as
one point of weight (their count) on their mean target: the same least-squares problem, much
smaller where inputs repeat, unchanged where they do not.

Hand-written: d3rlpy's FQE / DiscreteFQE evaluate a trained algorithm's greedy policy
(``Q(o', argmax_a pi(o'))``); the target here is the logged behaviour's value at the next
observation, which none of its estimators computes.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from aoc_cli.belief.censoring import cut_values
from aoc_cli.belief.config import FQEConfig
from aoc_cli.errors import BadSetting, param

#: Rows of the forward passes that compute the targets.
_EVAL_BATCH = 65536


def next_rows(episode_starts: np.ndarray, n_rows: int) -> np.ndarray:
    """(N,) int64: the next row of each row's episode, -1 for an episode's last row."""
    starts = np.asarray(episode_starts, dtype=np.int64)
    nxt = np.arange(1, n_rows + 1, dtype=np.int64)
    nxt[starts[1:] - 1] = -1
    return nxt


def _inputs(observations: np.ndarray, actions: np.ndarray, discrete: bool) -> np.ndarray:
    """(N, d) float32 standardised network inputs: o (discrete), [o, a] (continuous)."""
    x = np.asarray(observations, dtype=np.float64).reshape(len(observations), -1)
    if not discrete:
        x = np.concatenate([x, np.asarray(actions, np.float64).reshape(len(x), -1)], axis=1)
    std = x.std(0)
    return ((x - x.mean(0)) / np.where(std > 0, std, 1.0)).astype(np.float32)


def fitted_q_values(observations: np.ndarray, actions: np.ndarray, rewards: np.ndarray,
                    episode_starts: np.ndarray, gamma: float, n_actions: int | None = None,
                    config: FQEConfig | None = None, progress=None,
                    censored: np.ndarray | None = None) -> np.ndarray:
    """(N,) float64 Q(o^c, a^c) of the logged behaviour for every row (module docstring).

    observations (N, d_o); actions (N,) int with ``n_actions`` given (discrete) or (N, d_a);
    rewards (N,); episode_starts (E + 1,). Same inputs and seed, same values (CPU).
    ``progress(done, total, label)`` after each backup; ``censored`` (E,) bool: stays cut
    short, bootstrapped at their cut (None: none).
    """
    config = config or FQEConfig()
    n = len(rewards)
    if n == 0:
        return np.zeros(0)
    if not 0.0 <= gamma <= 1.0:
        raise BadSetting("gamma", gamma, f"{param('gamma')} must be in [0, 1] for "
                         f"{param('value', 'fqe')}, got {gamma}")
    expected = config.next_value == "expected"
    discrete = n_actions is not None
    x = _inputs(observations, actions, discrete)
    act = np.asarray(actions, np.int64).reshape(-1) if discrete else np.zeros(n, np.int64)
    # the distinct inputs (o, a): a row's loss term depends on its input and target only
    key = np.concatenate([x, act[:, None].astype(np.float32)], axis=1)
    uniq, group, count = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    group = group.reshape(-1)
    g_x = torch.from_numpy(np.ascontiguousarray(uniq[:, :-1]))
    g_a = torch.from_numpy(uniq[:, -1].astype(np.int64))
    g_w = torch.from_numpy(count.astype(np.float32))
    nxt = next_rows(episode_starts, n)
    has_next = nxt >= 0
    next_group = group[np.where(has_next, nxt, 0)]
    # the distinct observations o (the first d_o inputs of a group): expected targets' V(o)
    d_o = np.asarray(observations).reshape(n, -1).shape[1]
    _, obs_of_group = np.unique(uniq[:, :d_o], axis=0, return_inverse=True)
    obs_of_group = obs_of_group.reshape(-1)
    obs_count = np.bincount(obs_of_group, weights=count)
    next_obs = obs_of_group[next_group]
    r = np.asarray(rewards, np.float64)

    torch.manual_seed(config.seed)
    generator = torch.Generator().manual_seed(config.seed)
    out = int(n_actions) if discrete else 1
    net = nn.Sequential(nn.Linear(g_x.shape[1], config.hidden), nn.ReLU(),
                        nn.Linear(config.hidden, config.hidden), nn.ReLU(),
                        nn.Linear(config.hidden, out))
    # foreach: the same elementwise updates as the default per-tensor loop, one call for the
    # six tensors (the same values, tests/belief/test_held_out_targets.py): ~8% of a backup
    opt = torch.optim.Adam(net.parameters(), lr=config.lr, foreach=True)
    n_groups = len(uniq)
    steps = max(config.steps, int(np.ceil(2 * n_groups / config.batch_size)))
    q_group = np.zeros(n_groups)
    for it in range(config.iterations):
        if expected:  # V(o') = the rows at o' averaged: sum_g count_g Q_g / count(o')
            following = (np.bincount(obs_of_group, weights=count * q_group) / obs_count)[next_obs]
        else:
            following = q_group[next_group]
        target_rows = r + gamma * np.where(has_next, following, 0.0)
        if censored is not None:  # each censored stay's cut continued by the stays present
            cuts = np.asarray(episode_starts[1:])[censored] - 1
            target_rows[cuts] += gamma * cut_values(q_group[group], episode_starts,
                                                    censored)[censored]
        target = np.bincount(group, weights=target_rows, minlength=n_groups) / count
        y = torch.from_numpy(target.astype(np.float32))
        lr = config.final_lr if it >= config.iterations - config.final_iterations else config.lr
        for g in opt.param_groups:
            g["lr"] = lr
        for _ in range(steps):
            b = torch.randint(n_groups, (min(config.batch_size, n_groups),),
                              generator=generator)
            pred = net(g_x[b]).gather(1, g_a[b, None] if discrete else
                                      torch.zeros((len(b), 1), dtype=torch.int64))[:, 0]
            w = g_w[b]
            loss = (w * (pred - y[b]) ** 2).sum() / w.sum()
            opt.zero_grad()
            loss.backward()
            opt.step()
        q_group = _group_values(net, g_x, g_a, discrete)
        if progress is not None:
            progress(it + 1, config.iterations, "fitted Q evaluation")
    return q_group[group]


def _group_values(net: nn.Module, g_x: torch.Tensor, g_a: torch.Tensor,
                  discrete: bool) -> np.ndarray:
    """(G,) float64 Q of every distinct input."""
    parts = []
    with torch.no_grad():
        for i in range(0, len(g_x), _EVAL_BATCH):
            q = net(g_x[i:i + _EVAL_BATCH])
            parts.append((q.gather(1, g_a[i:i + _EVAL_BATCH, None]) if discrete else q)[:, 0])
    return torch.cat(parts).double().numpy()
