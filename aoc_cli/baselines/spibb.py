"""Pi_b-SPIBB (Laroche, Trichelair and Tachet des Combes, "Safe Policy Improvement with Baseline
Bootstrapping", ICML 2019), tabular and told the state: the peer of ``aoc bench icu-sepsis``.

On the log's count model (:func:`aoc_cli.baselines.sepsis_policies.log_model`: the MLE MDP,
the behaviour's estimate pi_b and the counts N(s, a)) the bootstrapped set is
B = {(s, a): N(s, a) < N_wedge}. Policy iteration in the MLE MDP, each improvement projected
onto the policies that copy pi_b on B (the paper's Pi_b-SPIBB):

    pi(a | s) = pi_b(a | s)                                  (s, a) in B
    pi(a* | s) = sum over a not in B of pi_b(a | s)          a* = argmax_{a not in B} Q^pi(s, a)

from pi_b until the policy stops changing (at most :data:`ITERATIONS` steps; the MLE model
discounted by :data:`MODEL_GAMMA`). A state the log
never visited takes the log's most frequent action (the policy must act there when valued in
the true MDP).

**The threshold N_wedge, by a rule on the log alone** (never the true values), stated before
any value was read: the log's episodes are split in two halves (a seeded permutation); for each
N_wedge of :data:`THRESHOLDS` (the paper's grid) SPIBB is fitted on one half and valued in the
MLE model of the other (a (state, action) that half never took leads to death: pessimistic
about what it did not see); the two directions are averaged, the threshold of the highest mean
held-out value is kept (ties: the larger, the more conservative) and SPIBB is fitted on the
whole log with it.
"""

from __future__ import annotations

import numpy as np

from aoc_cli.envs.tabular import TabularMDP
from aoc_cli.baselines.sepsis_policies import log_model

#: The paper's grid of N_wedge.
THRESHOLDS = (5, 7, 10, 15, 20, 30, 50, 70, 100)
ITERATIONS = 200
#: The discount of the planning and judging in the log's MLE models: a (state, action) a log
#: saw only looping back to its state would otherwise never end there (an artefact of few
#: counts; the task itself is undiscounted and always ends).
MODEL_GAMMA = 0.999


def _model(states, actions, rewards, terminals, starts):
    """The log's MLE model (discounted by :data:`MODEL_GAMMA`), behaviour and counts."""
    model, behaviour, counts = log_model(states, actions, rewards, terminals, starts)
    return (TabularMDP(model.P, model.r, model.d0, model.terminal, MODEL_GAMMA), behaviour,
            counts)


def spibb(model, behaviour: np.ndarray, counts: np.ndarray, n_wedge: int,
          fallback: int) -> np.ndarray:
    """(S, A) Pi_b-SPIBB's policy in ``model`` (a TabularMDP) for the behaviour's estimate
    ``behaviour`` (S, A) and the counts (S, A), bootstrapping below ``n_wedge``; unvisited
    states take action ``fallback``."""
    S, A = counts.shape
    boot = counts < n_wedge
    free = np.where(boot, 0.0, behaviour).sum(axis=1)          # the mass SPIBB may move
    movable = (~boot).any(axis=1) & (free > 0)
    unvisited = counts.sum(axis=1) == 0
    base = np.where(boot, behaviour, 0.0)
    base[unvisited, fallback] = 1.0
    pi = behaviour.copy()
    pi[unvisited, fallback] = 1.0
    for _ in range(ITERATIONS):
        q = model.q_values(pi)
        best = np.argmax(np.where(boot, -np.inf, q), axis=1)
        new = base.copy()
        new[np.flatnonzero(movable), best[movable]] += free[movable]
        if np.array_equal(new, pi):
            break
        pi = new
    return pi


def _fit(states, actions, rewards, terminals, starts, n_wedge: int, fallback: int):
    model, behaviour, counts = _model(states, actions, rewards, terminals, starts)
    return spibb(model, behaviour, counts, n_wedge, fallback)


def _half(arrays, starts: np.ndarray, episodes: np.ndarray):
    """The rows of ``episodes`` (sorted) of the log ``arrays`` (states, actions, rewards,
    terminals) with their episode starts."""
    lengths = starts[episodes + 1] - starts[episodes]
    rows = np.concatenate([np.arange(starts[e], starts[e + 1]) for e in episodes])
    return [a[rows] for a in arrays], np.concatenate([[0], np.cumsum(lengths)])


def spibb_policy(states, actions, rewards, terminals, starts, seed: int = 0
                 ) -> tuple[np.ndarray, dict]:
    """(S, A) Pi_b-SPIBB fitted on the whole log with the threshold the module docstring's
    rule chooses, and what the rule saw: ``{"n_wedge", "held_out": {N_wedge: mean held-out
    value}}``. Arrays per row: ``states`` (the told state), ``actions``, ``rewards``,
    ``terminals``; ``starts`` (E + 1,) the episode starts."""
    arrays = [np.asarray(states, np.int64), np.asarray(actions, np.int64),
              np.asarray(rewards, np.float64), np.asarray(terminals, bool)]
    starts = np.asarray(starts, np.int64)
    fallback = int(np.bincount(arrays[1]).argmax())
    order = np.random.default_rng(seed).permutation(len(starts) - 1)
    halves = [np.sort(order[: len(order) // 2]), np.sort(order[len(order) // 2:])]
    parts = [_half(arrays, starts, h) for h in halves]
    held = {}
    for n_wedge in THRESHOLDS:
        values = []
        for fit, judge in ((0, 1), (1, 0)):
            pi = _fit(*parts[fit][0], parts[fit][1], n_wedge, fallback)
            model, _b, _c = _model(*parts[judge][0], parts[judge][1])
            values.append(model.value(pi))
        held[n_wedge] = float(np.mean(values))
    best = max(THRESHOLDS, key=lambda n: (held[n], n))
    return _fit(*arrays, starts, best, fallback), {"n_wedge": best, "held_out": held}
