"""Small episodic MDPs with exact policy values (a linear solve), and logs sampled from them,
for the offline policy evaluation tests."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class SmallMDP:
    """S transient states, A actions, two absorbing outcomes (column S: survived, reward 1 on
    entering it; column S + 1: died, reward 0). ``P`` (S, A, S + 2), ``d0`` (S,). The reward
    comes only at the end, and episodes have random lengths."""

    P: np.ndarray
    d0: np.ndarray

    @classmethod
    def random(cls, n_states: int = 4, n_actions: int = 3, end: float = 0.25, seed: int = 0):
        rng = np.random.default_rng(seed)
        s, a = n_states, n_actions
        P = np.empty((s, a, s + 2))
        P[:, :, :s] = rng.dirichlet(np.ones(s), size=(s, a)) * (1 - end)
        alive = rng.uniform(0.2, 0.9, size=(s, a))
        P[:, :, s] = end * alive
        P[:, :, s + 1] = end * (1 - alive)
        return cls(P, rng.dirichlet(np.ones(s)))

    @property
    def n_states(self) -> int:
        return self.P.shape[0]

    def exact(self, pi: np.ndarray, gamma: float = 1.0) -> tuple[float, np.ndarray]:
        """(value of the start distribution, Q (S, A)) of policy ``pi`` (S, A), by solving
        (I - gamma P_pi) V = r_pi."""
        s = self.n_states
        r = self.P[:, :, s]                                       # (S, A) reward 1 on survival
        p_pi = np.einsum("sa,sat->st", pi, self.P[:, :, :s])
        v = np.linalg.solve(np.eye(s) - gamma * p_pi, (pi * r).sum(1))
        q = r + gamma * self.P[:, :, :s] @ v
        return float(self.d0 @ v), q

    def sample(self, pi_b: np.ndarray, episodes: int, seed: int = 0) -> dict:
        """A log of ``episodes`` under ``pi_b`` (S, A): flat ``state``, ``action``, ``reward``,
        ``propensity`` (N,) and ``starts`` (E + 1,)."""
        rng = np.random.default_rng(seed)
        s_n, a_n = self.P.shape[:2]
        states, actions, rewards, starts = [], [], [], [0]
        for _ in range(episodes):
            s = rng.choice(s_n, p=self.d0)
            while True:
                a = rng.choice(a_n, p=pi_b[s])
                nxt = rng.choice(s_n + 2, p=self.P[s, a])
                states.append(s)
                actions.append(a)
                rewards.append(1.0 if nxt == s_n else 0.0)
                if nxt >= s_n:
                    break
                s = nxt
            starts.append(len(states))
        states, actions = np.asarray(states), np.asarray(actions)
        return {"state": states, "action": actions, "reward": np.asarray(rewards),
                "propensity": pi_b[states, actions], "starts": np.asarray(starts)}


def noisy_log(seed: int, end: float, episodes: int, sample_seed: int):
    """A log of a random :class:`SmallMDP` (``seed``, ``end``) under a random behaviour, its
    observations the one-hot state plus uniform noise of 0.1: (observations (N, S), the log
    (:meth:`SmallMDP.sample`), the behaviour pi_b (S, A), the generator for what follows)."""
    mdp = SmallMDP.random(seed=seed, end=end)
    rng = np.random.default_rng(seed)
    s, a = mdp.P.shape[:2]
    pi_b = rng.dirichlet(np.ones(a), size=s)
    data = mdp.sample(pi_b, episodes, seed=sample_seed)
    obs = np.eye(s)[data["state"]] + 0.1 * rng.random((len(data["state"]), s))
    return obs, data, pi_b, rng


def mixed_policies(mdp: SmallMDP, seed: int = 1):
    """(pi_b, greedy, soft, rng) on ``mdp``: a random deterministic policy ``greedy``, the
    behaviour pi_b half it and half a random one (so it takes greedy's actions often), the
    stochastic ``soft`` 0.6 greedy + 0.4 uniform, each (S, A); ``rng`` the generator they
    were drawn from (``seed``), for what follows."""
    rng = np.random.default_rng(seed)
    s, a = mdp.P.shape[:2]
    greedy = np.eye(a)[rng.integers(0, a, size=s)]
    pi_b = 0.5 * greedy + 0.5 * rng.dirichlet(np.full(a, 2.0), size=s)
    return pi_b, greedy, 0.6 * greedy + 0.4 / a, rng
