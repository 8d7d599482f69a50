"""Exact values of policies in a finite MDP given by its tables: one linear solve per policy.

A :class:`TabularMDP` holds S states and A actions: transitions ``P`` (S, A, S), the expected
reward of each (state, action) ``r`` (S, A) (``sum_s' P[s, a, s'] R[s, a, s']``), the initial
distribution ``d0`` (S,) and the absorbing ``terminal`` states (S,) bool (value 0; no step is
taken from them). Returns are undiscounted by default (``gamma=1``), which is well defined when
every policy reaches a terminal state with probability 1 (the solve fails with a clear error
otherwise).

A policy is either stochastic, (S, A) with rows summing to 1 on the non-terminal states, or
deterministic, (S,) action indices. Its state values solve ``(I - gamma P_pi) v = r_pi`` on the
non-terminal states (``scipy.linalg.solve``; S = 716 for ICU-Sepsis takes milliseconds), and its
Q is one more step: ``Q = r + gamma P v``. The optimal values come from value iteration.

Why hand-written: no library we use evaluates a given policy of an MDP in tabular form exactly
(d3rlpy estimates values from data; gymnasium holds no tables). The whole of it is the linear
solve above.

>>> import numpy as np
>>> P = np.zeros((2, 1, 2)); P[0, 0] = [0.5, 0.5]; P[1, 0, 1] = 1.0   # stay or stop, 50/50
>>> mdp = TabularMDP(P, np.array([[1.0], [0.0]]), np.array([1.0, 0.0]),
...                  np.array([False, True]))
>>> round(mdp.value(np.array([0, 0])), 12)                          # 1 + 1/2 + 1/4 + ... = 2
2.0
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from aoc_cli.errors import AocError


@dataclass(frozen=True)
class TabularMDP:
    """A finite MDP: ``P`` (S, A, S), ``r`` (S, A), ``d0`` (S,), ``terminal`` (S,) bool."""

    P: np.ndarray
    r: np.ndarray
    d0: np.ndarray
    terminal: np.ndarray
    gamma: float = 1.0

    def __post_init__(self):
        S, A = self.r.shape
        if self.P.shape != (S, A, S) or self.d0.shape != (S,) or self.terminal.shape != (S,):
            raise AocError(f"MDP tables of inconsistent shapes: P {self.P.shape}, r "
                           f"{self.r.shape}, d0 {self.d0.shape}, terminal {self.terminal.shape}")
        if not 0.0 < self.gamma <= 1.0:
            raise AocError(f"gamma must be in (0, 1], got {self.gamma}")

    @property
    def n_states(self) -> int:
        return int(self.r.shape[0])

    @property
    def n_actions(self) -> int:
        return int(self.r.shape[1])

    def as_stochastic(self, policy) -> np.ndarray:
        """A policy (S, A) stochastic or (S,) deterministic -> (S, A) probabilities, checked:
        rows of non-terminal states non-negative and summing to 1 (terminal rows ignored)."""
        pi = np.asarray(policy)
        S, A = self.n_states, self.n_actions
        if pi.ndim == 1:
            if pi.shape != (S,) or not np.issubdtype(pi.dtype, np.integer):
                raise AocError(f"a deterministic policy is ({S},) action indices, got "
                               f"{pi.shape} {pi.dtype}")
            live = ~self.terminal
            if np.any((pi[live] < 0) | (pi[live] >= A)):
                bad = int(np.flatnonzero(live & ((pi < 0) | (pi >= A)))[0])
                raise AocError(f"the policy's action {int(pi[bad])} in state {bad} is not one "
                               f"of the {A} actions")
            out = np.zeros((S, A))
            out[np.flatnonzero(live), pi[live]] = 1.0
            return out
        if pi.shape != (S, A):
            raise AocError(f"a stochastic policy is ({S}, {A}), got {pi.shape}")
        pi = pi.astype(np.float64)
        live = ~self.terminal
        sums = pi[live].sum(axis=1)
        if np.any(pi[live] < 0) or not np.allclose(sums, 1.0, atol=1e-9):
            bad = int(np.flatnonzero(live)[np.argmax(np.abs(sums - 1.0) + (pi[live] < 0).any(1))])
            raise AocError(f"the policy's probabilities in state {bad} do not sum to 1 "
                           f"(sum {float(pi[bad].sum()):.6g}) or hold a negative entry")
        out = pi.copy()
        out[self.terminal] = 0.0
        return out

    def state_values(self, policy) -> np.ndarray:
        """(S,) the policy's expected return from each state (0 at terminal states)."""
        pi = self.as_stochastic(policy)
        live = np.flatnonzero(~self.terminal)
        P_pi = np.einsum("sa,sat->st", pi, self.P)[np.ix_(live, live)]       # (L, L)
        r_pi = np.einsum("sa,sa->s", pi[live], self.r[live])                 # (L,)
        system = np.eye(len(live)) - self.gamma * P_pi
        try:
            v_live = scipy.linalg.solve(system, r_pi)
        except (np.linalg.LinAlgError, scipy.linalg.LinAlgError) as err:
            raise AocError("the policy never reaches a terminal state from some state: its "
                           "undiscounted value is not defined (give gamma < 1)") from err
        if not np.all(np.isfinite(v_live)):
            raise AocError("the policy's values are not finite: it never reaches a terminal "
                           "state from some state (give gamma < 1)")
        v = np.zeros(self.n_states)
        v[live] = v_live
        return v

    def value(self, policy) -> float:
        """The policy's expected return from the initial distribution: ``d0 . v``."""
        return float(self.d0 @ self.state_values(policy))

    def q_values(self, policy) -> np.ndarray:
        """(S, A) the policy's Q: ``r + gamma P v`` (0 at terminal states)."""
        return self._backup(self.state_values(policy))

    def optimal(self, tol: float = 1e-6, max_iter: int = 100_000) -> tuple[np.ndarray, np.ndarray]:
        """The optimal values and a deterministic optimal policy: ``(v* (S,), policy (S,)
        int64)``. Value iteration until no state's value moves by more than ``tol`` in a sweep,
        then policy iteration from its greedy policy (exact solves) until no state's action
        improves by more than 1e-12: the values returned are the final policy's, solved
        exactly."""
        v = np.zeros(self.n_states)
        for _ in range(max_iter):
            new = self._backup(v).max(axis=1)
            done = np.max(np.abs(new - v)) <= tol
            v = new
            if done:
                break
        else:
            raise AocError(f"value iteration did not converge in {max_iter} sweeps")
        policy = greedy(self._backup(v))
        for _ in range(max_iter):
            v = self.state_values(policy)
            q = self._backup(v)
            best = greedy(q)
            better = q[np.arange(self.n_states), best] > \
                q[np.arange(self.n_states), policy] + 1e-12
            if not better.any():
                return v, policy
            policy = np.where(better, best, policy)
        raise AocError(f"policy iteration did not converge in {max_iter} steps")

    def _backup(self, v: np.ndarray) -> np.ndarray:
        """(S, A) one Bellman backup of state values ``v`` (S,): ``r + gamma P v``."""
        S, A = self.n_states, self.n_actions
        q = self.r + self.gamma * (self.P.reshape(S * A, S) @ v).reshape(S, A)
        q[self.terminal] = 0.0
        return q


def greedy(q: np.ndarray, support: np.ndarray | None = None) -> np.ndarray:
    """(S,) int64: per state the action of highest ``q`` (S, A) among those where ``support``
    (S, A) bool is true (all actions where a state has no support, or ``support`` is None).
    Ties go to the lowest action index."""
    q = np.asarray(q, dtype=np.float64)
    if support is None:
        return np.argmax(q, axis=1).astype(np.int64)
    support = np.asarray(support, dtype=bool)
    if support.shape != q.shape:
        raise AocError(f"support {support.shape} and Q {q.shape} differ in shape")
    masked = np.where(support, q, -np.inf)
    none = ~support.any(axis=1)
    masked[none] = q[none]
    return np.argmax(masked, axis=1).astype(np.int64)


__all__ = ["TabularMDP", "greedy"]
