"""The policies of ``aoc bench icu-sepsis`` as state policies, and their values.

A policy that decides from the observation alone (history length 0) is a state policy on
ICU-Sepsis: each live state's 48 numbers are distinct, so deciding every one of the 713 live
states' observation once gives the whole policy, (716,) action indices, valued exactly by a
linear solve over the package's tables (:class:`aoc_cli.envs.tabular.TabularMDP`). A policy that
reads a history is valued by Monte-Carlo rollouts in the package's environment instead, with a
95% interval.

Policies learnt from a log here:

* ``bc`` -- behaviour cloning, tabular: per distinct logged observation, its most frequent
  logged action (what a classifier on the observation converges to); an observation never logged
  takes the action of the nearest logged one (standardised Euclidean distance);
* ``tabular`` -- a reference that is *told the state* (the ``state`` column), as the issue's
  estimators were: transition counts of the log as a model, the logged behaviour's Q in it (one
  linear solve), greedy over the actions logged at least :data:`TABULAR_MIN_COUNT` times in the
  state (the behaviour's modal action elsewhere).
"""

from __future__ import annotations

import numpy as np

from aoc_cli.control import rollout
from aoc_cli.control.episodes import HistoryBuffer
from aoc_cli.envs.icu_sepsis import STATE_DEATH, STATE_SURVIVAL, SepsisTables
from aoc_cli.envs.tabular import TabularMDP, greedy

#: ``tabular``: a (state, action) needs this many logged steps to be chosen.
TABULAR_MIN_COUNT = 10
LIVE = 713
N_STATES = 716


def empty_history(length: int, observation_dim: int):
    """A one-row History of ``length`` steps with nothing in it (an episode's first step)."""
    return HistoryBuffer(length, observation_dim, 1, True).history()


def state_policy(decide, tables: SepsisTables, history_length: int = 0) -> np.ndarray:
    """(716,) int64: ``decide(observation, history)`` on every live state's observation with an
    empty history (terminal states: 0, never used)."""
    obs = tables.observations.astype(np.float32)
    history = empty_history(history_length, obs.shape[1])
    out = np.zeros(len(obs), dtype=np.int64)
    for s in range(LIVE):
        action = decide(obs[s], history)
        action = getattr(action, "action", action)
        out[s] = int(np.asarray(action).reshape(-1)[0])
    return out


def bc_policy(corpus_obs: np.ndarray, corpus_actions: np.ndarray,
              tables: SepsisTables) -> np.ndarray:
    """(716,) the tabular behaviour cloning of the module docstring (reads observations and
    actions only, never the state)."""
    obs = np.ascontiguousarray(corpus_obs, dtype=np.float32)
    uniq, inverse = np.unique(obs, axis=0, return_inverse=True)
    counts = np.zeros((len(uniq), int(tables.clinicians.shape[1])), dtype=np.int64)
    np.add.at(counts, (inverse.reshape(-1), np.asarray(corpus_actions, np.int64)), 1)
    modal = np.argmax(counts, axis=1)
    sd = obs.std(0) + 1e-6
    queries = tables.observations[:LIVE].astype(np.float32)
    d2 = (((queries[:, None, :] - uniq[None, :, :]) / sd) ** 2).sum(-1)   # (713, m)
    out = np.zeros(len(tables.observations), dtype=np.int64)
    out[:LIVE] = modal[np.argmin(d2, axis=1)]
    return out


def log_model(states: np.ndarray, actions: np.ndarray, rewards: np.ndarray,
              terminals: np.ndarray, starts: np.ndarray, n_actions: int = 25
              ) -> tuple[TabularMDP, np.ndarray, np.ndarray]:
    """The log as a tabular MDP: ``(model, behaviour (716, 25), counts (716, 25))``. A step's
    next state is the next row's; an episode's last step goes to survival (reward 1) or death
    (a truncated last step is left out). States never logged are terminal in the model."""
    S = N_STATES
    n = len(states)
    last = np.zeros(n, dtype=bool)
    last[starts[1:] - 1] = True
    nxt = np.empty(n, dtype=np.int64)
    nxt[:-1] = states[1:]
    ends = np.flatnonzero(last)
    nxt[ends] = np.where(rewards[ends] > 0, STATE_SURVIVAL, STATE_DEATH)
    keep = ~last | terminals
    counts3 = np.zeros((S, n_actions, S))
    np.add.at(counts3, (states[keep], actions[keep], nxt[keep]), 1.0)
    counts = counts3.sum(axis=2)
    seen = counts > 0
    P = np.zeros_like(counts3)
    P[seen] = counts3[seen] / counts[seen][:, None]
    P[~seen, STATE_DEATH] = 1.0
    r = P[:, :, STATE_SURVIVAL].copy()
    visited = seen.any(axis=1)
    terminal = ~visited
    r[terminal] = 0.0
    d0 = np.bincount(states[starts[:-1]], minlength=S) / (len(starts) - 1)
    behaviour = np.zeros((S, n_actions))
    behaviour[visited] = counts[visited] / counts[visited].sum(axis=1, keepdims=True)
    return TabularMDP(P, r, d0.astype(np.float64), terminal), behaviour, counts


def tabular_policy(states, actions, rewards, terminals, starts,
                   min_count: int = TABULAR_MIN_COUNT) -> np.ndarray:
    """(716,) the ``tabular`` reference of the module docstring."""
    model, behaviour, counts = log_model(states, actions, rewards, terminals, starts)
    q = model.q_values(behaviour)
    policy = greedy(q, counts >= min_count)
    thin = ~(counts >= min_count).any(axis=1)
    policy[thin] = np.argmax(counts[thin], axis=1)
    return policy


def monte_carlo(policy_decide, session, env, episodes: int, seed: int) -> dict:
    """The survival of ``policy_decide`` (a decide(observation, history) callable or None for
    the session's controller) over ``episodes`` rollouts: value and its 95% normal interval."""
    class _P:
        def decide(self, observation, history):
            return policy_decide(observation, history)

    results, _summary = rollout(session, env, episodes, seed=seed,
                                policy=None if policy_decide is None else _P())
    returns = np.array([r.total_return for r in results], dtype=np.float64)
    mean = float(returns.mean())
    half = 1.96 * float(returns.std(ddof=1)) / np.sqrt(len(returns)) if len(returns) > 1 else 0.0
    return {"value": mean, "low": mean - half, "high": mean + half, "kind": "monte-carlo",
            "episodes": int(len(returns))}


def exact(tables: SepsisTables, policy: np.ndarray) -> dict:
    """The exact value of a state policy (716,) in the tables' MDP."""
    value = tables.mdp.value(policy)
    return {"value": value, "low": value, "high": value, "kind": "exact"}


def inadmissible(tables: SepsisTables, policy: np.ndarray) -> dict:
    """How often a state policy (716,) leaves the clinicians' admissible doses: the share of
    the live states where its dose is inadmissible, and the expected number of inadmissible
    decisions per patient under it (its value in the same MDP with reward 1 for each
    inadmissible (state, dose); under the ``terminate`` strategy every such decision is fatal,
    so that is the probability that a patient dies of one)."""
    mdp = tables.mdp
    bad = ~tables.admissible                                               # (716, 25)
    policy = np.asarray(policy, np.int64)
    count = TabularMDP(mdp.P, bad.astype(np.float64), mdp.d0, mdp.terminal, mdp.gamma)
    return {"inadmissible_states": float(np.mean(bad[np.arange(LIVE), policy[:LIVE]])),
            "inadmissible_per_patient": count.value(policy)}
